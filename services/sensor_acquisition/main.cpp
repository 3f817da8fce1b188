// sensor_acquisition: the pipeline's sources. Source `sim` (pose level): the truth robot of
// libs/sim (nominal model + the paper's Table 3 errors) stops at joint configurations sampled
// inside the limits; each stop is published as JOINTS and as a POSE_MEASUREMENT with the noise
// model's covariance, at `--rate` stops per second of sensor time.
//
// The stream for --seed S and --poses N is exactly the calibration set of the offline
// `rcal experiment paper --seed S` with N poses: joints drawn in blocks of N (1000 when
// unlimited) from mt19937_64(S·1000 + 3), each block then measured in order from the same
// generator. Sensor time starts at --start-utime and advances 1/rate per pose; --speed paces
// it against the wall clock (1: real time, 0: as fast as possible).
// Sensor-level IMU/POSITION streams from the simulator come with the sensor-level simulator.
//
// Source `replay FILE`: a raw-stream CSV in the BROAD layout (sources.hpp) published as IMU (every
// row) and POSITION (decimated to --position-rate), utime from the file; or a pose dataset
// (columns q1..qN, x, y, z, ...) published as JOINTS + POSE_MEASUREMENT per pose (utime from its
// time column, else --start-utime + k/--rate; noise σ from --position-noise/--orientation-noise).
// Paced by --speed (1: real time, 0: as fast as possible; over udpm a burst larger than the
// receivers' socket buffers is dropped: use a finite speed or recv_buf_size=N in the LCM URL).
// A real sensor driver implements rcal::sensors::SensorSource.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <optional>
#include <thread>

#include "rcal/io/robot_urdf.hpp"
#include "rcal/services/common.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"
#include "sources.hpp"

