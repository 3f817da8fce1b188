// The logger's file names (services/logger/log_files.hpp): the index of `<prefix>.NNNN.lcmlog`
// and of the parameter history beside it, `<prefix>.NNNN.kinematic_params.csv`; the next index in
// a directory, which a name whose number does not parse or overflows must never keep from
// starting; each start of the logger (a run) writing its own numbered set, never appending to an
// earlier run's files.
#include "log_files.hpp"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <climits>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <lcm/lcm-cpp.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "netns.hpp"
#include "rcal/kinematic_params_t.hpp"

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

TEST(LogFiles, TheParameterHistoryIsNumberedAsItsLog) {
  EXPECT_EQ(LogFileName("rcal", 0), "rcal.0000.lcmlog");
  EXPECT_EQ(LogFileName("rcal", 12), "rcal.0012.lcmlog");
  EXPECT_EQ(ParamsCsvName("rcal", 12), "rcal.0012.kinematic_params.csv");
  EXPECT_EQ(ParamsCsvName("cell.a", 12345), "cell.a.12345.kinematic_params.csv");
  EXPECT_EQ(ParseLogFileIndex("rcal.0012.kinematic_params.csv", "rcal"), 12);
  std::string problem;
  EXPECT_FALSE(ParseLogFileIndex("rcal.x1.kinematic_params.csv", "rcal", &problem).has_value());
  EXPECT_NE(problem, "");
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
  // A history without its log still holds its number: it is never appended to.
  std::ofstream(d / "rcal.0006.kinematic_params.csv") << "x\n";
  EXPECT_EQ(NextFileIndex(d, "rcal"), 7);
  fs::remove_all(d);
}

