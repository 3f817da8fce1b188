// A cell run by ROS 2 drivers, as real processes inside a private network namespace: the
// simulated demo cell played by ros2_sim_drivers as its drivers would publish it over Cyclone DDS
// with the ROS 2 wire types (JointState 125 Hz with the names shuffled and a gripper joint added,
// Imu + MagneticField 100 Hz on a clock +37 ms off the arm's, PointStamped from the tracker on a
// clock −120 ms off, 0.5 ms stamp jitter) → ros2_input (clock offsets estimated and removed) →
// still_window → ekf_identifier, and dds_bridge --cell publishing the results in ROS 2 terms.
//
//   * the calibration reaches ≤ 1.5× the offline figure of the same cell (the offline
//     `rcal experiment paper --sensors` computation, as SensorPipeline);
//   * each driver's clock offset is recovered within 2 ms and locked;
//   * the arm's temperature (sensor_msgs/Temperature) and payload (geometry_msgs/InertiaStamped)
//     reach ARM_CONDITIONS as one stream, and every pose carries the temperature;
//   * TF (rt/tf_static) carries exactly the identified set-up frames, diagnostics every process;
//   * a restarted IMU driver (its stamps jump back) is re-synchronised and its offset re-locked;
//   * malformed and oversized samples are counted in ros2_input's HEALTH and never crash it;
//   * an arm that grows as it warms (ros2_sim_drivers --sim-effect), its temperature coming as
//     sensor_msgs/Temperature: the identifier's discrepancy watch names thermal growth and
//     identifies κ live.
// ctest label: ros2. Guards only turn a hang into a failure; nothing asserts on time.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <optional>
#include <set>

#include "dds_reader.hpp"
#include "netns.hpp"
#include "rcal/arm_conditions_t.hpp"
#include "rcal/calibration_status_t.hpp"
#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/cell/sim_cell.hpp"
#include "rcal/clock_offset_t.hpp"
#include "rcal/dds/dds_common.hpp"
#include "rcal/dds/ros2_convert.hpp"
#include "rcal/dds/setup_frames.hpp"
#include "rcal/health_t.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/calibration_export.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/joint_state_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/model_discrepancy_t.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/sim/effects.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_transport.hpp"
#include "sim_schedule.hpp"

