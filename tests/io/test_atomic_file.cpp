// AtomicWriteFile and ReadFile: content round trip, overwrite, no temporary file left behind
// (after success or failure), the old file intact when a write fails, and concurrent writers of
// one path each leaving a whole file.
#include "rcal/io/atomic_file.hpp"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>

#include <atomic>
#include <csignal>
#include <filesystem>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "io_test_util.hpp"

namespace rcal::io {
namespace {

namespace fs = std::filesystem;
using testing::ErrorOf;
using testing::ScratchDir;

// The names in `dir`, sorted.
std::set<std::string> Names(const fs::path& dir) {
  std::set<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) names.insert(entry.path().filename());
  return names;
}

std::string Binary(size_t n, unsigned seed) {
  std::string s(n, '\0');
  for (size_t i = 0; i < n; ++i) s[i] = static_cast<char>((i * 131 + seed * 17 + i / 7) & 0xff);
  return s;
}

TEST(AtomicFile, RoundTripKeepsEveryByte) {
  ScratchDir d;
  for (const std::string& content :
       {std::string(), std::string("a\r\nb\0c\n", 7), Binary(3 << 20, 1)}) {
    AtomicWriteFile(d / "f.bin", content);
    const std::string back = ReadFile(d / "f.bin");
    EXPECT_EQ(back.size(), content.size());
    EXPECT_TRUE(back == content);
    EXPECT_EQ(fs::file_size(d / "f.bin"), content.size());
  }
}

TEST(AtomicFile, OverwritesAndLeavesNoTemporaryFile) {
  ScratchDir d;
  AtomicWriteFile(d / "report.json", "first, and longer than the second\n");
  AtomicWriteFile(d / "report.json", "second\n");
  EXPECT_EQ(ReadFile(d / "report.json"), "second\n");
  EXPECT_EQ(Names(d.path()), std::set<std::string>{"report.json"});
}

TEST(AtomicFile, CreatesMissingParentDirectories) {
  ScratchDir d;
  AtomicWriteFile(d / "a/b/c.txt", "x");
  EXPECT_EQ(ReadFile(d / "a/b/c.txt"), "x");
  EXPECT_EQ(Names(d / "a/b"), std::set<std::string>{"c.txt"});
}

TEST(AtomicFile, FailedRenameKeepsTheTargetAndRemovesTheTemporaryFile) {
  // The target is a directory that is not empty: the rename cannot replace it.
  ScratchDir d;
  fs::create_directories(d / "target/inner");
  AtomicWriteFile(d / "target/inner/keep.txt", "kept");
  const std::string error = ErrorOf([&] { AtomicWriteFile(d / "target", "new"); });
  EXPECT_NE(error, "<no error>");
  EXPECT_NE(error.find((d / "target").string()), std::string::npos) << error;
  EXPECT_EQ(ReadFile(d / "target/inner/keep.txt"), "kept");
  EXPECT_EQ(Names(d.path()), std::set<std::string>{"target"});
}

TEST(AtomicFile, FailedWriteKeepsTheOldFileAndRemovesTheTemporaryFile) {
  // A file-size limit makes write(2) fail (EFBIG) part way, as a full disk would.
  ScratchDir d;
  AtomicWriteFile(d / "data.csv", "old content\n");
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit old_limit{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  rlimit small = old_limit;
  small.rlim_cur = 4096;
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
  const std::string error = ErrorOf([&] { AtomicWriteFile(d / "data.csv", Binary(1 << 20, 2)); });
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &old_limit), 0);
  std::signal(SIGXFSZ, old_handler);
  EXPECT_NE(error.find((d / "data.csv").string()), std::string::npos) << error;
  EXPECT_EQ(ReadFile(d / "data.csv"), "old content\n");
  EXPECT_EQ(Names(d.path()), std::set<std::string>{"data.csv"});
}

TEST(AtomicFile, AParentThatIsAFileIsAnErrorAndTheFileIsKept) {
  ScratchDir d;
  AtomicWriteFile(d / "plain", "plain file");
  EXPECT_NE(ErrorOf([&] { AtomicWriteFile(d / "plain/child.txt", "x"); }), "<no error>");
  EXPECT_EQ(ReadFile(d / "plain"), "plain file");
  EXPECT_EQ(Names(d.path()), std::set<std::string>{"plain"});
}

