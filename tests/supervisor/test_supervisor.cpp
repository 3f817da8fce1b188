// The supervisor's policy as a pure state machine: every expected time below is worked out by
// hand from the Policy numbers, not from the implementation.
#include "rcal/supervisor/supervisor.hpp"

#include <gtest/gtest.h>

namespace rcal::supervisor {
namespace {

using Kind = Action::Kind;

// heartbeat_timeout: sensor_acquisition's (0: not checked).
std::vector<ProcessSpec> Table(double heartbeat_timeout = 0) {
  return {{"logger", {"logger"}, 0},
          {"sensor_acquisition", {"sensor_acquisition", "--source", "sim"}, heartbeat_timeout},
          {"ekf_identifier", {"ekf_identifier"}, 0}};
}

Policy TestPolicy() {
  Policy p;
  p.backoff_initial = 1.0;
  p.backoff_factor = 2.0;
  p.backoff_max = 8.0;
  p.healthy_run = 100.0;
  p.fast_crash = 5.0;
  p.max_fast_crashes = 3;
  p.crash_window = 60.0;
  p.stop_timeout = 2.0;
  p.startup_grace = 10.0;
  return p;
}

// Starts the table at t with pids 100, 101, 102.
Supervisor Started(double t = 0, Policy policy = TestPolicy(), double heartbeat_timeout = 0) {
  Supervisor s(Table(heartbeat_timeout), policy);
  const auto a = s.StartAll(t);
  for (size_t i = 0; i < a.size(); ++i) s.OnStarted(a[i].name, 100 + static_cast<int>(i), t);
  return s;
}

std::vector<std::string> Names(const std::vector<Action>& actions) {
  std::vector<std::string> n;
  for (const auto& a : actions) n.push_back(a.name);
  return n;
}

TEST(Supervisor, StartsInTableOrder) {
  Supervisor s(Table(), TestPolicy());
  const auto a = s.StartAll(0);
  ASSERT_EQ(a.size(), 3u);
  for (const auto& x : a) EXPECT_EQ(x.kind, Kind::kStart);
  EXPECT_EQ(Names(a), (std::vector<std::string>{"logger", "sensor_acquisition", "ekf_identifier"}));
  EXPECT_TRUE(s.StartAll(1).empty());  // already running
}

TEST(Supervisor, RejectsBadTables) {
  EXPECT_THROW(Supervisor({}, {}), std::invalid_argument);
  EXPECT_THROW(Supervisor({{"a", {"x"}, 0}, {"a", {"y"}, 0}}, {}), std::invalid_argument);
  EXPECT_THROW(Supervisor({{"", {"x"}, 0}}, {}), std::invalid_argument);
  EXPECT_THROW(Supervisor({{"a", {}, 0}}, {}), std::invalid_argument);
}

TEST(Supervisor, RestartsWithExponentialBackoffCappedAtMax) {
  Policy p = TestPolicy();
  p.max_fast_crashes = 100;  // never give up here
  Supervisor s = Started(0, p);
  // Crash after 20 s each time (not fast): waits 1, 2, 4, 8, 8 s.
  double t = 0;
  int pid = 102;
  for (double wait : {1.0, 2.0, 4.0, 8.0, 8.0}) {
    t += 20;
    EXPECT_TRUE(s.OnExited(pid, 1, t).empty());
    EXPECT_EQ(s.status("ekf_identifier").state, State::kBackoff);
    EXPECT_TRUE(s.Tick(t + wait - 0.01).empty()) << wait;
    const auto a = s.Tick(t + wait);
    ASSERT_EQ(a.size(), 1u) << wait;
    EXPECT_EQ(a[0].kind, Kind::kStart);
    EXPECT_EQ(a[0].name, "ekf_identifier");
    EXPECT_NE(a[0].reason.find("exited with code 1"), std::string::npos) << a[0].reason;
    t += wait;
    s.OnStarted("ekf_identifier", ++pid, t);
  }
  EXPECT_EQ(s.status("ekf_identifier").restarts, 5);
  EXPECT_EQ(s.status("ekf_identifier").last_exit, 1);
  EXPECT_EQ(s.status("logger").restarts, 0);
}

TEST(Supervisor, HealthyRunResetsTheBackoff) {
  Supervisor s = Started();
  s.OnExited(102, -9, 20);  // wait 1
  EXPECT_EQ(s.status("ekf_identifier").last_exit, -9);
  EXPECT_NE(s.status("ekf_identifier").last_reason.find("signal 9"), std::string::npos);
  ASSERT_EQ(s.Tick(21).size(), 1u);
  s.OnStarted("ekf_identifier", 200, 21);
  s.OnExited(200, 1, 41);  // wait 2
  EXPECT_TRUE(s.Tick(42.9).empty());
  ASSERT_EQ(s.Tick(43).size(), 1u);
  s.OnStarted("ekf_identifier", 201, 43);
  s.OnExited(201, 1, 143);  // ran 100 s = healthy_run: back to 1
  EXPECT_TRUE(s.Tick(143.9).empty());
  EXPECT_EQ(s.Tick(144).size(), 1u);
}

TEST(Supervisor, GivesUpAfterRepeatedFastCrashesWithinTheWindow) {
  Supervisor s = Started();
  // Fast crashes (run < 5 s) at 1, 3, 7 s: the third gives up (max 3 within 60 s).
  s.OnExited(102, 1, 1);
  ASSERT_EQ(s.Tick(2).size(), 1u);  // 1 s backoff
  s.OnStarted("ekf_identifier", 200, 2);
  s.OnExited(200, 1, 3);
  ASSERT_EQ(s.Tick(5).size(), 1u);  // 2 s backoff
  s.OnStarted("ekf_identifier", 201, 5);
  s.OnExited(201, 1, 7);
  EXPECT_EQ(s.status("ekf_identifier").state, State::kFailed);
  EXPECT_NE(s.status("ekf_identifier").last_reason.find("gave up"), std::string::npos);
  EXPECT_TRUE(s.Tick(1000).empty());  // never restarted
  EXPECT_EQ(s.status("logger").state, State::kRunning);
}

TEST(Supervisor, FastCrashesSpreadBeyondTheWindowDoNotGiveUp) {
  Policy p = TestPolicy();
  p.backoff_max = 1.0;
  Supervisor s = Started(0, p);
  int pid = 102;
  double t = 0;
  for (int k = 0; k < 10; ++k) {
    t += 4;  // fast crash (4 s < 5 s)
    s.OnExited(pid, 1, t);
    ASSERT_NE(s.status("ekf_identifier").state, State::kFailed) << k;
    t += 31;  // 1 s backoff then 30 s: each window of 60 s holds at most 2 crashes
    ASSERT_EQ(s.Tick(t).size(), 1u);
    s.OnStarted("ekf_identifier", ++pid, t);
  }
}

TEST(Supervisor, StartFailureCountsAsACrash) {
  Supervisor s(Table(), TestPolicy());
  s.StartAll(0);
  s.OnStarted("logger", 100, 0);
  s.OnStarted("sensor_acquisition", 101, 0);
  s.OnStartFailed("ekf_identifier", "No such file", 0);
  EXPECT_EQ(s.status("ekf_identifier").state, State::kBackoff);
  EXPECT_EQ(s.status("ekf_identifier").last_exit, 127);
  EXPECT_NE(s.status("ekf_identifier").last_reason.find("No such file"), std::string::npos);
  EXPECT_EQ(s.Tick(1).size(), 1u);
}

TEST(Supervisor, StaleHeartbeatInterruptsThenKillsThenRestarts) {
  Supervisor s = Started(0, TestPolicy(), 3.0);
  // sensor_acquisition: timeout 3 s, grace 10 s. Heartbeats until 20 s.
  for (double t = 1; t <= 20; t += 1) {
    s.OnHeartbeat("sensor_acquisition", t);
    EXPECT_TRUE(s.Tick(t).empty()) << t;
  }
  EXPECT_TRUE(s.Tick(23).empty());  // exactly 3 s: not yet stale
  auto a = s.Tick(23.1);
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0], (Action{Kind::kInterrupt, "sensor_acquisition", 101, a[0].reason}));
  EXPECT_NE(a[0].reason.find("heartbeat stale"), std::string::npos);
  EXPECT_EQ(s.status("sensor_acquisition").state, State::kStopping);
  EXPECT_TRUE(s.Tick(25.0).empty());  // SIGKILL due at 25.1
  a = s.Tick(25.1);
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0].kind, Kind::kKill);
  EXPECT_EQ(a[0].pid, 101);
  EXPECT_TRUE(s.Tick(26).empty());  // killed once
  s.OnExited(101, -9, 26);
  EXPECT_EQ(s.status("sensor_acquisition").state, State::kBackoff);
  a = s.Tick(27);
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0].kind, Kind::kStart);
  EXPECT_NE(a[0].reason.find("heartbeat stale"), std::string::npos) << a[0].reason;
}

