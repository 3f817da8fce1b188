// dds_bridge as a real process between real LCM (UDP multicast) and real DDS (Cyclone, loopback
// config), inside a private network namespace, on a non-default LCM port and DDS domain:
//   - a separate DDS subscriber process (rcal_dds_echo) started after the bridge forwarded the
//     parameters, with no LCM publisher alive any more, gets the latest parameters and status at
//     once (transient-local), equal bit for bit to what was published on LCM;
//   - the bridge survives a restart of the LCM publisher (SIGKILL, new process, new values) and
//     forwards the new values; a late subscriber then gets those;
//   - every DDS message names the robot; KINEMATIC_PARAMS of another robot are rejected (HEALTH);
//   - with the real ekf_identifier fed simulated poses, SIGKILLed and restarted from its
//     checkpoint: the bridge forwards what the identifier publishes before and after, and a late
//     subscriber gets exactly the identifier's last KINEMATIC_PARAMS as seen on LCM.
//
// The truth is tests/dds/test_messages.hpp (what rcal_dds_test_publisher publishes). Run outside
// a namespace, the test re-runs itself under deploy/netns-run (skipped when `unshare -n` is not
// permitted). Waits have generous guards only to turn a hang into a failure; nothing is timed.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <sstream>
#include <thread>

#include "dds_reader.hpp"
#include "process_helpers.hpp"
#include "rcal/dds/convert.hpp"
#include "rcal/dds/dds_common.hpp"
#include "rcal/health_t.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_transport.hpp"
#include "test_messages.hpp"

#ifdef RCAL_EKF_IDENTIFIER
#include "rcal/io/robot_urdf.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/transport/adapters.hpp"
#endif