TEST(AtomicFile, ConcurrentWritersOfOnePathEachLeaveAWholeFile) {
  // Threads of one process share a pid: each write needs its own temporary file.
  ScratchDir d;
  const fs::path target = d / "shared.txt";
  constexpr int kThreads = 4, kWrites = 50;
  std::vector<std::string> contents;
  for (int t = 0; t < kThreads; ++t) contents.push_back(Binary(20000 + 1000 * t, 10 + t));
  AtomicWriteFile(target, contents[0]);
  std::atomic<int> failures{0}, torn{0};
  std::atomic<bool> stop{false};
  std::thread reader([&] {
    while (!stop) {
      const std::string s = ReadFile(target);
      bool whole = false;
      for (const auto& c : contents) whole |= s == c;
      if (!whole) ++torn;
    }
  });
  std::vector<std::thread> writers;
  for (int t = 0; t < kThreads; ++t)
    writers.emplace_back([&, t] {
      for (int k = 0; k < kWrites; ++k) {
        try {
          AtomicWriteFile(target, contents[t]);
        } catch (const std::exception&) {
          ++failures;
        }
      }
    });
  for (auto& w : writers) w.join();
  stop = true;
  reader.join();
  EXPECT_EQ(failures, 0);
  EXPECT_EQ(torn, 0);
  EXPECT_EQ(Names(d.path()), std::set<std::string>{"shared.txt"});
}

// The temporary files of `target` in `dir` (names starting "TARGET.tmp.").
std::vector<std::string> TempFiles(const fs::path& dir, const std::string& target) {
  std::vector<std::string> out;
  for (const auto& n : Names(dir))
    if (n.rfind(target + ".tmp.", 0) == 0) out.push_back(n);
  return out;
}

// A child process that rewrites `path` with 32 MB until killed; returns when one of its
// temporary files exists, killed by SIGKILL, so the file it was writing stays behind.
pid_t KillAWriterMidWrite(const fs::path& dir, const std::string& target) {
  for (int attempt = 0; attempt < 50; ++attempt) {
    const pid_t pid = ::fork();
    if (pid == 0) {
      const std::string big = Binary(32 << 20, 3);
      for (;;) AtomicWriteFile(dir / target, big);
    }
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (TempFiles(dir, target).empty() && std::chrono::steady_clock::now() < until)
      std::this_thread::yield();
    ::kill(pid, SIGKILL);
    int status = 0;
    ::waitpid(pid, &status, 0);
    // Killed between two writes (the rename done): try again.
    for (const auto& n : TempFiles(dir, target))
      if (n.rfind(target + ".tmp." + std::to_string(pid) + ".", 0) == 0) return pid;
  }
  ADD_FAILURE() << "no writer was killed mid-write in 50 attempts";
  return 0;
}

TEST(AtomicFile, TemporaryFilesOfKilledWritersAreRemovedOnTheFirstWrite) {
  ScratchDir d;
  const pid_t dead = KillAWriterMidWrite(d.path(), "checkpoint.bin");
  ASSERT_NE(dead, 0);
  ASSERT_EQ(TempFiles(d.path(), "checkpoint.bin").size(), 1u);
  // A live process's temporary file (a child that sleeps) and a dead writer's file of another
  // target must stay.
  const pid_t live = ::fork();
  if (live == 0) {
    ::pause();
    ::_exit(0);
  }
  const std::string live_tmp = "checkpoint.bin.tmp." + std::to_string(live) + ".0";
  const std::string other_tmp = "other.bin.tmp." + std::to_string(dead) + ".0";
  AtomicWriteFile(d / live_tmp, "being written by a live process");
  AtomicWriteFile(d / other_tmp, "another target's");
  // The old name (no counter) of a dead writer goes too.
  AtomicWriteFile(d / ("checkpoint.bin.tmp." + std::to_string(dead)), "old layout");

  AtomicWriteFile(d / "checkpoint.bin", "fresh\n");
  EXPECT_EQ(ReadFile(d / "checkpoint.bin"), "fresh\n");
  EXPECT_EQ(TempFiles(d.path(), "checkpoint.bin"), std::vector<std::string>{live_tmp});
  EXPECT_TRUE(fs::exists(d / other_tmp));
  // Once the live one has died, an explicit clean-up at start removes its file as well.
  ::kill(live, SIGKILL);
  ::waitpid(live, nullptr, 0);
  EXPECT_EQ(RemoveStaleTempFiles(d / "checkpoint.bin"), 1);
  EXPECT_TRUE(TempFiles(d.path(), "checkpoint.bin").empty());
  EXPECT_EQ(RemoveStaleTempFiles(d / "other.bin"), 1);
  EXPECT_EQ(Names(d.path()), (std::set<std::string>{"checkpoint.bin"}));
}

TEST(AtomicFile, ReadFileOfAMissingFileNamesIt) {
  ScratchDir d;
  const std::string error = ErrorOf([&] { (void)ReadFile(d / "missing.txt"); });
  EXPECT_NE(error.find("missing.txt"), std::string::npos) << error;
}

}  // namespace
}  // namespace rcal::io
