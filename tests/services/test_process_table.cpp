// The supervisor's process table parser (services/supervisor/process_table.*, schema
// rcal.processes/1): the shipped table, every key, and the errors (unknown keys, wrong types,
// missing or duplicate entries) naming the key and the line.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>

#include "process_table.hpp"

namespace rcal::services {
namespace {

std::string ErrorOf(const std::string& text) {
  try {
    ParseProcessTable(text, "t.yaml");
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST(ProcessTable, TheShippedTableStartsTheLoggerFirst) {
  const auto t = LoadProcessTable(RCAL_SOURCE_DIR "/config/processes.yaml");
  ASSERT_GE(t.processes.size(), 4u);
  EXPECT_EQ(t.processes.front().name, "logger");
  for (const char* name : {"ekf_identifier", "sensor_acquisition", "ik_corrector", "orientation_kf",
                           "position_kf", "aided_ins"}) {
    bool found = false;
    for (const auto& p : t.processes) found |= p.name == name && p.argv.at(0) == name;
    EXPECT_TRUE(found) << name;
  }
}

TEST(ProcessTable, TheDemoTableParses) {
  // deploy/rcal-up --demo: the sensor-level chain, logger first, the sensors started last.
  const auto t = LoadProcessTable(RCAL_SOURCE_DIR "/config/processes.demo.yaml");
  std::vector<std::string> names;
  for (const auto& p : t.processes) {
    names.push_back(p.name);
    EXPECT_EQ(p.argv.at(0), p.name);
  }
  EXPECT_EQ(names, (std::vector<std::string>{"logger", "ekf_identifier", "still_window",
                                             "sensor_acquisition"}));
  const auto& sa = t.processes.back().argv;
  EXPECT_NE(std::find(sa.begin(), sa.end(), "--linger"), sa.end());
  EXPECT_NE(std::find(sa.begin(), sa.end(), "sensors"), sa.end());
}

TEST(ProcessTable, EveryKey) {
  const auto t = ParseProcessTable(R"(
schema: rcal.processes/1
lcm_url: udpm://239.255.76.67:7999?ttl=0
log_dir: /tmp/x
policy:
  backoff_initial: 0.25
  backoff_factor: 3
  backoff_max: 10
  healthy_run: 20
  fast_crash: 2
  max_fast_crashes: 4
  crash_window: 30
  stop_timeout: 1.5
  startup_grace: 7
processes:
  - name: a
    command: [prog_a, --flag, "1"]
    heartbeat_timeout: 3
  - name: b
    command: [/bin/true]
)");
  EXPECT_EQ(t.lcm_url, "udpm://239.255.76.67:7999?ttl=0");
  EXPECT_EQ(t.log_dir, "/tmp/x");
  EXPECT_EQ(t.policy.backoff_initial, 0.25);
  EXPECT_EQ(t.policy.backoff_factor, 3);
  EXPECT_EQ(t.policy.backoff_max, 10);
  EXPECT_EQ(t.policy.healthy_run, 20);
  EXPECT_EQ(t.policy.fast_crash, 2);
  EXPECT_EQ(t.policy.max_fast_crashes, 4);
  EXPECT_EQ(t.policy.crash_window, 30);
  EXPECT_EQ(t.policy.stop_timeout, 1.5);
  EXPECT_EQ(t.policy.startup_grace, 7);
  ASSERT_EQ(t.processes.size(), 2u);
  EXPECT_EQ(t.processes[0].name, "a");
  EXPECT_EQ(t.processes[0].argv, (std::vector<std::string>{"prog_a", "--flag", "1"}));
  EXPECT_EQ(t.processes[0].heartbeat_timeout, 3);
  EXPECT_EQ(t.processes[1].heartbeat_timeout, 0);
}

TEST(ProcessTable, DefaultsWhenOptionalKeysAreAbsent) {
  const auto t = ParseProcessTable(
      "schema: rcal.processes/1\nprocesses:\n  - name: a\n"
      "    command: [a]\n");
  EXPECT_EQ(t.lcm_url, "");
  EXPECT_EQ(t.log_dir, "log");
  EXPECT_EQ(t.policy.backoff_initial, supervisor::Policy{}.backoff_initial);
  EXPECT_EQ(t.policy.stop_timeout, supervisor::Policy{}.stop_timeout);
}

TEST(ProcessTable, ErrorsNameTheKeyAndTheLine) {
  const std::string ok_procs = "processes:\n  - name: a\n    command: [a]\n";
  // Schema missing or wrong.
  EXPECT_NE(ErrorOf(ok_procs).find("schema"), std::string::npos);
  EXPECT_NE(ErrorOf("schema: rcal.processes/2\n" + ok_procs).find("schema"), std::string::npos);
  // Unknown keys at every level.
  EXPECT_NE(
      ErrorOf("schema: rcal.processes/1\nlog_dri: x\n" + ok_procs).find("log_dri: unknown key"),
      std::string::npos);
  EXPECT_NE(ErrorOf("schema: rcal.processes/1\npolicy:\n  backof_max: 3\n" + ok_procs)
                .find("policy.backof_max: unknown key (line 3)"),
            std::string::npos);
  const std::string unknown_in_process = ErrorOf(
      "schema: rcal.processes/1\nprocesses:\n  - name: a\n    command: [a]\n    restart: no\n");
  EXPECT_NE(unknown_in_process.find("restart"), std::string::npos) << unknown_in_process;
  EXPECT_NE(unknown_in_process.find("line 5"), std::string::npos) << unknown_in_process;
  // Wrong types.
  const std::string wrong_type =
      ErrorOf("schema: rcal.processes/1\npolicy:\n  stop_timeout: soon\n" + ok_procs);
  EXPECT_NE(wrong_type.find("policy.stop_timeout"), std::string::npos) << wrong_type;
  EXPECT_NE(wrong_type.find("t.yaml"), std::string::npos) << wrong_type;
  // Processes: required, non-empty, named, unique, with a command.
  EXPECT_NE(ErrorOf("schema: rcal.processes/1\n").find("processes"), std::string::npos);
  EXPECT_NE(ErrorOf("schema: rcal.processes/1\nprocesses: []\n").find("processes"),
            std::string::npos);
  EXPECT_NE(ErrorOf("schema: rcal.processes/1\nprocesses:\n  - command: [a]\n").find("name"),
            std::string::npos);
  EXPECT_NE(ErrorOf("schema: rcal.processes/1\nprocesses:\n  - name: a\n    command: [a]\n"
                    "  - name: a\n    command: [b]\n")
                .find("duplicate"),
            std::string::npos);
  EXPECT_NE(ErrorOf("schema: rcal.processes/1\nprocesses:\n  - name: a\n    command: []\n")
                .find("command"),
            std::string::npos);
  // Not YAML at all.
  EXPECT_FALSE(ErrorOf("schema: [unclosed\n").empty());
}

}  // namespace
}  // namespace rcal::services
