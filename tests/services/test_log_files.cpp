// The logger's log file names (services/logger/log_files.hpp): the index of
// `<prefix>.NNNN.lcmlog`, and the next index in a directory, which a name whose number does not
// parse or overflows must never keep from starting.
#include "log_files.hpp"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>

#include <climits>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace rcal::logger {
namespace {

namespace fs = std::filesystem;

TEST(LogFiles, ParsesTheIndexOfALogOfThePrefix) {
  EXPECT_EQ(ParseLogFileIndex("rcal.0000.lcmlog", "rcal"), 0);
  EXPECT_EQ(ParseLogFileIndex("rcal.0042.lcmlog", "rcal"), 42);
  EXPECT_EQ(ParseLogFileIndex("rcal.123456.lcmlog", "rcal"), 123456);
  EXPECT_EQ(ParseLogFileIndex("cell.a.0007.lcmlog", "cell.a"), 7);
  EXPECT_EQ(ParseLogFileIndex("rcal.2147483646.lcmlog", "rcal"), INT_MAX - 1);
}

TEST(LogFiles, OtherNamesAreNotLogsAndNeedNoWarning) {
  std::string problem = "unset";
  for (const char* f : {"kinematic_params.csv", "rcal.lcmlog", "rcalx.0001.lcmlog",
                        "other.0001.lcmlog", "rcal.0001.lcmlog.tmp", "rcal", "rcal.0001"}) {
    EXPECT_FALSE(ParseLogFileIndex(f, "rcal", &problem).has_value()) << f;
    EXPECT_EQ(problem, "") << f;
  }
}

TEST(LogFiles, ANumberThatOverflowsOrDoesNotParseIsRefusedWithAReason) {
  for (const char* f : {"rcal.99999999999.lcmlog", "rcal.2147483647.lcmlog",
                        "rcal.99999999999999999999999.lcmlog", "rcal.12x.lcmlog", "rcal.-3.lcmlog",
                        "rcal.+3.lcmlog", "rcal. 3.lcmlog", "rcal..lcmlog", "rcal.0x10.lcmlog"}) {
    std::string problem;
    EXPECT_FALSE(ParseLogFileIndex(f, "rcal", &problem).has_value()) << f;
    EXPECT_NE(problem, "") << f;
  }
  std::string problem;
  (void)ParseLogFileIndex("rcal.99999999999.lcmlog", "rcal", &problem);
  EXPECT_NE(problem.find("99999999999"), std::string::npos) << problem;
}

TEST(LogFiles, NextIndexSkipsNamesItCannotUse) {
  const fs::path d = fs::temp_directory_path() / ("rcal_log_files_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  EXPECT_EQ(NextFileIndex(d, "rcal"), 0);
  for (const char* f : {"rcal.0000.lcmlog", "rcal.0003.lcmlog", "rcal.99999999999.lcmlog",
                        "rcal.abc.lcmlog", "other.0100.lcmlog", "kinematic_params.csv"})
    std::ofstream(d / f) << "x";
  EXPECT_EQ(NextFileIndex(d, "rcal"), 4);
  EXPECT_EQ(NextFileIndex(d, "other"), 101);
  EXPECT_EQ(NextFileIndex(d, "none"), 0);
  fs::remove_all(d);
}

TEST(LogFiles, TheLoggerStartsBesideAFileWhoseNumberOverflows) {
  // The logger itself (an in-process LCM, no network): it must start, write the next file and
  // stop cleanly on SIGINT.
  const fs::path d =
      fs::temp_directory_path() / ("rcal_logger_start_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  for (const char* f : {"rcal.0002.lcmlog", "rcal.99999999999.lcmlog"}) std::ofstream(d / f) << "x";
  std::vector<std::string> args = {LOGGER_EXE, "--dir", d.string(), "--lcm-url", "memq://"};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  int status = 0;
  bool exited = false;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (!fs::exists(d / "rcal.0003.lcmlog") && std::chrono::steady_clock::now() < deadline) {
    if (::waitpid(pid, &status, WNOHANG) == pid) {
      exited = true;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_FALSE(exited) << "the logger exited at start, status " << status;
  EXPECT_TRUE(fs::exists(d / "rcal.0003.lcmlog"));
  if (!exited) {
    ::kill(pid, SIGINT);
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "status " << status;
  }
  fs::remove_all(d);
}

}  // namespace
}  // namespace rcal::logger
