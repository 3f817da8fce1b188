// Pose measurements from LCM event logs (tools/rcal/pose_log.cpp): the events written with
// lcm::LogFile (what lcm-logger writes) read back bit-exact, bad events skipped and counted with
// the field named, and `rcal analyze LOG` finding an effect hidden in a log's poses.
#include "pose_log.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <random>
#include <tuple>

#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/cell/online_identification.hpp"
#include "rcal/cell/sim_cell.hpp"
#include "rcal/imu_sample_t.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/joint_state_t.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/sim/effects.hpp"
#include "rcal/sim/imu_stream.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/sim/sensor_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal_cli.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;
constexpr const char* kChannel = transport::channels::kPoseMeasurement;

// A fresh folder per name and process (ctest runs this file's tests as parallel processes).
fs::path TempDir(const std::string& name) {
  return testing::TempDir("test_pose_log", name);
}

// The GRB3016 as `rcal analyze --frames auto` builds it for position data: a world ← base frame
// and a flange → marker offset.
kinematics::KinematicModel CellModel() {
  io::RobotSpec spec = io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml").spec;
  spec.base = io::FrameSpec{};
  spec.markers = {io::MarkerSpec{}};
  return io::BuildModel(spec);
}

void WriteEvent(lcm::LogFile& log, int64_t utime, const void* data, int size) {
  lcm::LogEvent e;
  e.eventnum = 0;
  e.timestamp = utime;
  e.channel = kChannel;
  e.datalen = size;
  e.data = const_cast<void*>(data);
  ASSERT_EQ(log.writeEvent(&e), 0);
}

void WritePose(lcm::LogFile& log, const pose_measurement_t& msg) {
  std::vector<unsigned char> buf(msg.getEncodedSize());
  msg.encode(buf.data(), 0, static_cast<int>(buf.size()));
  WriteEvent(log, msg.utime, buf.data(), static_cast<int>(buf.size()));
}

// `rcal analyze DIR/run.lcmlog ARGS --out DIR/out` (output in DIR/stdout.txt); its analysis.json.
nlohmann::json RunAnalyze(const fs::path& dir, const std::string& args) {
  const std::string cmd = std::string(RCAL_EXE) + " analyze " + (dir / "run.lcmlog").string() +
                          " " + args + " --out " + (dir / "out").string() + " > " +
                          (dir / "stdout.txt").string() + " 2>&1";
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::ifstream in(dir / "out" / "analysis.json");
  if (!in.good()) {
    ADD_FAILURE() << "no analysis.json from " << cmd;
    return {};
  }
  return nlohmann::json::parse(in);
}

TEST(PoseLog, ReadsValidPosesBitExactAndCountsEveryBadEvent) {
  const auto model = CellModel();
  sim::Rng rng(7);
  sim::PoseNoise noise;
  noise.orientation = true;
  const auto ms =
      sim::MeasurePoses(model, model.Nominal(), sim::SampleJoints(model, 5, rng), noise, rng);
  const fs::path path = TempDir("read") / "poses.lcmlog";
  {
    lcm::LogFile log(path.string(), "w");
    ASSERT_TRUE(log.good());
    WritePose(log, transport::ToMessage(ms[0], 1'000'000, 0));
    WritePose(log, transport::ToMessage(ms[1], 2'000'000, 1));
    const unsigned char junk[5] = {1, 2, 3, 4, 5};
    WriteEvent(log, 2'500'000, junk, 5);                        // does not decode
    WritePose(log, transport::ToMessage(ms[2], 2'000'000, 2));  // repeated time
    auto nan = transport::ToMessage(ms[3], 3'000'000, 3);
    nan.p[1] = std::numeric_limits<double>::quiet_NaN();
    WritePose(log, nan);
    WritePose(log, transport::ToMessage(ms[4], 4'000'000, 4));
  }
  EXPECT_TRUE(IsLcmLog(path));
  const PoseLog read = ReadPoseLog(path, model, kChannel);
  EXPECT_EQ(read.events, 6);
  EXPECT_EQ(read.skipped, 3);
  EXPECT_NE(read.first_skip_reason.find("decode"), std::string::npos) << read.first_skip_reason;
  ASSERT_EQ(read.poses.size(), 3u);
  const int expected[] = {0, 1, 4};
  for (int k = 0; k < 3; ++k) {
    const auto& z = read.poses[k].measurement;
    const auto& m = ms[expected[k]];
    EXPECT_EQ(read.poses[k].pose_index, expected[k]);
    EXPECT_EQ(z.q, m.q);
    EXPECT_EQ(z.p_WM_W, m.p_WM_W);
    EXPECT_EQ(z.covariance, m.covariance);
    EXPECT_LT((z.R_EI - m.R_EI).norm(), 1e-15);
  }
  const io::PoseDataset d = ToPoseDataset(read, model.num_joints());
  ASSERT_EQ(d.samples.size(), 3u);
  EXPECT_TRUE(d.has_orientation);
  EXPECT_DOUBLE_EQ(d.samples[2].time, 4.0);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(d.samples[k].row, k + 1);  // rcal track's JSON rows

  // Not a log: a CSV, an empty file, a missing file.
  const fs::path csv = path.parent_path() / "poses.csv";
  std::ofstream(csv) << "q1,q2\n";
  EXPECT_FALSE(IsLcmLog(csv));
  EXPECT_FALSE(IsLcmLog(path.parent_path() / "missing.lcmlog"));
  EXPECT_THROW(ReadPoseLog(path.parent_path() / "missing.lcmlog", model, kChannel),
               std::runtime_error);
}