namespace {

// Publishes a source's samples, pacing recorded ones by utime against the wall clock.
int RunSource(rcal::sensors::SensorSource& source, rcal::transport::Transport& t, double speed) {
  using namespace rcal;
  namespace ch = transport::channels;
  transport::Health health("sensor_acquisition");
  spdlog::info("sensor_acquisition: {}, speed {}", source.Describe(), speed);
  std::optional<int64_t> utime0;
  long long wall0 = 0;
  int64_t published = 0;
  while (!services::StopRequested() && !source.Finished()) {
    const auto e = source.Next(100);
    if (!e) continue;
    const int64_t utime = sensors::Utime(*e);
    if (!utime0) {
      utime0 = utime;
      wall0 = services::MonotonicMicros();
    }
    if (source.Recorded() && speed > 0) {
      const long long due = wall0 + static_cast<long long>((utime - *utime0) / speed);
      while (!services::StopRequested()) {
        const long long now = services::MonotonicMicros();
        if (now >= due) break;
        std::this_thread::sleep_for(std::chrono::microseconds(std::min(due - now, 50'000LL)));
      }
    }
    bool ok = false;
    if (const auto* imu = std::get_if<transport::ImuSample>(&*e))
      ok = t.Publish(ch::kImu, transport::ToMessage(*imu));
    else if (const auto* pos = std::get_if<transport::PositionSample>(&*e))
      ok = t.Publish(ch::kPosition, transport::ToMessage(*pos));
    else if (const auto* js = std::get_if<joint_state_t>(&*e))
      ok = t.Publish(ch::kJoints, *js);
    else
      ok = t.Publish(ch::kPoseMeasurement, std::get<pose_measurement_t>(*e));
    if (ok) {
      health.Published();
      ++published;
    } else {
      health.Error("publish failed at utime " + std::to_string(utime));
    }
    health.Tick(utime, t);
    t.HandleTimeout(0);  // keeps LCM's receive queue empty
  }
  spdlog::info("done: {} samples published", published);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace rcal;
  namespace ch = transport::channels;
  std::string source = "sim", robot_path = "config/robots/grb3016.yaml", lcm_url;
  unsigned seed = 1;
  int poses = 0;
  double rate = 2.0, speed = 1.0, position_noise = 5e-5, orientation_noise = 1.745e-3;
  bool position_only = false;
  int64_t start_utime = 1'000'000;
  CLI::App app{
      "sensor_acquisition: publishes the pipeline's sensor streams.\n"
      "Source sim: the simulated GRB3016 (Table 3 errors) publishes JOINTS and POSE_MEASUREMENT "
      "per still pose, HEALTH at 1 Hz of sensor time.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  std::string replay_file;
  rcal::sensors::RawCsvReplaySettings replay;
  app.add_option("--source", source, "sim | replay (FILE: a raw-stream CSV, BROAD layout)")
      ->check(CLI::IsMember({"sim", "replay"}))
      ->capture_default_str();
  app.add_option("--robot", robot_path, "robot YAML or URDF")->capture_default_str();
  app.add_option("--seed", seed, "random seed (the offline experiment's)")->capture_default_str();
  app.add_option("--poses", poses, "poses to publish, then exit (0: unlimited)")
      ->capture_default_str();
  app.add_option("--rate", rate, "poses per second of sensor time")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--speed", speed, "sensor time per wall time (0: as fast as possible)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--start-utime", start_utime, "sensor time of the first pose [µs]")
      ->capture_default_str();
  app.add_option("--position-noise", position_noise, "σ per axis [m]")->capture_default_str();
  app.add_option("--orientation-noise", orientation_noise, "σ per axis [rad]")
      ->capture_default_str();
  app.add_flag("--position-only", position_only, "position-only measurements");
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  app.add_option("file", replay_file,
                 "replay: the raw-stream CSV (t_s, gyr_*, acc_*, mag_*, pos_*)");
  app.add_option("--position-rate", replay.position_rate,
                 "replay: POSITION rate [Hz] (0: every row)")
      ->capture_default_str();
  app.add_option("--mag-scale", replay.mag_scale, "replay: magnetometer file unit → T")
      ->capture_default_str();
  app.add_option("--position-sigma", replay.position_sigma,
                 "replay: σ per axis in the POSITION covariance [m]")
      ->capture_default_str();
  app.add_option("--max-rows", replay.max_rows, "replay: rows to publish (0: all)")
      ->capture_default_str();
  app.add_option("--utime-offset", replay.utime_offset, "replay: added to every utime [µs]")
      ->capture_default_str();
  bool include_test = false;
  app.add_flag("--include-test", include_test,
               "replay of a pose dataset: also the rows of the test set");
  CLI11_PARSE(app, argc, argv);
  if (source == "replay" && replay_file.empty()) {
    std::fprintf(stderr, "sensor_acquisition: --source replay needs FILE\n");
    return 2;
  }

  try {
    services::InstallStopHandlers();
    transport::LcmTransport t(lcm_url);
    if (source == "replay") {
      const std::string path = services::RepoPath(replay_file);
      if (sensors::IsRawStreamCsv(path)) {
        sensors::RawCsvReplaySource src(path, replay);
        return RunSource(src, t, speed);
      }
      sensors::PoseDatasetReplaySettings ps;
      ps.rate = rate;
      ps.start_utime = start_utime;
      ps.position_sigma = position_noise;
      ps.orientation_sigma = orientation_noise;
      ps.include_test = include_test;
      sensors::PoseDatasetReplaySource src(path, ps);
      return RunSource(src, t, speed);
    }
    const auto robot = io::LoadRobot(services::RepoPath(robot_path));
    const auto& model = robot.model;
    const Eigen::VectorXd x_true = sim::Table3Errors(model);
    sim::PoseNoise noise;
    noise.position_sigma = position_noise;
    noise.orientation_sigma = orientation_noise;
    noise.orientation = !position_only;
    sim::Rng rng(seed * 1000 + 3);
    transport::Health health("sensor_acquisition");
    spdlog::info("sensor_acquisition sim on {}: {} poses at {} Hz, speed {}", t.url(),
                 poses > 0 ? std::to_string(poses) : "unlimited", rate, speed);

    const int block = poses > 0 ? poses : 1000;
    std::vector<Eigen::VectorXd> qs;
    size_t next = 0;
    const long long wall0 = services::MonotonicMicros();
    const double period_us = 1e6 / rate;
    for (int k = 0; (poses == 0 || k < poses) && !services::StopRequested(); ++k) {
      if (next == qs.size()) {
        qs = sim::SampleJoints(model, block, rng);
        next = 0;
      }
      const Eigen::VectorXd& q = qs[next++];
      const int64_t utime = start_utime + static_cast<int64_t>(std::llround(k * period_us));
      if (speed > 0) {
        const long long due = wall0 + static_cast<long long>((utime - start_utime) / speed);
        while (!services::StopRequested()) {
          const long long now = services::MonotonicMicros();
          if (now >= due) break;
          std::this_thread::sleep_for(std::chrono::microseconds(std::min(due - now, 50'000LL)));
        }
      }
      const auto z = sim::MeasurePose(model, x_true, q, noise, rng);
      if (t.Publish(ch::kJoints, transport::ToJointState(model, q, utime))) health.Published();
      if (t.Publish(ch::kPoseMeasurement, transport::ToMessage(z, utime, k))) health.Published();
      health.Tick(utime, t);
      t.HandleTimeout(0);  // keeps LCM's receive queue empty
    }
    spdlog::info("done");
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