namespace rcal::dds {
namespace {

namespace fs = std::filesystem;
using testing::Alive;
using testing::Spawn;
using testing::TestParams;
using testing::TestStatus;
using testing::TestUtime;
using testing::Wait;

constexpr const char* kUrl = "udpm://239.255.76.67:7723?ttl=0";  // not the default port
constexpr int kDomain = 77;                                      // not the default domain
constexpr const char* kRobot = "robot_a";

// Polls `done` until true or the guard runs out (false).
bool WaitFor(const std::function<bool()>& done, double guard_s = 60) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(guard_s);
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

// One line of rcal_dds_echo as key → value.
std::map<std::string, std::string> Fields(const std::string& line) {
  std::map<std::string, std::string> out;
  std::istringstream in(line);
  std::string word;
  in >> out["topic"];
  while (in >> word) {
    const auto eq = word.find('=');
    if (eq != std::string::npos) out[word.substr(0, eq)] = word.substr(eq + 1);
  }
  return out;
}

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  std::string item;
  while (std::getline(in, item, ',')) out.push_back(item);
  return out;
}

bool SameBits(double a, double b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

// The stamp of an echo line is utime, independently of convert.cpp's arithmetic.
void ExpectStamp(const std::map<std::string, std::string>& f, int64_t utime) {
  const int64_t sec = std::stoll(f.at("sec")), ns = std::stoll(f.at("nanosec"));
  EXPECT_EQ(ns % 1000, 0);
  EXPECT_LT(ns, 1'000'000'000);
  EXPECT_EQ(sec * 1'000'000 + ns / 1000, utime);
}

// An echo line of kinematic_params equals the LCM message published, bit for bit.
void ExpectParams(const std::string& line, const kinematic_params_t& m) {
  const auto f = Fields(line);
  ASSERT_EQ(f.at("topic"), "kinematic_params") << line;
  ExpectStamp(f, m.utime);
  EXPECT_EQ(f.at("frame_id"), "base");
  EXPECT_EQ(f.at("robot_id"), m.robot_id);
  EXPECT_EQ(f.at("model_id"), m.model_id);
  EXPECT_EQ(Split(f.at("names")), m.names);
  const auto values = Split(f.at("values")), sigmas = Split(f.at("sigmas")),
             identified = Split(f.at("identified"));
  ASSERT_EQ(values.size(), m.values.size());
  ASSERT_EQ(sigmas.size(), m.sigmas.size());
  ASSERT_EQ(identified.size(), m.identified.size());
  for (size_t i = 0; i < values.size(); ++i) {
    EXPECT_TRUE(SameBits(std::strtod(values[i].c_str(), nullptr), m.values[i]))
        << m.names[i] << ": " << values[i];
    EXPECT_TRUE(SameBits(std::strtod(sigmas[i].c_str(), nullptr), m.sigmas[i]))
        << m.names[i] << ": " << sigmas[i];
    EXPECT_EQ(identified[i] == "1", m.identified[i] != 0) << m.names[i];
  }
  EXPECT_EQ(std::stoi(f.at("poses_used")), m.poses_used);
}

void ExpectStatus(const std::string& line, const calibration_status_t& m) {
  const auto f = Fields(line);
  ASSERT_EQ(f.at("topic"), "calibration_status") << line;
  ExpectStamp(f, m.utime);
  EXPECT_EQ(f.at("robot_id"), kRobot);
  EXPECT_EQ(std::stoi(f.at("poses_accepted")), m.poses_accepted);
  EXPECT_EQ(std::stoi(f.at("poses_rejected")), m.poses_rejected);
  EXPECT_TRUE(SameBits(std::strtod(f.at("condition_number").c_str(), nullptr), m.condition_number));
  EXPECT_TRUE(SameBits(std::strtod(f.at("rms_position_residual").c_str(), nullptr),
                       m.rms_position_residual));
  EXPECT_TRUE(SameBits(std::strtod(f.at("rms_orientation_residual").c_str(), nullptr),
                       m.rms_orientation_residual));
  EXPECT_TRUE(SameBits(std::strtod(f.at("last_nis").c_str(), nullptr), m.last_nis));
  EXPECT_EQ(std::stoi(f.at("relinearizations")), m.relinearizations);
  EXPECT_EQ(f.at("converged") == "1", m.converged != 0);
}

std::string ReadAll(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

using dds::testing::Reader;

class DdsBridge : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("rcal_dds_bridge_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override {
    for (pid_t p : pids_) {
      kill(-p, SIGKILL);
      waitpid(p, nullptr, 0);
    }
    if (!HasFailure()) fs::remove_all(dir_);
  }
  pid_t Start(const std::vector<std::string>& argv, const std::string& name) {
    const pid_t p = Spawn(argv, dir_ / (name + ".out"), dir_ / (name + ".err"));
    pids_.push_back(p);
    return p;
  }
  void Kill(pid_t p) {
    kill(-p, SIGKILL);
    waitpid(p, nullptr, 0);
    std::erase(pids_, p);
  }
  pid_t Publisher(int version, const std::string& robot = kRobot, bool ins = false) {
    return Start({RCAL_DDS_TEST_PUBLISHER, "--lcm-url", kUrl, "--version", std::to_string(version),
                  "--robot-id", robot, "--ins", ins ? "1" : "0"},
                 "publisher" + std::to_string(version) + robot + (ins ? "_ins" : ""));
  }
  // Runs rcal_dds_echo to completion; returns its output lines.
  std::vector<std::string> Echo(const std::string& topic, int count, const std::string& name) {
    const pid_t p = Start({RCAL_DDS_ECHO, "--domain", std::to_string(kDomain), "--topic", topic,
                           "--count", std::to_string(count), "--guard", "60"},
                          name);
    const int rc = Wait(p);
    std::erase(pids_, p);
    EXPECT_EQ(rc, 0) << name << ": " << ReadAll(dir_ / (name + ".err"));
    std::vector<std::string> lines;
    std::istringstream in(ReadAll(dir_ / (name + ".out")));
    for (std::string l; std::getline(in, l);) lines.push_back(l);
    return lines;
  }
  fs::path dir_;
  std::vector<pid_t> pids_;
};

TEST_F(DdsBridge, LateSubscriberGetsLatestExactValuesAndBridgeSurvivesPublisherRestart) {
  RCAL_IN_NAMESPACE(
      "DdsBridge.LateSubscriberGetsLatestExactValuesAndBridgeSurvivesPublisherRestart");
  // Every process here (bridge, echo, this test) uses the repository's loopback configuration.
  setenv("CYCLONEDDS_URI", LoopbackConfigUri().c_str(), 1);

  // The bridge's heartbeats and rejections, on LCM.
  transport::LcmTransport lcm(kUrl);
  std::optional<health_t> health;
  lcm.Subscribe<health_t>(transport::channels::kHealth, [&](const health_t& h) {
    if (h.process == "dds_bridge") health = h;
  });
  auto pump = [&] {
    while (lcm.HandleTimeout(0) > 0) {
    }
  };

  // The bridge starts without CYCLONEDDS_URI: it must choose the loopback file itself.
  unsetenv("CYCLONEDDS_URI");
  const pid_t bridge = Start({RCAL_DDS_BRIDGE, "--robot-id", kRobot, "--lcm-url", kUrl,
                              "--dds-domain", std::to_string(kDomain)},
                             "bridge");
  setenv("CYCLONEDDS_URI", LoopbackConfigUri().c_str(), 1);
  ASSERT_TRUE(WaitFor([&] {
    lcm.HandleTimeout(50);
    return health.has_value();
  })) << "no HEALTH from the bridge: "
      << ReadAll(dir_ / "bridge.err");

  EXPECT_NE(ReadAll(dir_ / "bridge.out").find("(CYCLONEDDS_URI " + LoopbackConfigUri() + ")"),
            std::string::npos)
      << ReadAll(dir_ / "bridge.out");

  // What the bridge forwards, seen from a DDS participant in this process.
  EntityGuard participant(dds_create_participant(kDomain, nullptr, nullptr));
  ASSERT_GT(participant.get(), 0);
  Reader<KinematicParams> params(participant.get(), kKinematicParamsTopic, LatchedQos());
  Reader<CalibrationStatus> status(participant.get(), kCalibrationStatusTopic, LatchedQos());
  Reader<ToolPose> pose(participant.get(), kToolPoseTopic, StreamQos());
  int poses = 0, poses_with_orientation = 0;
  std::optional<int32_t> poses_used;
  std::optional<int64_t> status_utime;
  std::vector<std::string> robot_ids;
  auto take = [&] {
    params.Take([&](const KinematicParams& d) {
      robot_ids.push_back(d.robot_id);
      poses_used = d.poses_used;
    });
    status.Take([&](const CalibrationStatus& d) {
      robot_ids.push_back(d.robot_id);
      status_utime = int64_t{d.header.stamp.sec} * 1'000'000 + d.header.stamp.nanosec / 1000;
    });
    pose.Take([&](const ToolPose& d) {
      robot_ids.push_back(d.robot_id);
      EXPECT_STREQ(d.header.frame_id, "meas");
      ++poses;
      poses_with_orientation += d.has_orientation;
    });
  };

  // ---- version 1 ------------------------------------------------------------------------------
  pid_t publisher = Publisher(1);
  ASSERT_TRUE(WaitFor([&] {
    take();
    pump();
    return poses_used == TestParams(1).poses_used && status_utime == TestUtime(1) && poses >= 3 &&
           poses_with_orientation >= 1;
  })) << ReadAll(dir_ / "bridge.err");
  // No LCM publisher from here on: whatever a new subscriber gets, the bridge's writers kept.
  Kill(publisher);

  const auto p1 = Echo("kinematic_params", 1, "echo_params_1");
  ASSERT_EQ(p1.size(), 1u);
  ExpectParams(p1[0], TestParams(1));
  const auto s1 = Echo("calibration_status", 1, "echo_status_1");
  ASSERT_EQ(s1.size(), 1u);
  ExpectStatus(s1[0], TestStatus(1));

  // ---- the LCM publisher restarts with new values -----------------------------------------------
  publisher = Publisher(2);
  ASSERT_TRUE(WaitFor([&] {
    take();
    pump();
    return poses_used == TestParams(2).poses_used && status_utime == TestUtime(2);
  })) << ReadAll(dir_ / "bridge.err");
  Kill(publisher);
  EXPECT_TRUE(Alive(bridge)) << "the bridge exited: " << ReadAll(dir_ / "bridge.err");

  const auto p2 = Echo("kinematic_params", 1, "echo_params_2");
  ASSERT_EQ(p2.size(), 1u);
  ExpectParams(p2[0], TestParams(2));  // the latest only (depth 1), not version 1
  const auto s2 = Echo("calibration_status", 1, "echo_status_2");
  ASSERT_EQ(s2.size(), 1u);
  ExpectStatus(s2[0], TestStatus(2));

  // ---- another robot's parameters are not this bridge's: rejected, named in HEALTH -------------
  const int64_t rejected_before = health->rejected;
  publisher = Publisher(3, "robot_b");
  ASSERT_TRUE(WaitFor([&] {
    lcm.HandleTimeout(50);
    return health->rejected > rejected_before;
  })) << ReadAll(dir_ / "bridge.err");
  EXPECT_NE(health->last_error.find("kinematic_params.robot_id"), std::string::npos)
      << health->last_error;
  Kill(publisher);
  take();
  EXPECT_EQ(poses_used, TestParams(2).poses_used);  // robot_b's parameters never reached DDS
  EXPECT_TRUE(Alive(bridge));

  // Every DDS message named this bridge's robot.
  ASSERT_FALSE(robot_ids.empty());
  for (const auto& id : robot_ids) EXPECT_EQ(id, kRobot);

  // SIGINT (how the supervisor stops it) ends the bridge cleanly.
  kill(bridge, SIGINT);
  EXPECT_EQ(Wait(bridge), 0) << ReadAll(dir_ / "bridge.err");
  std::erase(pids_, bridge);
}

// --tool-pose-from ins: the tool pose comes from aided_ins's channels (INS_TOOL_POSITION,
// INS_ORIENTATION), exactly as from the filters'; the filters' own channels are then not the
// bridge's (a publisher on them brings no pose).
TEST_F(DdsBridge, TheToolPoseCanComeFromTheTrackerAidedIns) {
  RCAL_IN_NAMESPACE("DdsBridge.TheToolPoseCanComeFromTheTrackerAidedIns");
  setenv("CYCLONEDDS_URI", LoopbackConfigUri().c_str(), 1);
  transport::LcmTransport lcm(kUrl);
  std::optional<health_t> health;
  lcm.Subscribe<health_t>(transport::channels::kHealth, [&](const health_t& h) {
    if (h.process == "dds_bridge") health = h;
  });
  const pid_t bridge = Start({RCAL_DDS_BRIDGE, "--robot-id", kRobot, "--lcm-url", kUrl,
                              "--dds-domain", std::to_string(kDomain), "--tool-pose-from", "ins"},
                             "bridge");
  ASSERT_TRUE(WaitFor([&] {
    lcm.HandleTimeout(50);
    return health.has_value();
  })) << ReadAll(dir_ / "bridge.err");
  EXPECT_NE(
      ReadAll(dir_ / "bridge.out").find("tool pose from INS_TOOL_POSITION and INS_ORIENTATION"),
      std::string::npos)
      << ReadAll(dir_ / "bridge.out");
  EntityGuard participant(dds_create_participant(kDomain, nullptr, nullptr));
  ASSERT_GT(participant.get(), 0);
  Reader<ToolPose> pose(participant.get(), kToolPoseTopic, StreamQos());
  int poses = 0, poses_with_orientation = 0;
  double x = 0.0;
  auto take = [&] {
    pose.Take([&](const ToolPose& d) {
      ++poses;
      poses_with_orientation += d.has_orientation;
      x = d.position[0];
    });
  };
  // The filters' channels: nothing reaches DDS for a second and a half.
  pid_t publisher = Publisher(1, kRobot, false);
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(1500);
  while (std::chrono::steady_clock::now() < until) {
    take();
    lcm.HandleTimeout(50);
  }
  EXPECT_EQ(poses, 0);
  Kill(publisher);
  // aided_ins's channels: the poses, with their orientation, the publisher's values.
  publisher = Publisher(1, kRobot, true);
  ASSERT_TRUE(WaitFor([&] {
    take();
    lcm.HandleTimeout(20);
    return poses >= 3 && poses_with_orientation >= 1;
  })) << ReadAll(dir_ / "bridge.err");
  Kill(publisher);
  EXPECT_NEAR(x, testing::TestToolPosition(1, 0).p[0], 0.1);  // 0.5 + version + 1e-3 k
  kill(bridge, SIGINT);
  EXPECT_EQ(Wait(bridge), 0) << ReadAll(dir_ / "bridge.err");
  std::erase(pids_, bridge);
}

#ifdef RCAL_EKF_IDENTIFIER
TEST_F(DdsBridge, ForwardsTheRealIdentifierAcrossItsRestart) {
  RCAL_IN_NAMESPACE("DdsBridge.ForwardsTheRealIdentifierAcrossItsRestart");
  setenv("CYCLONEDDS_URI", LoopbackConfigUri().c_str(), 1);
  const std::string robot_yaml = RCAL_SOURCE_DIR "/config/robots/grb3016.yaml";
  const auto model = io::LoadRobot(robot_yaml).model;

  // The identifier's outputs on LCM: the truth the DDS side must equal.
  transport::LcmTransport lcm(kUrl);
  std::optional<kinematic_params_t> lcm_params;
  int statuses = 0;
  bool bridge_up = false;
  lcm.Subscribe<kinematic_params_t>(transport::channels::kKinematicParams,
                                    [&](const kinematic_params_t& m) { lcm_params = m; });
  lcm.Subscribe<calibration_status_t>(transport::channels::kCalibrationStatus,
                                      [&](const calibration_status_t&) { ++statuses; });
  lcm.Subscribe<health_t>(transport::channels::kHealth, [&](const health_t& h) {
    bridge_up = bridge_up || h.process == "dds_bridge";
  });

  const pid_t bridge = Start({RCAL_DDS_BRIDGE, "--robot-id", model.name(), "--lcm-url", kUrl,
                              "--dds-domain", std::to_string(kDomain)},
                             "bridge");
  ASSERT_TRUE(WaitFor([&] {
    lcm.HandleTimeout(50);
    return bridge_up;
  })) << ReadAll(dir_ / "bridge.err");

  EntityGuard participant(dds_create_participant(kDomain, nullptr, nullptr));
  ASSERT_GT(participant.get(), 0);
  Reader<KinematicParams> params(participant.get(), kKinematicParamsTopic, LatchedQos());
  std::optional<int32_t> dds_poses_used;
  std::vector<std::string> robot_ids;
  auto take = [&] {
    params.Take([&](const KinematicParams& d) {
      robot_ids.push_back(d.robot_id);
      dds_poses_used = d.poses_used;
    });
  };

  // Simulated still-pose measurements of the truth robot (Table 3 errors).
  sim::Rng rng(7);
  const auto poses = sim::MeasurePoses(model, sim::Table3Errors(model),
                                       sim::SampleJoints(model, 8, rng), sim::PoseNoise{}, rng);
  const fs::path checkpoint = dir_ / "ekf.checkpoint.json";
  const std::vector<std::string> identifier = {RCAL_EKF_IDENTIFIER,
                                               "--cell",
                                               RCAL_SOURCE_DIR "/config/cells/grb3016_poses.yaml",
                                               "--checkpoint",
                                               checkpoint.string(),
                                               "--lcm-url",
                                               kUrl};
  // Starts the identifier, waits for its start-up CALIBRATION_STATUS (it is listening then),
  // feeds poses [from, to) one at a time, each after the previous one was published.
  auto run = [&](size_t from, size_t to, const std::string& log) {
    // Handle what earlier processes published first, so an old status is not taken for the new
    // process's start-up status (no identifier is running here, nothing more is coming).
    while (lcm.HandleTimeout(100) > 0) {
    }
    const int before = statuses;
    const pid_t p = Start(identifier, log);
    EXPECT_TRUE(WaitFor([&] {
      lcm.HandleTimeout(50);
      return statuses > before;
    })) << ReadAll(dir_ / (log + ".err"));
    for (size_t k = from; k < to; ++k) {
      lcm.Publish(transport::channels::kPoseMeasurement,
                  transport::ToMessage(poses[k], 1'000'000 * static_cast<int64_t>(k + 1),
                                       static_cast<int32_t>(k)));
      EXPECT_TRUE(WaitFor([&] {
        lcm.HandleTimeout(50);
        return lcm_params && lcm_params->poses_used == static_cast<int32_t>(k + 1);
      })) << "pose "
          << k << ": " << ReadAll(dir_ / (log + ".err"));
    }
    return p;
  };

  const pid_t first = run(0, 5, "identifier1");
  ASSERT_TRUE(lcm_params);
  ASSERT_TRUE(WaitFor([&] {
    take();
    return dds_poses_used == 5;
  }));
  Kill(first);  // SIGKILL: no clean shutdown

  const pid_t second = run(5, 8, "identifier2");  // resumes from the checkpoint
  ASSERT_TRUE(lcm_params);
  ASSERT_EQ(lcm_params->poses_used, 8);
  ASSERT_TRUE(WaitFor([&] {
    take();
    return dds_poses_used == 8;
  }));
  Kill(second);
  EXPECT_TRUE(Alive(bridge)) << ReadAll(dir_ / "bridge.err");

  // A late subscriber, no identifier running: the identifier's last message, bit for bit.
  const auto late = Echo("kinematic_params", 1, "echo_identifier");
  ASSERT_EQ(late.size(), 1u);
  ExpectParams(late[0], *lcm_params);
  for (const auto& id : robot_ids) EXPECT_EQ(id, model.name());
}
#endif  // RCAL_EKF_IDENTIFIER

}  // namespace
}  // namespace rcal::dds