// A log of position-only poses whose robot has a second-harmonic error on joint 3 (eccentric
// gear) of 6σ RMS beyond what geometry absorbs: `rcal analyze LOG` names it, from the log alone.
TEST(PoseLog, RcalAnalyzeFindsAnEffectHiddenInALog) {
  const auto model = CellModel();
  sim::Rng rng(21);
  sim::PoseNoise noise;
  noise.position_sigma = 5e-5;
  noise.orientation = false;
  Eigen::VectorXd x = sim::Table3Errors(model);
  x(model.FindParameter("base_x")) = 1.2;
  const int n = 80;
  const auto qs = sim::SampleJoints(model, n, rng);
  const std::vector<kinematics::EffectContext> ctx(n);
  const kinematics::Effect hidden{kinematics::EffectCause::kJointPeriodic, 2, 2};
  const auto truth = sim::MakeEffectTruth(
      model, {sim::EffectOfSize(model, hidden, qs, ctx, x, 6 * noise.position_sigma, rng, {},
                                /*beyond_geometry=*/true)});
  const auto ms = sim::MeasurePosesWithEffects(truth, x, qs, ctx, noise, rng);
  const fs::path dir = TempDir("analyze");
  {
    lcm::LogFile log((dir / "run.lcmlog").string(), "w");
    for (int k = 0; k < n; ++k) WritePose(log, transport::ToMessage(ms[k], 1'000'000 * (k + 1), k));
  }
  const nlohmann::json j =
      RunAnalyze(dir, " --robot " RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  ASSERT_FALSE(j.is_null());
  ASSERT_EQ(j.at("effects").size(), 1u) << j.at("effects").dump();
  const auto& e = j.at("effects")[0];
  EXPECT_EQ(e.at("cause"), "joint_periodic");
  EXPECT_EQ(e.at("joints")[0], model.joints()[2].name);
  EXPECT_GT(j.at("gain").at("relative_gain").get<double>(), 0.2);
}

// Full poses from the pipeline: positions in the position sensor's frame, orientations in the
// IMU's earth frame (magnetic north 50° from the sensor's x axis, an IMU mounted turned by 20°).
// `rcal analyze LOG` adds the earth ← world and flange → IMU rotations for a log, so a clean log
// shows no effect and the noise it estimates is the simulated noise.
TEST(PoseLog, RcalAnalyzeIdentifiesTheEarthFrameOfALogsOrientations) {
  io::RobotSpec spec = io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml").spec;
  spec.base = io::FrameSpec{};
  spec.markers = {io::MarkerSpec{}};
  spec.imu = io::FrameSpec{};
  spec.earth = io::FrameSpec{};
  const auto model = io::BuildModel(spec);
  sim::Rng rng(5);
  sim::PoseNoise noise;
  noise.position_sigma = 5e-5;
  noise.orientation_sigma = 2e-4;
  noise.orientation = true;
  Eigen::VectorXd x = sim::Table3Errors(model);
  x(model.FindParameter("base_x")) = 1.2;
  x(model.FindParameter("earth_rz")) = 0.87;
  x(model.FindParameter("imu_rz")) = 0.35;
  const int n = 60;
  const auto ms = sim::MeasurePoses(model, x, sim::SampleJoints(model, n, rng), noise, rng);
  const fs::path dir = TempDir("earth");
  {
    lcm::LogFile log((dir / "run.lcmlog").string(), "w");
    for (int k = 0; k < n; ++k) WritePose(log, transport::ToMessage(ms[k], 1'000'000 * (k + 1), k));
  }
  const nlohmann::json j =
      RunAnalyze(dir, " --robot " RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  ASSERT_FALSE(j.is_null());
  EXPECT_TRUE(j.at("effects").empty()) << j.at("effects").dump();
  EXPECT_NEAR(j.at("position_noise_m").get<double>(), 5e-5, 1.5e-5);
  EXPECT_NEAR(j.at("orientation_noise_rad").get<double>(), 2e-4, 0.6e-4);
}

// The IMU channel of a log (`rcal analyze LOG --imu`): a simulated stream with a magnet passing
// (8 µT for 8 s) recorded as imu_sample_t (field in tesla) plus one sample out of order and one
// without a field; the analysis names the disturbance from the log alone and says that without a
// truth orientation the gain cannot be measured.
TEST(PoseLog, RcalAnalyzeImuNamesAMagneticDisturbanceInALog) {
  sim::ImuStreamSettings ss;
  ss.rest_s = 15.0;
  ss.motion_s = 15.0;
  sim::ImuStreamEffects fx;
  fx.mag_disturbance = true;
  fx.mag_disturbance_start_s = 20.0;
  fx.mag_disturbance_end_s = 28.0;
  fx.mag_disturbance_uT = Eigen::Vector3d(8.0, 0.0, 0.0);
  std::mt19937_64 rng(3);
  const auto stream = sim::SimulateImuStream(ss, fx, rng);
  const fs::path dir = TempDir("imu");
  {
    lcm::LogFile log((dir / "run.lcmlog").string(), "w");
    const auto write = [&](const imu_sample_t& m) {
      std::vector<unsigned char> buf(m.getEncodedSize());
      m.encode(buf.data(), 0, static_cast<int>(buf.size()));
      lcm::LogEvent e;
      e.eventnum = 0;
      e.timestamp = m.utime;
      e.channel = transport::channels::kImu;
      e.datalen = static_cast<int32_t>(buf.size());
      e.data = buf.data();
      ASSERT_EQ(log.writeEvent(&e), 0);
    };
    for (size_t k = 0; k < stream.size(); ++k) {
      imu_sample_t m{};
      m.utime = static_cast<int64_t>(std::llround(stream[k].t * 1e6)) + 1'000'000;
      for (int i = 0; i < 3; ++i) {
        m.gyro[i] = stream[k].gyro(i);
        m.accel[i] = stream[k].accel(i);
        m.mag[i] = stream[k].mag_uT(i) * 1e-6;
      }
      m.has_mag = true;
      write(m);
      if (k == 100) write(m);  // repeated time: skipped
      if (k == 200) {
        m.utime += 1;
        m.has_mag = false;  // no field: skipped
        write(m);
      }
    }
  }
  const nlohmann::json j = RunAnalyze(dir, " --imu");
  ASSERT_FALSE(j.is_null());
  EXPECT_EQ(j.at("kind"), "imu_stream");
  bool magnetic = false;
  for (const auto& e : j.at("effects")) magnetic |= e.at("cause") == "magnetic_disturbance";
  EXPECT_TRUE(magnetic) << j.at("effects").dump();
  std::ifstream out_text(dir / "stdout.txt");
  const std::string text((std::istreambuf_iterator<char>(out_text)), {});
  EXPECT_NE(text.find("2 of"), std::string::npos) << text;  // the two bad events counted
}

// A log recorded the way the demo records it: sensor_acquisition --source sim --level sensors
// (the GRB3016 cell, stops of 1.5 s between minimum-jerk moves, every 100 Hz tick published as
// JOINTS then IMU with the field in tesla) as the logger writes it; `joints` false leaves the
// JOINTS channel out. Returns the trajectory (its still intervals are the truth of the rests).
sim::JointTrajectory WriteDemoLikeLog(const fs::path& log_path, int stops, unsigned seed,
                                      bool joints, bool mag_disturbance) {
  const auto robot = io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  const cell::Cell cell = cell::MakeCell(robot.spec, seed);
  sim::Rng rng(seed * 1000 + 3);
  std::vector<Eigen::VectorXd> waypoints = {sim::SampleJoints(cell.model, 1, rng).front()};
  for (const auto& q : sim::SampleJoints(cell.model, stops, rng)) waypoints.push_back(q);
  sim::TrajectorySettings ts;
  ts.still_time = 1.5;
  const sim::JointTrajectory trajectory(waypoints, ts);
  const sim::ToolMotionTruth truth(cell.model, cell.x_true, trajectory);
  sim::SensorSimSettings ss;
  ss.mag_disturbance = mag_disturbance;
  sim::SensorSim sensors(truth, ss, seed);
  lcm::LogFile log(log_path.string(), "w");
  const auto write = [&](const char* channel, int64_t utime, const auto& m) {
    std::vector<unsigned char> buf(m.getEncodedSize());
    m.encode(buf.data(), 0, static_cast<int>(buf.size()));
    lcm::LogEvent e;
    e.eventnum = 0;
    e.timestamp = utime;
    e.channel = channel;
    e.datalen = static_cast<int32_t>(buf.size());
    e.data = buf.data();
    ASSERT_EQ(log.writeEvent(&e), 0);
  };
  const int64_t start = 1'000'000;
  while (const auto f = sensors.Next()) {
    const int64_t utime = start + std::llround(f->t * 1e6);
    if (joints)
      write(transport::channels::kJoints, utime, transport::ToJointState(cell.model, f->q, utime));
    imu_sample_t m{};
    m.utime = utime;
    for (int i = 0; i < 3; ++i) {
      m.gyro[i] = f->imu.gyro_S(i);
      m.accel[i] = f->imu.accel_S(i);
      m.mag[i] = f->imu.mag_S(i) * 1e-6;
    }
    m.has_mag = true;
    write(transport::channels::kImu, utime, m);
  }
  return trajectory;
}

// `rcal analyze LOG --imu` on the demo's kind of log: its stops are 1.5 s, far from the 3 s rests
// the analysis asked for (it refused the demo's own log: "no rest segment of at least 3 s").
// With the JOINTS channel the rests are the arm's stops: one per stop, each inside the stop's
// truth still interval; the analysis runs on short rests and says what they cannot test (the
// long-τ Allan test), the reference is pooled over several rests, and on the clean log nothing
// but the arm's own acceleration (accel_motion: the accelerometer sees the moves) is named.
// Without JOINTS the rests are detected from the IMU, and the analysis still runs.
TEST(PoseLog, RcalAnalyzeImuRunsOnTheDemosShortStops) {
  const int stops = 12;
  for (const bool joints : {true, false}) {
    SCOPED_TRACE(joints ? "with JOINTS" : "IMU only");
    const fs::path dir = TempDir(joints ? "imu_demo_joints" : "imu_demo_imu_only");
    const sim::JointTrajectory trajectory =
        WriteDemoLikeLog(dir / "run.lcmlog", stops, 1, joints, false);
    const nlohmann::json j = RunAnalyze(dir, " --imu");
    ASSERT_FALSE(j.is_null());
    std::ifstream out_text(dir / "stdout.txt");
    const std::string text((std::istreambuf_iterator<char>(out_text)), {});
    const auto& rests = j.at("rests");
    EXPECT_TRUE(rests.at("short").get<bool>());
    EXPECT_GE(rests.at("reference_rests").get<int>(), 2);
    EXPECT_GE(rests.at("reference_s").get<double>(), 3.0);
    EXPECT_NE(rests.at("note").get<std::string>().find("long-τ Allan test"), std::string::npos);
    EXPECT_NE(text.find("short rests:"), std::string::npos) << text;
    const auto& segments = j.at("rest_segments_s");
    if (joints) {
      EXPECT_NE(rests.at("source").get<std::string>().find("JOINTS"), std::string::npos);
      // One rest per stop (the home pose and each calibration stop), inside its still interval.
      ASSERT_EQ(static_cast<int>(segments.size()), trajectory.num_waypoints());
      for (int k = 0; k < trajectory.num_waypoints(); ++k) {
        const auto [t0, t1] = trajectory.StillInterval(k);
        const double b = segments[k][0].get<double>() - 1.0, e = segments[k][1].get<double>() - 1.0;
        EXPECT_GE(b, t0 - 1e-9) << "stop " << k;
        EXPECT_LE(e, t1 + 1e-9) << "stop " << k;
        EXPECT_GE(e - b, 1.0) << "stop " << k;  // 1.5 s less the settle time at each end
      }
    } else {
      EXPECT_EQ(rests.at("source"), "detected still");
      EXPECT_GE(static_cast<int>(segments.size()), stops / 2);
    }
    std::map<std::string, nlohmann::json> cand;
    for (const auto& c : j.at("candidates")) cand[c.at("cause")] = c;
    EXPECT_TRUE(cand.at("gyro_bias").at("tested").get<bool>());
    EXPECT_NE(cand.at("gyro_bias").at("note").get<std::string>().find("drift"), std::string::npos);
    EXPECT_FALSE(cand.at("gyro_bias").at("significant").get<bool>());
    EXPECT_FALSE(cand.at("magnetic_disturbance").at("significant").get<bool>());
    EXPECT_TRUE(cand.at("accel_motion").at("significant").get<bool>());
    EXPECT_FALSE(cand.at("time_offset").at("tested").get<bool>());
  }
}

// The same short stops with a 15 µT field disturbance at a fifth of the stops (the simulator's
// magnetic disturbance of the robustness sweep): the adapted analysis still names it.
TEST(PoseLog, RcalAnalyzeImuNamesAMagneticDisturbanceAtShortStops) {
  const fs::path dir = TempDir("imu_demo_magnet");
  WriteDemoLikeLog(dir / "run.lcmlog", 12, 1, true, true);
  const nlohmann::json j = RunAnalyze(dir, " --imu");
  ASSERT_FALSE(j.is_null());
  EXPECT_TRUE(j.at("rests").at("short").get<bool>());
  bool magnetic = false;
  for (const auto& e : j.at("effects")) magnetic |= e.at("cause") == "magnetic_disturbance";
  EXPECT_TRUE(magnetic) << j.at("effects").dump();
}

// The demo's log, offline: the still windows of the demo's simulated cell
// (config/cells/grb3016.sim.yaml, here 15 stops) as POSE_MEASUREMENT events;
// `rcal calibrate --log LOG --cell config/cells/grb3016.yaml` holds the first six back for the
// set-up guess, as ekf_identifier --cell does, and reaches cell::OnlineIdentification on the same
// poses to 1e-9 (the messages carry R_EI as a quaternion: rounding only). Without a pose to
// accept it exits non-zero, saying what to check (was: every parameter 0, exit 0).
TEST(PoseLog, RcalCalibrateLogWithTheCellReachesTheOnlineIdentification) {
  const io::BuiltCell built = io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml");
  const cell::CellSimSpec sim =
      cell::LoadCellSimSpec(RCAL_SOURCE_DIR "/config/cells/grb3016.sim.yaml");
  cell::RunSettings rs = cell::SimRunSettings(built, sim);
  rs.num_cal = 15;
  rs.num_test = 0;
  const auto w = cell::SimulateWindows(cell::MakeSimCell(built, sim), rs);
  ASSERT_EQ(w.cal.size(), 15u);
  const fs::path dir = TempDir("calibrate_cell");
  {
    lcm::LogFile log((dir / "run.lcmlog").string(), "w");
    for (int k = 0; k < 15; ++k)
      WritePose(log, transport::ToMessage(w.cal[k], 1'000'000 * (k + 1), k));
  }
  const std::string cmd = std::string(RCAL_EXE) + " calibrate --log " +
                          (dir / "run.lcmlog").string() + " --cell " + RCAL_SOURCE_DIR +
                          "/config/cells/grb3016.yaml --json " + (dir / "out.json").string() +
                          " > " + (dir / "stdout.txt").string() + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::ifstream in(dir / "out.json");
  const auto j = nlohmann::json::parse(in);
  cell::OnlineIdentification online(built);
  for (int k = 0; k < 15; ++k) {
    // Through the message, as the process receives it.
    std::string error;
    const auto z =
        transport::FromMessage(transport::ToMessage(w.cal[k], 1'000'000 * (k + 1), k), &error);
    ASSERT_TRUE(z) << error;
    online.Add({*z, 1'000'000 * (k + 1), k, {}});
  }
  const Eigen::VectorXd x = online.ekf().x(), sigma = online.ekf().sigma();
  EXPECT_EQ(j.at("poses_accepted").get<int>(), online.ekf().accepted());
  EXPECT_EQ(j.at("model_id"), transport::ModelId(built.model));
  EXPECT_EQ(j.at("cell"), "grb3016_demo");
  // One entry per parameter in model order, the unit in the key (value_m / value_rad), the frame
  // its value is in named.
  const auto& params = j.at("parameters");
  ASSERT_EQ(params.size(), static_cast<size_t>(x.size()));
  for (int i = 0; i < x.size(); ++i) {
    const auto& P = built.model.parameters()[i];
    const std::string unit = P.is_angle ? "rad" : "m";
    EXPECT_EQ(params[i].at("name"), P.name);
    EXPECT_EQ(params[i].size(), 4u) << params[i].dump();
    EXPECT_FALSE(params[i].at("frame").get<std::string>().empty()) << P.name;
    EXPECT_NEAR(params[i].at("value_" + unit).get<double>(), x(i), 1e-9) << P.name;
    EXPECT_NEAR(params[i].at("sigma_" + unit).get<double>(), sigma(i), 1e-9) << P.name;
  }
  // The wrong cell for this log: the pose-level GRB3016 (no set-up frames) rejects every pose.
  const std::string wrong = std::string(RCAL_EXE) + " calibrate --log " +
                            (dir / "run.lcmlog").string() + " --cell " + RCAL_SOURCE_DIR +
                            "/config/cells/grb3016_poses.yaml > " + (dir / "wrong.txt").string() +
                            " 2>&1";
  const int status = std::system(wrong.c_str());
  EXPECT_NE(status, 0);
  std::ifstream wrong_in(dir / "wrong.txt");
  const std::string text((std::istreambuf_iterator<char>(wrong_in)), {});
  EXPECT_NE(text.find("no pose accepted"), std::string::npos) << text;
}

}  // namespace
}  // namespace rcal::tool

