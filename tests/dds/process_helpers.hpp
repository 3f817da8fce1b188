// Helpers of the DDS process tests: spawn and reap processes, and run a test body inside a
// private network namespace (deploy/netns-run), re-executing the test binary there when needed.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace rcal::dds::testing {

namespace fs = std::filesystem;

// Starts argv[0] with argv in a new process group, stdout to `out`, stderr to `err`.
inline pid_t Spawn(const std::vector<std::string>& argv, const fs::path& out, const fs::path& err) {
  const pid_t pid = fork();
  if (pid == 0) {
    setpgid(0, 0);
    FILE* o = std::fopen(out.c_str(), "w");
    FILE* e = std::fopen(err.c_str(), "w");
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

inline int Wait(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
}

inline bool Alive(pid_t pid) {
  return waitpid(pid, nullptr, WNOHANG) == 0;
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

// In a test body: skip when no namespace can be made, return after delegating, else go on.
#define RCAL_IN_NAMESPACE(filter)                                                   \
  switch (::rcal::dds::testing::InNamespaceOrDelegate(filter)) {                    \
    case ::rcal::dds::testing::Where::kNotPermitted:                                \
      GTEST_SKIP() << "unshare -n is not permitted here (deploy/netns-run failed)"; \
    case ::rcal::dds::testing::Where::kDelegated:                                   \
      return;                                                                       \
    case ::rcal::dds::testing::Where::kHere:                                        \
      break;                                                                        \
  }

}  // namespace rcal::dds::testing