namespace rcal {
namespace {

using integration::ProcessFixture;
constexpr const char* kUrl = "udpm://239.255.76.67:7721?ttl=0&recv_buf_size=8388608";
constexpr const char* kCell = RCAL_SOURCE_DIR "/config/cells/grb3016.yaml";
constexpr const char* kSim = RCAL_SOURCE_DIR "/config/cells/grb3016.sim.yaml";
constexpr unsigned kSeed = 1;
constexpr int kCal = 25, kTest = 50;

using dds::testing::Reader;

dds_qos_t* Reliable(bool transient_local) {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  if (transient_local) dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, transient_local ? 1 : 100);
  return q;
}

// What the LCM side of a run showed.
struct CellRun {
  std::optional<kinematic_params_t> params;
  std::optional<calibration_status_t> status;
  std::optional<clock_offset_t> clocks;
  std::optional<health_t> input_health, window_health;
  int joints = 0;
  // Wall time [s] from the JOINTS sample at a window's end leaving ros2_input to its
  // POSE_MEASUREMENT reaching this test: the still window closing, and the identifier's input.
  std::vector<double> pose_latency_s;
  std::deque<std::pair<int64_t, double>> joints_wall;  // (utime, wall [s]) of recent JOINTS
  std::vector<pose_measurement_t> poses;
  std::vector<model_discrepancy_t> discrepancies;  // every MODEL_DISCREPANCY
  std::vector<arm_conditions_t> conditions;        // every ARM_CONDITIONS
};

double WallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

class Ros2Cell : public ProcessFixture {
 protected:
  void SetUp() override {
    ProcessFixture::SetUp();
    setenv("CYCLONEDDS_URI", dds::LoopbackConfigUri().c_str(), 1);
  }
  void Listen(transport::LcmTransport& t, CellRun& run) {
    namespace ch = transport::channels;
    t.Subscribe<kinematic_params_t>(ch::kKinematicParams,
                                    [&](const kinematic_params_t& m) { run.params = m; });
    t.Subscribe<calibration_status_t>(ch::kCalibrationStatus,
                                      [&](const calibration_status_t& m) { run.status = m; });
    t.Subscribe<clock_offset_t>(ch::kClockOffset, [&](const clock_offset_t& m) { run.clocks = m; });
    t.Subscribe<joint_state_t>(ch::kJoints, [&](const joint_state_t& m) {
      ++run.joints;
      run.joints_wall.emplace_back(m.utime, WallSeconds());
      if (run.joints_wall.size() > 20000) run.joints_wall.pop_front();
    });
    t.Subscribe<pose_measurement_t>(ch::kPoseMeasurement, [&](const pose_measurement_t& m) {
      run.poses.push_back(m);
      for (const auto& [u, wall] : run.joints_wall)
        if (u >= m.utime) {
          run.pose_latency_s.push_back(WallSeconds() - wall);
          break;
        }
    });
    t.Subscribe<arm_conditions_t>(ch::kArmConditions,
                                  [&](const arm_conditions_t& m) { run.conditions.push_back(m); });
    t.Subscribe<model_discrepancy_t>(ch::kModelDiscrepancy, [&](const model_discrepancy_t& m) {
      run.discrepancies.push_back(m);
    });
    t.Subscribe<health_t>(ch::kHealth, [&](const health_t& h) {
      if (h.process == "ros2_input") run.input_health = h;
      if (h.process == "still_window") run.window_health = h;
    });
  }
  // ros2_input, still_window, ekf_identifier (and dds_bridge) on the demo cell, then the drivers
  // with `driver_args` at `speed`× real time (the identifier with `ekf_args`); runs until the
  // drivers are done and the identifier has judged every window.
  CellRun RunCell(const std::vector<std::string>& driver_args, bool bridge,
                  const std::function<void()>& while_running = {}, const std::string& speed = "5",
                  const std::vector<std::string>& ekf_args = {}) {
    CellRun run;
    transport::LcmTransport t(kUrl);
    Listen(t, run);
    std::vector<std::string> ekf_cmd = {RCAL_EKF_IDENTIFIER,
                                        "--lcm-url",
                                        kUrl,
                                        "--cell",
                                        kCell,
                                        "--checkpoint",
                                        (dir_ / "ekf.checkpoint.json").string()};
    ekf_cmd.insert(ekf_cmd.end(), ekf_args.begin(), ekf_args.end());
    const pid_t ekf = Start(ekf_cmd, "ekf_identifier.log");
    const pid_t sw =
        Start({RCAL_STILL_WINDOW, "--lcm-url", kUrl, "--cell", kCell}, "still_window.log");
    const pid_t in = Start({RCAL_ROS2_INPUT, "--lcm-url", kUrl, "--cell", kCell}, "ros2_input.log");
    std::optional<pid_t> br;
    if (bridge) br = Start({RCAL_DDS_BRIDGE, "--lcm-url", kUrl, "--cell", kCell}, "dds_bridge.log");
    EXPECT_TRUE(integration::Until([&] { return run.status && run.input_health; },
                                   [&] { t.HandleTimeout(100); }));
    std::vector<std::string> cmd = {RCAL_ROS2_SIM_DRIVERS, "--sim",   kSim, "--seed",
                                    std::to_string(kSeed), "--speed", speed};
    cmd.insert(cmd.end(), driver_args.begin(), driver_args.end());
    const pid_t drivers = Start(cmd, "ros2_sim_drivers.log");
    EXPECT_TRUE(integration::Until([&] { return !integration::Running(drivers); },
                                   [&] {
                                     t.HandleTimeout(100);
                                     if (while_running) while_running();
                                   },
                                   600));
    Reaped(drivers);
    // The last windows: the identifier has judged all still_window published.
    int64_t settled = 0;
    integration::Until([&] { return ++settled > 40; },
                       [&] {
                         t.HandleTimeout(100);
                         if (while_running) while_running();
                       });
    EXPECT_EQ(Stop(in), 0);
    EXPECT_EQ(Stop(sw), 0);
    EXPECT_EQ(Stop(ekf), 0);
    if (br) {
      EXPECT_EQ(Stop(*br), 0);
    }
    while (t.HandleTimeout(100) > 0) {  // the final HEALTHs (one message per call)
    }
    return run;
  }
};

// The offline figure of the demo cell (SensorPipeline's): its test error after `poses` poses.
double OfflineTestErrorMm(int poses, std::vector<Eigen::VectorXd>* test_q, cell::Cell* out) {
  const auto robot = io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  const cell::Cell cell = cell::MakeCell(robot.spec, kSeed);
  cell::RunSettings rs;
  rs.seed = kSeed;
  rs.num_cal = kCal;
  rs.num_test = kTest;
  const auto w = cell::SimulateWindows(cell, rs);
  for (const auto& m : w.test) test_q->push_back(m.q);
  const auto offline = cell::RunOnline(cell, w.cal, *test_q);
  *out = cell;
  return offline.test_error_after_pose_mm.at(std::max(poses, 1) - 1);
}

TEST_F(Ros2Cell, TheDemoCellCalibratesThroughItsRos2Drivers) {
  RCAL_IN_NAMESPACE("Ros2Cell.TheDemoCellCalibratesThroughItsRos2Drivers");
  const io::BuiltCell built = io::LoadCell(kCell);
  // The bridge's ROS 2 outputs, read while the cell runs.
  dds::EntityGuard participant(dds_create_participant(0, nullptr, nullptr));
  ASSERT_GT(participant.get(), 0);
  Reader<dds::TFMessage> tf(participant.get(), "rt/tf_static", Reliable(true));
  Reader<dds::DiagnosticArray> diagnostics(participant.get(), "rt/diagnostics", Reliable(false));
  Reader<dds::RosString> description(participant.get(), "rt/robot_description", Reliable(true));
  std::string urdf;
  std::optional<std::vector<dds::NamedTransform>> transforms;
  std::set<std::string> diagnosed;
  auto read = [&] {
    tf.Take([&](const dds::TFMessage& m) {
      std::string error;
      transforms = dds::FromRos(m, &error);
      EXPECT_TRUE(transforms) << error;
    });
    description.Take([&](const dds::RosString& m) { urdf = m.data ? m.data : ""; });
    diagnostics.Take([&](const dds::DiagnosticArray& m) {
      std::string error;
      const auto r = dds::FromRos(m, &error);
      ASSERT_TRUE(r) << error;
      for (const auto& s : *r) diagnosed.insert(s.name);
    });
  };

  // The arm warms with a time constant of 100 s (its controller's temperature driver).
  constexpr double kWarmup = 100.0;
  const CellRun run =
      RunCell({"--poses", std::to_string(kCal), "--test-poses", std::to_string(kTest),
               "--sim-warmup", std::to_string(kWarmup), "--sim-payloads", "0,5,10"},
              true, read);
  read();
  ASSERT_TRUE(run.params && run.status && run.clocks && run.input_health);
  const int accepted = run.status->poses_accepted;
  std::printf(
      "ros2 cell: %d poses accepted, %d rejected; ros2_input rejected %lld, still_window "
      "rejected %lld (%s)\n",
      accepted, run.status->poses_rejected, static_cast<long long>(run.input_health->rejected),
      static_cast<long long>(run.window_health ? run.window_health->rejected : -1),
      run.window_health ? run.window_health->last_error.c_str() : "");

  // Clocks: both offsets recovered within 2 ms (locked needs two independent 20 s windows to
  // agree: the tracker's takes a median 156 s of motion, so it may still be `estimating`).
  ASSERT_EQ(run.clocks->num_sources, 2);
  const double truth[2] = {0.037, -0.120};
  for (int i = 0; i < 2; ++i) {
    std::printf("clock %s: %.3f ms ± %.3f ms (truth %.1f ms), state %d\n",
                run.clocks->source[i].c_str(), 1e3 * run.clocks->offset[i],
                1e3 * run.clocks->sigma[i], 1e3 * truth[i], run.clocks->state[i]);
    EXPECT_NEAR(run.clocks->offset[i], truth[i], 0.002) << run.clocks->source[i];
    EXPECT_GE(run.clocks->state[i], 1) << run.clocks->source[i];
    EXPECT_LT(run.clocks->sigma[i], 0.002) << run.clocks->source[i];
  }

  // The calibration: ≤ 1.5× the offline figure after as many poses.
  std::vector<Eigen::VectorXd> test_q;
  cell::Cell cell;
  const double offline_mm = OfflineTestErrorMm(accepted, &test_q, &cell);
  std::string error;
  const auto x = transport::ParamsFromMessage(*run.params, cell.model, &error);
  ASSERT_TRUE(x) << error;
  const double online_mm =
      identification::ErrorsAgainstTruth(cell.model, *x, cell.x_true, test_q).mean_position_m * 1e3;
  std::printf("test error: through ROS 2 %.4f mm, offline %.4f mm (%d poses)\n", online_mm,
              offline_mm, accepted);
  std::vector<double> lat = run.pose_latency_s;
  if (!lat.empty()) {
    std::sort(lat.begin(), lat.end());
    std::printf(
        "window end (JOINTS out of ros2_input) -> POSE_MEASUREMENT: median %.1f ms, max "
        "%.1f ms over %zu windows (at 5x real time)\n",
        1e3 * lat[lat.size() / 2], 1e3 * lat.back(), lat.size());
  }
  EXPECT_GE(accepted, kCal - 3);  // the windows before the clocks locked are refused
  EXPECT_LT(online_mm, 1.5 * offline_mm);

  // TF: exactly the identified set-up frames of the last parameters.
  ASSERT_TRUE(transforms.has_value());
  const auto x_built = transport::ParamsFromMessage(*run.params, built.model, &error);
  ASSERT_TRUE(x_built) << error;
  const auto expected =
      dds::SetupTransforms(io::CalibratedSpec(built.robot_spec, built.model, *x_built), "rcal_");
  ASSERT_EQ(transforms->size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_EQ((*transforms)[i].parent, expected[i].parent);
    EXPECT_EQ((*transforms)[i].child, expected[i].child);
    EXPECT_LT(((*transforms)[i].p_PC_P - expected[i].p_PC_P).norm(), 1e-12);
    EXPECT_LT((*transforms)[i].q_PC.angularDistance(expected[i].q_PC), 1e-9);
  }
  for (const char* name :
       {"rcal/ros2_input", "rcal/still_window", "rcal/ekf_identifier", "rcal/clock_offsets"})
    EXPECT_TRUE(diagnosed.count(name)) << name;

  // The arm's temperature (sensor_msgs/Temperature, 1 Hz on the controller's clock) reaches every
  // pose: the warming curve at the window's end (the drivers' sim time 0 is utime 1e9 µs) within
  // 5σ of the report's noise and the rise over a report's period, the reorder delay and half a
  // window (the report standing at the window's middle).
  ASSERT_GE(run.poses.size(), static_cast<size_t>(kCal - 3));
  sim::SessionSettings session;
  session.warmup_time_constant_s = kWarmup;
  for (const pose_measurement_t& m : run.poses) {
    const double t = static_cast<double>(m.utime - 1'000'000'000) * 1e-6;  // [s] sim time
    const double slope = session.temperature_rise_c / kWarmup * std::exp(-t / kWarmup);  // [K/s]
    EXPECT_NEAR(m.temperature_c, sim::WarmedTo(session, t), 5 * 0.3 + slope * 3.5)
        << "pose " << m.pose_index << " at " << t << " s";
  }
  const double rise = run.poses.back().temperature_c - run.poses.front().temperature_c;
  std::printf("poses' temperature: %.2f to %.2f °C over %zu poses\n",
              run.poses.front().temperature_c, run.poses.back().temperature_c, run.poses.size());
  EXPECT_GT(rise, 3.0);
  // The payload (geometry_msgs/InertiaStamped at 1 Hz with the temperature; the simulated arm
  // carries 0, 5 or 10 kg per stop, --sim-payloads): on ARM_CONDITIONS beside the temperature, one
  // stream in time order, every report with both once both have come; every pose carries the
  // payload its stop held (the simulator's schedule: the last stop the arm stood at before the
  // pose's time on the arm's clock).
  ASSERT_GT(run.conditions.size(), 20u);
  int both = 0;
  std::set<double> reported;
  for (size_t i = 0; i < run.conditions.size(); ++i) {
    const arm_conditions_t& c = run.conditions[i];
    if (i > 0) {
      EXPECT_GT(c.utime, run.conditions[i - 1].utime);
    }
    if (std::isnan(c.payload_kg) || std::isnan(c.temperature_c)) continue;
    reported.insert(c.payload_kg);
    ++both;
  }
  EXPECT_GT(both, static_cast<int>(run.conditions.size()) - 3);
  EXPECT_EQ(reported, (std::set<double>{0.0, 5.0, 10.0}));
  const cell::CellSimSpec sim_spec = cell::LoadCellSimSpec(kSim);
  const cell::SimProgramme programme =
      cell::MakeSimProgramme(io::LoadCell(sim_spec.cell), sim_spec, kSeed, kCal, kTest);
  cell::SimArmConditions payloads(kWarmup, 0, kSeed);
  payloads.SetPayloads(programme.truth.trajectory(), {0.0, 5.0, 10.0});
  const sim::JointTrajectory& trajectory = programme.truth.trajectory();
  for (const pose_measurement_t& m : run.poses) {
    const double t = static_cast<double>(m.utime - 1'000'000'000) * 1e-6;  // [s] sim time
    const int stop = integration::StopAt(trajectory, t);
    ASSERT_GE(stop, 1) << "pose " << m.pose_index << " at " << t << " s";
    EXPECT_EQ(m.payload_kg, payloads.PayloadAt(stop)) << "pose " << m.pose_index << " at " << t;
  }
}

// The ROS 2 twin of
// SensorPipeline.TheControllersTemperatureReachesThePosesAndThermalGrowthIsNamedLive (issue 15):
// ros2_sim_drivers --sim-effect thermal=κ makes the simulated arm grow by κ = 5e-5 1/K with its
// true temperature while it warms (+12 K, time constant 100 s), and its controller reports the
// temperature as sensor_msgs/Temperature at 1 Hz. Through ros2_input (clocks estimated) and
// still_window, every pose carries it; the identifier's discrepancy watch (every 50 poses, switch
// on) names thermal growth by temperature and identifies κ within 3σ of the truth.
TEST_F(Ros2Cell, AnArmGrowingAsItWarmsIsNamedThroughItsRos2Drivers) {
  RCAL_IN_NAMESPACE("Ros2Cell.AnArmGrowingAsItWarmsIsNamedThroughItsRos2Drivers");
  constexpr double kKappa = 5e-5;  // [1/K]
  const CellRun run =
      RunCell({"--poses", "60", "--test-poses", "5", "--sim-warmup", "100", "--sim-effect",
               "thermal=" + std::to_string(kKappa)},
              false, {}, "10", {"--discrepancy-every", "50", "--discrepancy-switch"});
  ASSERT_TRUE(run.params && run.status);
  ASSERT_GE(run.poses.size(), 50u);
  for (const pose_measurement_t& m : run.poses)
    ASSERT_TRUE(std::isfinite(m.temperature_c)) << "pose " << m.pose_index;
  ASSERT_FALSE(run.discrepancies.empty());
  const model_discrepancy_t& first = run.discrepancies.front();
  ASSERT_GE(first.num_suspects, 1);
  EXPECT_EQ(first.description[0], "thermal (temperature)");
  EXPECT_EQ(first.switched_in, 1);
  ASSERT_EQ(run.params->num_effect_params, 1);
  EXPECT_EQ(run.params->effect_names[0], "thermal.temperature.kappa");
  EXPECT_NEAR(run.params->effect_values[0], kKappa, 3 * run.params->effect_sigmas[0]);
  EXPECT_LT(run.params->effect_sigmas[0], 0.2 * kKappa);
  std::printf(
      "through ROS 2: thermal growth named by temperature at %d poses (z %.1f), κ %.4g ± %.2g 1/K "
      "(truth %.4g); %d poses accepted; temperature %.1f to %.1f °C\n",
      first.poses_used, first.z[0], run.params->effect_values[0], run.params->effect_sigmas[0],
      kKappa, run.status->poses_accepted, run.poses.front().temperature_c,
      run.poses.back().temperature_c);
}

// The ROS 2 twin of SensorPipeline.AWindowMeasuredUnderTwoPayloadsIsRefusedAndCounted: a grasp
// made at the measurement stop (ros2_sim_drivers --sim-payload-at stop), its
// geometry_msgs/InertiaStamped published as it is made. Through ros2_input (clocks estimated: the
// report moved to the arm's clock by the median of its arrival lags), still_window refuses exactly
// the windows of the stops where the payload changed, and every pose it publishes carries the
// payload its stop held (truth: the simulator's schedule). Under load: beside a sensor-level
// pipeline and a busy core (README).
TEST_F(Ros2Cell, AWindowMeasuredUnderTwoPayloadsIsRefusedThroughItsRos2Drivers) {
  RCAL_IN_NAMESPACE("Ros2Cell.AWindowMeasuredUnderTwoPayloadsIsRefusedThroughItsRos2Drivers");
  constexpr int kStops = 20;
  const cell::CellSimSpec sim_spec = cell::LoadCellSimSpec(kSim);
  const cell::SimProgramme programme =
      cell::MakeSimProgramme(io::LoadCell(sim_spec.cell), sim_spec, kSeed, kStops, 1);
  cell::SimArmConditions payloads(sim::SessionSettings{}.warmup_time_constant_s, 0, kSeed);
  payloads.SetPayloads(programme.truth.trajectory(), {0.0, 10.0},
                       cell::SimArmConditions::PayloadChangeAt::kAtStop);
  const std::set<int> grasped = integration::GraspedStops(payloads, kStops);
  ASSERT_GE(grasped.size(), 4u);
  ASSERT_LE(grasped.size(), static_cast<size_t>(kStops - 4));
  const CellRun run = RunCell({"--poses", std::to_string(kStops), "--test-poses", "1",
                               "--sim-payloads", "0,10", "--sim-payload-at", "stop"},
                              false, {}, "10");
  std::set<int> stops;
  const sim::JointTrajectory& trajectory = programme.truth.trajectory();
  for (const pose_measurement_t& m : run.poses) {
    const double t = static_cast<double>(m.utime - 1'000'000'000) * 1e-6;  // [s] sim time
    const int stop = integration::StopAt(trajectory, t);
    ASSERT_GE(stop, 1) << "pose " << m.pose_index << " at " << t << " s";
    EXPECT_FALSE(grasped.count(stop)) << "pose " << m.pose_index << ": stop " << stop;
    EXPECT_EQ(m.payload_kg, payloads.PayloadAt(stop)) << "pose " << m.pose_index;
    stops.insert(stop);
  }
  EXPECT_EQ(stops.size(), run.poses.size());  // one pose per stop
  // Every other stop gave its pose, but for the first (the marker's clock offset is still being
  // estimated: still_window refuses a window whose clock σ is not yet small against it).
  int unlocked = 0;
  for (int k = 1; k <= kStops; ++k)
    if (!grasped.count(k) && !stops.count(k)) {
      EXPECT_EQ(k, 1) << "stop " << k << " gave no pose";
      ++unlocked;
    }
  ASSERT_TRUE(run.window_health.has_value());
  EXPECT_EQ(run.window_health->rejected, static_cast<int64_t>(grasped.size()) + unlocked);
  EXPECT_NE(run.window_health->last_error.find("arm_conditions.payload_kg changed"),
            std::string::npos)
      << run.window_health->last_error;
  std::printf(
      "through ROS 2: %zu of %d windows measured under two payloads refused (%d more: "
      "clocks not yet locked); %zu poses published\n",
      grasped.size(), kStops, unlocked, run.poses.size());
}

// ros2_sim_drivers' payload options where they cannot apply: refused naming them, before any DDS
// entity exists.
TEST_F(Ros2Cell, PayloadOptionsThatCannotApplyAreRefusedNamingThem) {
  RCAL_IN_NAMESPACE("Ros2Cell.PayloadOptionsThatCannotApplyAreRefusedNamingThem");
  struct Case {
    std::vector<std::string> args;
    std::string named;
    int exit_code;  // 2: the drivers' own refusal; 105: CLI11's check of the value
  };
  const std::vector<Case> cases = {
      {{"--sim-payload-at", "stop"}, "--sim-payload-at needs --sim-payloads", 2},
      {{"--sim-payloads", "5", "--sim-payload-at", "later"}, "--sim-payload-at", 105}};
  for (size_t k = 0; k < cases.size(); ++k) {
    std::vector<std::string> argv = {RCAL_ROS2_SIM_DRIVERS, "--sim", kSim};
    argv.insert(argv.end(), cases[k].args.begin(), cases[k].args.end());
    const std::string log = "ros2_sim_drivers_" + std::to_string(k) + ".log";
    const pid_t p = Start(argv, log);
    EXPECT_EQ(integration::Wait(p), cases[k].exit_code) << cases[k].named;
    Reaped(p);
    const std::string out = io::ReadFile(dir_ / log);
    EXPECT_NE(out.find(cases[k].named), std::string::npos) << out;
  }
}

TEST_F(Ros2Cell, ARestartedImuDriverIsResynchronisedAndItsOffsetLockedAgain) {
  RCAL_IN_NAMESPACE("Ros2Cell.ARestartedImuDriverIsResynchronisedAndItsOffsetLockedAgain");
  // The IMU driver restarts 60 s into the programme: its stamps start over from the beginning.
  const CellRun run =
      RunCell({"--poses", "12", "--test-poses", "1", "--imu-restart-at", "60"}, false);
  ASSERT_TRUE(run.clocks && run.status && run.input_health);
  EXPECT_GE(run.input_health->resyncs, 1);
  ASSERT_EQ(run.clocks->num_sources, 2);
  EXPECT_EQ(run.clocks->resets[0], 1);  // the IMU's clock
  EXPECT_EQ(run.clocks->resets[1], 0);
  EXPECT_GE(run.clocks->state[0], 1);
  // After the restart the IMU clock reads sim time − 60 s + 37 ms: offset −59.963 s.
  EXPECT_NEAR(run.clocks->offset[0], -60.0 + 0.037, 0.002);
  EXPECT_GE(run.status->poses_accepted, 8);
}

TEST_F(Ros2Cell, MalformedAndOversizedSamplesAreCountedAndNeverCrash) {
  RCAL_IN_NAMESPACE("Ros2Cell.MalformedAndOversizedSamplesAreCountedAndNeverCrash");
  CellRun run;
  transport::LcmTransport t(kUrl);
  Listen(t, run);
  const pid_t in = Start({RCAL_ROS2_INPUT, "--lcm-url", kUrl, "--cell", kCell}, "ros2_input.log");
  ASSERT_TRUE(integration::Until([&] { return run.input_health.has_value(); },
                                 [&] { t.HandleTimeout(100); }));
  dds::EntityGuard participant(dds_create_participant(0, nullptr, nullptr));
  auto writer = [&](const dds_topic_descriptor_t* desc, const char* name) {
    dds_qos_t* q = Reliable(false);
    const dds_entity_t topic = dds_create_topic(participant.get(), desc, name, q, nullptr);
    const dds_entity_t w = dds_create_writer(participant.get(), topic, q, nullptr);
    dds_delete_qos(q);
    EXPECT_GT(w, 0) << name;
    return w;
  };
  const dds_entity_t joints_w = writer(dds::Descriptor<dds::JointState>(), "rt/joint_states");
  const dds_entity_t imu_w = writer(dds::Descriptor<dds::Imu>(), "rt/imu/data");
  // Another type on the tracker's topic name: DDS does not match it with ros2_input's reader.
  const dds_entity_t wrong_w = writer(dds::Descriptor<dds::RosString>(), "rt/tracker/point");
  usleep(1'000'000);  // discovery

  const io::BuiltCell cell = io::LoadCell(kCell);
  joint_state_t good;
  good.num_joints = 6;
  good.names = cell.ros2_joint_names;
  good.q = {0.1, 0.2, 0.3, 0.4, 0.5, 0.6};
  good.dq.assign(6, 0.0);
  std::string error;
  int64_t utime = 5'000'000;
  auto write_joints = [&](const std::function<void(dds::JointState&)>& spoil) {
    good.utime = (utime += 8'000);
    auto s = dds::ToRos(good, {}, "", &error);
    ASSERT_TRUE(s);
    spoil(s->get());
    EXPECT_GE(dds_write(joints_w, &s->get()), 0);
  };
  int bad = 0;
  // NaN, lengths that disagree, a stamp's nanosec beyond 1e9, a missing joint.
  write_joints([](dds::JointState& m) { m.position._buffer[0] = std::nan(""); });
  write_joints([](dds::JointState& m) { m.position._length = 2; });
  write_joints([](dds::JointState& m) { m.header.stamp.nanosec = 2'000'000'000u; });
  write_joints([](dds::JointState& m) {
    dds_free(m.name._buffer[3]);
    m.name._buffer[3] = dds_string_dup("j9");
  });
  bad += 4;
  // Oversized: 5 000 names, beyond any arm (a valid CDR sample of ~150 kB; a best-effort reader
  // may lose such a fragmented sample: then DDS counts it, in HEALTH's dropped).
  {
    auto s = dds::ToRos(good, {}, "", &error);
    ASSERT_TRUE(s);
    auto& m = s->get();
    const uint32_t n = 5'000;
    for (uint32_t i = 0; i < m.name._length; ++i) dds_free(m.name._buffer[i]);
    dds_free(m.name._buffer);
    m.name._buffer = static_cast<char**>(dds_alloc(n * sizeof(char*)));
    m.name._length = m.name._maximum = n;
    for (uint32_t i = 0; i < n; ++i) m.name._buffer[i] = dds_string_dup("joint_with_a_long_name");
    m.header.stamp.sec = static_cast<int32_t>((utime += 8'000) / 1'000'000);
    EXPECT_GE(dds_write(joints_w, &m), 0);
    ++bad;
  }
  // An IMU in g, one in °/s, one in another frame.
  for (int k = 0; k < 3; ++k) {
    transport::ImuSample s;
    s.utime = (utime += 8'000);
    s.gyro_B = {0.01, 0.0, 0.0};
    s.f_B = {0.0, 0.0, 9.81};
    if (k == 0) s.f_B = {0.0, 0.0, 1.0};
    if (k == 1) s.gyro_B = {90.0, 0.0, 0.0};
    auto m = dds::ToRos(s, k == 2 ? "camera_link" : "imu_link", &error);
    ASSERT_TRUE(m);
    EXPECT_GE(dds_write(imu_w, &m->get()), 0);
    ++bad;
  }
  auto junk = dds::ToRos(std::string(100, 'x'));
  dds_write(wrong_w, &junk.get());
  // Then good joints (0.8 s of them: longer than the reorder delay): they come through.
  for (int k = 0; k < 100; ++k) write_joints([](dds::JointState&) {});
  auto counted = [&] { return run.input_health->rejected + run.input_health->dropped; };
  ASSERT_TRUE(
      integration::Until([&] { return run.input_health && counted() >= bad && run.joints >= 10; },
                         [&] { t.HandleTimeout(100); }, 60))
      << "rejected " << (run.input_health ? run.input_health->rejected : -1) << ", dropped "
      << (run.input_health ? run.input_health->dropped : -1) << ", joints " << run.joints;
  // Every bad sample refused (or, the oversized one, lost by DDS and counted as such).
  EXPECT_GE(run.input_health->rejected, bad - 1);
  EXPECT_LE(run.input_health->rejected, bad);
  EXPECT_EQ(counted(), bad);
  EXPECT_TRUE(integration::Running(in));
  EXPECT_EQ(Stop(in), 0);
}

}  // namespace
}  // namespace rcal