TEST(Supervisor, NoHeartbeatAtAllIsStaleAfterGracePlusTimeout) {
  Supervisor s = Started(100, TestPolicy(), 3.0);
  EXPECT_TRUE(s.Tick(113).empty());  // 100 + 10 grace + 3 timeout
  const auto a = s.Tick(113.5);
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0].name, "sensor_acquisition");
  // Processes without a heartbeat timeout are never checked.
  EXPECT_EQ(s.status("ekf_identifier").state, State::kRunning);
  EXPECT_EQ(s.status("logger").state, State::kRunning);
}

TEST(Supervisor, ShutdownStopsInReverseOrderOneAtATimeLoggerLast) {
  Supervisor s = Started();
  auto a = s.Shutdown(50);
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0], (Action{Kind::kInterrupt, "ekf_identifier", 102, "shutdown"}));
  EXPECT_FALSE(s.Done());
  EXPECT_TRUE(s.Tick(51).empty());  // waits for the exit
  a = s.OnExited(102, 0, 51);
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0], (Action{Kind::kInterrupt, "sensor_acquisition", 101, "shutdown"}));
  // sensor_acquisition ignores SIGINT: SIGKILL after 2 s, then the logger.
  EXPECT_TRUE(s.Tick(52.9).empty());
  a = s.Tick(53);
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0].kind, Kind::kKill);
  EXPECT_EQ(a[0].name, "sensor_acquisition");
  a = s.OnExited(101, -9, 53.1);
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0], (Action{Kind::kInterrupt, "logger", 100, "shutdown"}));
  EXPECT_TRUE(s.OnExited(100, 0, 53.2).empty());
  EXPECT_TRUE(s.Done());
  for (const auto& st : s.Status()) EXPECT_EQ(st.state, State::kStopped) << st.name;
  EXPECT_EQ(s.status("ekf_identifier").restarts, 0);  // a stop is not a restart
}