std::string ReadFile(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Two starts in one directory (two runs, or a run and its restart after a kill), the second
// with a rotation: each writes its own numbered history beside its own log, with its header; the
// first run's history is left as it was, but for the row a kill cut short.
TEST(LogFiles, EachStartWritesItsOwnNumberedSet) {
  const fs::path d = fs::temp_directory_path() / ("rcal_log_sets_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  {
    LogFiles run(d, "rcal");
    EXPECT_EQ(run.index(), 0);
    EXPECT_EQ(run.log_path(), d / "rcal.0000.lcmlog");
    std::ofstream(run.log_path()) << "log";  // the logger opens its log at start
    ASSERT_TRUE(run.AppendParams("utime,poses_used,a\n", "1,1,0.5\n"));
    ASSERT_TRUE(run.AppendParams("utime,poses_used,a\n", "2,2,0.25\n"));
  }
  EXPECT_EQ(ReadFile(d / "rcal.0000.kinematic_params.csv"),
            "utime,poses_used,a\n1,1,0.5\n2,2,0.25\n");
  // What a kill in the middle of a write leaves.
  std::ofstream(d / "rcal.0000.kinematic_params.csv", std::ios::app) << "3,3,0.1";
  {
    LogFiles run(d, "rcal");
    EXPECT_EQ(run.index(), 1);
    EXPECT_EQ(ReadFile(d / "rcal.0000.kinematic_params.csv"),
              "utime,poses_used,a\n1,1,0.5\n2,2,0.25\n");
    std::ofstream(run.log_path()) << "log";
    ASSERT_TRUE(run.AppendParams("utime,poses_used,b\n", "10,1,7\n"));
    run.Next();  // rotation past --max-bytes
    EXPECT_EQ(run.log_path(), d / "rcal.0002.lcmlog");
    std::ofstream(run.log_path()) << "log";
    ASSERT_TRUE(run.AppendParams("utime,poses_used,b\n", "11,2,8\n"));
  }
  EXPECT_EQ(ReadFile(d / "rcal.0001.kinematic_params.csv"), "utime,poses_used,b\n10,1,7\n");
  EXPECT_EQ(ReadFile(d / "rcal.0002.kinematic_params.csv"), "utime,poses_used,b\n11,2,8\n");
  EXPECT_FALSE(fs::exists(d / "kinematic_params.csv"));
  EXPECT_EQ(RemoveTornLastRow(d / "rcal.0002.kinematic_params.csv"), 0u);
  EXPECT_EQ(RemoveTornLastRow(d / "missing.csv"), 0u);
  fs::remove_all(d);
}

// Rows of a parameter history CSV (after its header), as (utime, poses_used) pairs.
std::vector<std::pair<long, int>> CsvRows(const fs::path& p, std::string* header) {
  std::ifstream in(p);
  std::vector<std::pair<long, int>> rows;
  std::string line;
  if (!std::getline(in, line)) return rows;
  *header = line;
  while (std::getline(in, line)) {
    std::stringstream s(line);
    long utime = 0;
    int poses = 0;
    char comma = 0;
    s >> utime >> comma >> poses;
    rows.emplace_back(utime, poses);
  }
  return rows;
}

// The logger itself, run twice in one directory as `deploy/demo` twice would (inside a private
// network namespace, KINEMATIC_PARAMS over UDP multicast): the second run writes rcal.0001.lcmlog
// and rcal.0001.kinematic_params.csv with its own parameters only; the first run's history holds
// only the first run's. (The logger used to append every run to one kinematic_params.csv.)
TEST(LogFiles, TwoRunsOfTheLoggerWriteTwoNumberedSets) {
  RCAL_IN_NAMESPACE("LogFiles.TwoRunsOfTheLoggerWriteTwoNumberedSets");
  const fs::path d = fs::temp_directory_path() / ("rcal_logger_runs_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  const std::string url = "udpm://239.255.76.67:7741?ttl=0";
  lcm::LCM lcm(url);
  ASSERT_TRUE(lcm.good());
  for (int run = 1; run <= 2; ++run) {
    const fs::path csv = d / ParamsCsvName("rcal", run - 1);
    const pid_t pid = integration::Spawn({LOGGER_EXE, "--dir", d.string(), "--lcm-url", url},
                                         d / ("logger_" + std::to_string(run) + ".log"));
    ASSERT_GT(pid, 0);
    // Publish this run's parameters (poses_used = run) until the logger has written three rows.
    kinematic_params_t m{};
    m.robot_id = "test";
    m.model_id = "test";
    m.num_params = 1;
    m.names = {"a" + std::to_string(run)};
    m.values = {0.5 * run};
    m.sigmas = {0.1};
    m.identified = {true};
    m.poses_used = run;
    std::string header;
    const bool written =
        integration::Until([&] { return CsvRows(csv, &header).size() >= 3; },
                           [&] {
                             m.utime += 1000;
                             lcm.publish("KINEMATIC_PARAMS", &m);
                             std::this_thread::sleep_for(std::chrono::milliseconds(20));
                           },
                           60);
    EXPECT_TRUE(written) << csv;
    ::kill(pid, SIGINT);
    EXPECT_EQ(integration::Wait(pid), 0);
  }
  for (int run = 1; run <= 2; ++run) {
    SCOPED_TRACE("run " + std::to_string(run));
    EXPECT_TRUE(fs::exists(d / LogFileName("rcal", run - 1)));
    std::string header;
    const auto rows = CsvRows(d / ParamsCsvName("rcal", run - 1), &header);
    EXPECT_EQ(header,
              "utime,poses_used,a" + std::to_string(run) + ",sigma_a" + std::to_string(run));
    EXPECT_GE(rows.size(), 3u);
    for (const auto& [utime, poses] : rows) EXPECT_EQ(poses, run) << "row of utime " << utime;
  }
  EXPECT_FALSE(fs::exists(d / LogFileName("rcal", 2)));
  EXPECT_FALSE(fs::exists(d / "kinematic_params.csv"));
  fs::remove_all(d);
}

// --cell FILE: the CSV history follows the cell's KINEMATIC_PARAMS channel (here KP_CELL); the
// default channel's messages are still recorded in the log but are not this cell's parameters.
TEST(LogFiles, TheLoggerTakesTheParameterChannelFromTheCell) {
  RCAL_IN_NAMESPACE("LogFiles.TheLoggerTakesTheParameterChannelFromTheCell");
  const fs::path d = fs::temp_directory_path() / ("rcal_logger_cell_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  std::string text;
  {
    std::ifstream in(RCAL_SOURCE_DIR "/config/cells/grb3016_poses.yaml");
    text.assign(std::istreambuf_iterator<char>(in), {});
  }
  const std::string rel = "../robots/grb3016.yaml";
  ASSERT_NE(text.find(rel), std::string::npos);
  text.replace(text.find(rel), rel.size(), RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  text += "channels: {kinematic_params: KP_CELL}\n";
  std::ofstream(d / "cell.yaml") << text;
  const std::string url = "udpm://239.255.76.67:7742?ttl=0";
  lcm::LCM lcm(url);
  ASSERT_TRUE(lcm.good());
  const pid_t pid = integration::Spawn({LOGGER_EXE, "--cell", (d / "cell.yaml").string(), "--dir",
                                        (d / "lcm").string(), "--lcm-url", url},
                                       d / "logger.log");
  ASSERT_GT(pid, 0);
  kinematic_params_t m{};
  m.robot_id = "test";
  m.model_id = "test";
  m.num_params = 1;
  m.names = {"a"};
  m.values = {0.5};
  m.sigmas = {0.1};
  m.identified = {true};
  const fs::path csv = d / "lcm" / ParamsCsvName("rcal", 0);
  std::string header;
  const bool written =
      integration::Until([&] { return CsvRows(csv, &header).size() >= 3; },
                         [&] {
                           m.utime += 1000;
                           m.poses_used = 1;  // the cell's channel
                           lcm.publish("KP_CELL", &m);
                           m.poses_used = 2;  // not the cell's channel
                           lcm.publish("KINEMATIC_PARAMS", &m);
                           std::this_thread::sleep_for(std::chrono::milliseconds(20));
                         },
                         60);
  EXPECT_TRUE(written) << csv;
  ::kill(pid, SIGINT);
  EXPECT_EQ(integration::Wait(pid), 0);
  for (const auto& [utime, poses] : CsvRows(csv, &header))
    EXPECT_EQ(poses, 1) << "row of utime " << utime;
  // Both channels are in the log.
  std::ifstream in(d / "lcm" / LogFileName("rcal", 0), std::ios::binary);
  const std::string log((std::istreambuf_iterator<char>(in)), {});
  EXPECT_NE(log.find("KP_CELL"), std::string::npos);
  EXPECT_NE(log.find("KINEMATIC_PARAMS"), std::string::npos);
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
