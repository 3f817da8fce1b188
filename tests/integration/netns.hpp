// Shared by the integration tests: spawn real processes in their own process group with their
// output in a file, and run a test body inside deploy/netns-run (a private network namespace
// with multicast on loopback) unless already there. Where that is not permitted the test skips,
// or fails when every test must run (RCAL_REQUIRE_ALL_TESTS, CI).
#pragma once

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace rcal::integration {

namespace fs = std::filesystem;

/// Starts argv[0] with argv in a new process group, stdout to `out` and stderr to `err` (one
/// file when they are the same path).
inline pid_t Spawn(const std::vector<std::string>& argv, const fs::path& out, const fs::path& err) {
  const pid_t pid = fork();
  if (pid == 0) {
    setpgid(0, 0);
    FILE* o = std::fopen(out.c_str(), "w");
    FILE* e = err == out ? o : std::fopen(err.c_str(), "w");
    if (o) dup2(fileno(o), 1);
    if (e) dup2(fileno(e), 2);
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    execv(args[0], args.data());
    _exit(127);
  }
  return pid;
}

/// Starts argv[0] with stdout and stderr both in `log`.
inline pid_t Spawn(const std::vector<std::string>& argv, const fs::path& log) {
  return Spawn(argv, log, log);
}

/// Exit code, or −signal.
inline int Wait(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
}

/// True while `pid` (a child) has not exited.
inline bool Running(pid_t pid) {
  int status = 0;
  return waitpid(pid, &status, WNOHANG) == 0;
}

/// Calls `step` until `done` is true or the guard (only there to turn a hang into a failure)
/// runs out.
inline bool Until(const std::function<bool()>& done, const std::function<void()>& step,
                  double guard_s = 120) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(guard_s);
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) return false;
    step();
  }
  return true;
}

enum class Where { kHere, kDelegated, kNotPermitted };

inline Where InNamespaceOrDelegate(const char* filter) {
  if (std::getenv("RCAL_IN_NETNS")) return Where::kHere;
  const std::string netns = RCAL_SOURCE_DIR "/deploy/netns-run";
  if (std::system((netns + " true >/dev/null 2>&1").c_str()) != 0) return Where::kNotPermitted;
  const std::string self = fs::read_symlink("/proc/self/exe").string();
  const int rc = std::system((netns + " " + self + " --gtest_filter=" + filter).c_str());
  EXPECT_EQ(rc, 0) << "the test inside the namespace failed (output above)";
  return Where::kDelegated;
}

/// A test that cannot run here: skipped on a developer's machine, a failure where every test
/// must run (RCAL_REQUIRE_ALL_TESTS, on in CI), so that CI never goes green without it.
#if defined(RCAL_REQUIRE_ALL_TESTS) && RCAL_REQUIRE_ALL_TESTS
#define RCAL_CANNOT_RUN_HERE(why) \
  GTEST_FAIL() << "cannot run here, and every test must (RCAL_REQUIRE_ALL_TESTS): " << why
#else
#define RCAL_CANNOT_RUN_HERE(why) GTEST_SKIP() << why
#endif

#define RCAL_IN_NAMESPACE(filter)                                                         \
  switch (::rcal::integration::InNamespaceOrDelegate(filter)) {                           \
    case ::rcal::integration::Where::kNotPermitted:                                       \
      RCAL_CANNOT_RUN_HERE("unshare -n is not permitted here (deploy/netns-run failed)"); \
    case ::rcal::integration::Where::kDelegated:                                          \
      return;                                                                             \
    case ::rcal::integration::Where::kHere:                                               \
      break;                                                                              \
  }

/// A temporary directory and the processes started in it; kills what is left at the end and
/// keeps the directory (with the processes' logs) when the test failed.
class ProcessFixture : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ =
        fs::temp_directory_path() /
        ("rcal_it_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) +
         "_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override {
    for (pid_t p : pids_) {
      kill(-p, SIGKILL);
      waitpid(p, nullptr, 0);
    }
    if (!HasFailure()) {
      fs::remove_all(dir_);
      return;
    }
    std::fprintf(stderr, "logs kept in %s\n", dir_.c_str());
    // The namespace is the test's own, so its UDP counters are the test's: datagrams the kernel
    // dropped because a socket's receive buffer was full (RcvbufErrors) are losses no process
    // can see.
    if (std::getenv("RCAL_IN_NETNS")) {
      FILE* snmp = std::fopen("/proc/net/snmp", "r");
      char line[512];
      while (snmp != nullptr && std::fgets(line, sizeof line, snmp) != nullptr)
        if (std::string(line).rfind("Udp:", 0) == 0) std::fprintf(stderr, "namespace %s", line);
      if (snmp != nullptr) std::fclose(snmp);
    }
  }
  pid_t Start(const std::vector<std::string>& argv, const std::string& log) {
    const pid_t p = Spawn(argv, dir_ / log);
    pids_.push_back(p);
    return p;
  }
  /// SIGINT to the process group and wait; returns the exit code.
  int Stop(pid_t p) {
    kill(-p, SIGINT);
    std::erase(pids_, p);
    return Wait(p);
  }
  void Reaped(pid_t p) { std::erase(pids_, p); }
  fs::path dir_;
  std::vector<pid_t> pids_;
};

}  // namespace rcal::integration