TEST(Supervisor, ShutdownCancelsScheduledRestartsAndSkipsFailed) {
  Supervisor s = Started();
  s.OnExited(102, 1, 10);  // ekf_identifier in backoff
  auto a = s.Shutdown(10.5);
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0].name, "sensor_acquisition");
  EXPECT_EQ(s.status("ekf_identifier").state, State::kStopped);
  a = s.OnExited(101, 0, 11);
  EXPECT_EQ(Names(a), std::vector<std::string>{"logger"});
  // A process that exits on its own during shutdown is not restarted.
  a = s.OnExited(100, 0, 11.5);
  EXPECT_TRUE(a.empty());
  EXPECT_TRUE(s.Tick(100).empty());
  EXPECT_TRUE(s.Done());
}

TEST(Supervisor, UnknownPidsAndNamesAreIgnored) {
  Supervisor s = Started();
  EXPECT_TRUE(s.OnExited(999, 0, 1).empty());
  s.OnHeartbeat("nobody", 1);
  EXPECT_TRUE(s.Tick(2).empty());
  for (const auto& st : s.Status()) EXPECT_EQ(st.state, State::kRunning);
  EXPECT_THROW(s.status("nobody"), std::out_of_range);
}

TEST(Supervisor, StateNames) {
  EXPECT_STREQ(ToString(State::kStopped), "stopped");
  EXPECT_STREQ(ToString(State::kRunning), "running");
  EXPECT_STREQ(ToString(State::kBackoff), "backoff");
  EXPECT_STREQ(ToString(State::kStopping), "stopping");
  EXPECT_STREQ(ToString(State::kFailed), "failed");
}

}  // namespace
}  // namespace rcal::supervisor
