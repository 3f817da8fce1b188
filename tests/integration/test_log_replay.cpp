// A recorded LCM log replayed through the identifier gives the live run's parameters. Inside a
// private network namespace on a non-default port: sensor_acquisition (sim) → ekf_identifier,
// recorded by lcm-logger; then the log's POSE_MEASUREMENT events played with lcm-logplayer into
// a fresh ekf_identifier, and read offline by `rcal calibrate-log`. Both must give the live run's
// final KINEMATIC_PARAMS to 1e-9. The README's replay recipe ("The live pipeline") is this replay:
// keep the two in step.
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <thread>

#include "netns.hpp"
#include "rcal/calibration_status_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal {
namespace {

using namespace integration;
namespace ch = transport::channels;
constexpr const char* kUrl = "udpm://239.255.76.67:7715?ttl=0";  // not the default port
constexpr int kPoses = 40;
constexpr double kRate = 20;  // poses per second of sensor time
constexpr int64_t kStartUtime = 1'000'000;
constexpr int64_t kLastUtime = kStartUtime + (kPoses - 1) * 50'000;

struct Listener {
  transport::LcmTransport t{kUrl};
  std::map<int64_t, kinematic_params_t> params;
  int statuses = 0;
  Listener() {
    t.Subscribe<kinematic_params_t>(ch::kKinematicParams,
                                    [this](const kinematic_params_t& m) { params[m.utime] = m; });
    t.Subscribe<calibration_status_t>(ch::kCalibrationStatus,
                                      [this](const calibration_status_t&) { ++statuses; });
  }
  bool WaitFor(const std::function<bool()>& done) {
    return Until(done, [this] { t.HandleTimeout(100); });
  }
};

std::vector<std::string> Identifier() {
  return {RCAL_EKF_IDENTIFIER, "--cell", RCAL_SOURCE_DIR "/config/cells/grb3016_poses.yaml",
          "--lcm-url", kUrl};
}

std::string ReadText(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

class LogReplay : public ProcessFixture {};

TEST_F(LogReplay, LogPlayerThroughIdentifierAndCalibrateLogEqualTheLiveRun) {
  RCAL_IN_NAMESPACE("LogReplay.LogPlayerThroughIdentifierAndCalibrateLogEqualTheLiveRun");
  const fs::path log = dir_ / "live.lcmlog";
  kinematic_params_t live;
  {
    Listener l;
    const pid_t id = Start(Identifier(), "ekf_identifier_live.log");
    ASSERT_TRUE(l.WaitFor([&] { return l.statuses > 0; }));  // it announces itself at start
    const pid_t logger =
        Start({RCAL_LCM_LOGGER_PATH, "-f", "--lcm-url=" + std::string(kUrl), log.string()},
              "lcm-logger.log");
    // lcm-logger is recording once a probe shows up in its file (flushed every 100 ms). Events
    // are written in order, so once a probe published after some message is in the file, that
    // message is too. (Waiting for the file to grow was not enough: on a loaded machine
    // lcm-logger wrote the first 21 of 40 poses by then and lost the rest at SIGINT.)
    auto probe_in_log = [&](const std::string& channel) {
      return Until(
          [&] { return fs::exists(log) && ReadText(log).find(channel) != std::string::npos; },
          [&] {
            const char probe[] = "probe";
            l.t.PublishRaw(channel, probe, sizeof probe);
            l.t.HandleTimeout(50);
          });
    };
    ASSERT_TRUE(probe_in_log("PROBE_START"));
    const pid_t src = Start({RCAL_SENSOR_ACQUISITION, "--source", "sim", "--sim",
                             RCAL_SOURCE_DIR "/config/cells/grb3016_poses.sim.yaml", "--poses",
                             std::to_string(kPoses), "--rate", std::to_string(kRate), "--speed",
                             "1", "--start-utime", std::to_string(kStartUtime), "--lcm-url", kUrl},
                            "sensor_acquisition.log");
    // Keep reading while the poses flow (the socket buffer is small).
    ASSERT_TRUE(l.WaitFor([&] { return l.params.count(kLastUtime) > 0; }));
    ASSERT_EQ(Wait(src), 0);
    Reaped(src);
    live = l.params.at(kLastUtime);
    EXPECT_EQ(live.poses_used, kPoses);
    // lcm-logger has the last messages once a probe published after them is in the file.
    ASSERT_TRUE(probe_in_log("PROBE_END"));
    EXPECT_EQ(Stop(logger), 0);
    EXPECT_EQ(Stop(id), 0);
  }

  // The log's pose measurements through a fresh identifier with lcm-logplayer.
  {
    Listener l;
    const pid_t id = Start(Identifier(), "ekf_identifier_replay.log");
    ASSERT_TRUE(l.WaitFor([&] { return l.statuses > 0; }));
    const pid_t player = Start({RCAL_LCM_LOGPLAYER_PATH, "--lcm-url=" + std::string(kUrl),
                                "--regexp=^POSE_MEASUREMENT$", "--speed=4", log.string()},
                               "lcm-logplayer.log");
    ASSERT_TRUE(l.WaitFor([&] { return l.params.count(kLastUtime) > 0; }));
    Wait(player);
    Reaped(player);
    const kinematic_params_t& replay = l.params.at(kLastUtime);
    EXPECT_EQ(replay.poses_used, live.poses_used);
    ASSERT_EQ(replay.num_params, live.num_params);
    for (int i = 0; i < live.num_params; ++i) {
      EXPECT_EQ(replay.names[i], live.names[i]);
      EXPECT_NEAR(replay.values[i], live.values[i], 1e-9) << live.names[i];
      EXPECT_NEAR(replay.sigmas[i], live.sigmas[i], 1e-9) << live.names[i];
    }
    EXPECT_EQ(Stop(id), 0);
  }

#ifdef RCAL_TOOL
  // The same log offline.
  const fs::path json = dir_ / "calibrate_log.json";
  const std::string cmd = std::string(RCAL_TOOL) + " calibrate-log " + log.string() +
                          " --cell " RCAL_SOURCE_DIR "/config/cells/grb3016_poses.yaml --json " +
                          json.string() + " > " + (dir_ / "calibrate_log.out").string();
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  const auto j = nlohmann::json::parse(std::ifstream(json));
  EXPECT_EQ(j["poses_accepted"].get<int>(), live.poses_used);
  ASSERT_EQ(static_cast<int>(j["parameters"].size()), live.num_params);
  for (int i = 0; i < live.num_params; ++i) {
    const auto& p = j["parameters"][i];
    EXPECT_EQ(p["name"].get<std::string>(), live.names[i]);
    const auto& value = p.contains("value_m") ? p["value_m"] : p["value_rad"];
    const auto& sigma = p.contains("sigma_m") ? p["sigma_m"] : p["sigma_rad"];
    EXPECT_NEAR(value.get<double>(), live.values[i], 1e-9) << live.names[i];
    EXPECT_NEAR(sigma.get<double>(), live.sigmas[i], 1e-9) << live.names[i];
  }
#endif
}

}  // namespace
}  // namespace rcal