namespace rcal::tool {
namespace {

// `rcal calibrate --log DIR/run.lcmlog ARGS --json DIR/out.json`: exit code and output.
std::pair<int, std::string> RunCalibrateLog(const fs::path& dir, const std::string& args) {
  const std::string cmd = std::string(RCAL_EXE) + " calibrate --log " +
                          (dir / "run.lcmlog").string() + " " + args + " --json " +
                          (dir / "out.json").string() + " > " + (dir / "stdout.txt").string() +
                          " 2> " + (dir / "stderr.txt").string();
  const int status = std::system(cmd.c_str());
  std::ifstream err(dir / "stderr.txt");
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1,
          std::string((std::istreambuf_iterator<char>(err)), {})};
}

// Issue 13, item 4, on the log path: the demo cell's log (20 stops of
// config/cells/grb3016.sim.yaml) with its joints in degrees, its positions in millimetres, given
// with a cell of another arm or with a cell whose set-up frames are not the recorded cell's (the
// pose-level cell: every frame fixed at the identity, so the EKF starts 1-2 m off) is refused with
// the likely cause on stderr, never exit 0. Was: exit 0 and the parameters printed (every one 0
// with nothing accepted) in each case.
TEST(PoseLog, RcalCalibrateLogRefusesWhereUsersTrip) {
  const io::BuiltCell built = io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml");
  const cell::CellSimSpec sim =
      cell::LoadCellSimSpec(RCAL_SOURCE_DIR "/config/cells/grb3016.sim.yaml");
  cell::RunSettings rs = cell::SimRunSettings(built, sim);
  rs.num_cal = 20;
  rs.num_test = 0;
  const auto w = cell::SimulateWindows(cell::MakeSimCell(built, sim), rs);
  ASSERT_EQ(w.cal.size(), 20u);
  const auto write = [&](const fs::path& dir, double q_scale, double p_scale) {
    lcm::LogFile log((dir / "run.lcmlog").string(), "w");
    for (int k = 0; k < 20; ++k) {
      kinematics::PoseMeasurement m = w.cal[k];
      m.q *= q_scale;
      m.p_WM_W *= p_scale;
      WritePose(log, transport::ToMessage(m, 1'000'000 * (k + 1), k));
    }
  };
  const fs::path dir = TempDir("calibrate_log_trips");
  // The demo's cell with another arm's robot file.
  const auto other_arm = [&](const std::string& urdf) {
    std::ifstream in(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml");
    std::string text((std::istreambuf_iterator<char>(in)), {});
    const std::string from = "../robots/grb3016.yaml";
    text.replace(text.find(from), from.size(), std::string(RCAL_SOURCE_DIR "/") + urdf);
    const fs::path cell = dir / (fs::path(urdf).stem().string() + "_cell.yaml");
    std::ofstream(cell) << text;
    return cell.string();
  };
  const auto json = [&] {
    std::ifstream in(dir / "out.json");
    return nlohmann::json::parse(in);
  };
  const auto stdout_text = [&] {
    std::ifstream in(dir / "stdout.txt");
    return std::string((std::istreambuf_iterator<char>(in)), {});
  };
  const auto has = [](const std::string& text, const std::string& what) {
    return text.find(what) != std::string::npos;
  };
  write(dir, 1, 1);
  // The log as recorded, with its cell: a calibration (residuals at the sensor noise).
  auto [code, err] = RunCalibrateLog(dir, "--cell config/cells/grb3016.yaml");
  EXPECT_EQ(code, 0) << err;
  EXPECT_FALSE(json().at("rejected").get<bool>());
  EXPECT_LT(json().at("residual_position_sigma_m").get<double>(), 1e-4);
  // A cell whose frames are not the recorded cell's: the EKF starts at the drawing with the base
  // 1-2 m away: every pose rejected at the gate (the "0 poses accepted, 50 rejected",
  // exit 0).
  std::tie(code, err) = RunCalibrateLog(dir, "--cell config/cells/grb3016_poses.yaml");
  EXPECT_EQ(code, 3) << err;
  EXPECT_TRUE(has(err, "calibration REJECTED, these parameters are no calibration:")) << err;
  EXPECT_TRUE(has(err,
                  "the EKF rejected 20 of 20 poses at its innovation gate (refused beyond "
                  "50 %): the model does not describe the measurements: set-up frames "
                  "(world ← base, flange → marker) far from where the EKF starts them"))
      << err;
  EXPECT_FALSE(has(stdout_text(), "REJECTED"));  // the cause on stderr, not in the figures
  EXPECT_EQ(json().at("poses_accepted").get<int>(), 0);
  EXPECT_TRUE(json().at("rejected").get<bool>());
  // Another arm's file: the UR5e takes the GRB3016's joints (its limits ±2π), and its fit leaves
  // residuals of metres; the KR6's limits refuse them before the fit.
  std::tie(code, err) =
      RunCalibrateLog(dir, "--cell " + other_arm("tests/data/arms/ur5e_like.urdf"));
  EXPECT_EQ(code, 3) << err;
  EXPECT_TRUE(has(err, "is this the robot that was measured (")) << err;
  EXPECT_TRUE(has(err, "ur5e_like.urdf')?")) << err;
  std::tie(code, err) =
      RunCalibrateLog(dir, "--cell " + other_arm("tests/data/arms/kr6_like.urdf"));
  EXPECT_EQ(code, 1) << err;
  EXPECT_TRUE(has(err,
                  "poses have a joint beyond the limits of robot 'kr6_like': is this the "
                  "robot that was measured?"))
      << err;
  // Joints in degrees, positions in millimetres.
  write(dir, 180 / std::numbers::pi, 1);
  std::tie(code, err) = RunCalibrateLog(dir, "--cell config/cells/grb3016.yaml");
  EXPECT_EQ(code, 1) << err;
  EXPECT_TRUE(has(err, "lie within its limits: joints in degrees? rcal reads radians")) << err;
  write(dir, 1, 1000);
  std::tie(code, err) = RunCalibrateLog(dir, "--cell config/cells/grb3016.yaml");
  EXPECT_EQ(code, 1) << err;
  EXPECT_TRUE(has(err,
                  "and × 1e-3 every one lies within it: positions in millimetres? rcal "
                  "reads metres"))
      << err;
}

}  // namespace
}  // namespace rcal::tool
