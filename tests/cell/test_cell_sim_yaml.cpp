// The simulated counterpart of a cell (cell/cell_sim_yaml.hpp): the demo's sim file is exactly
// today's MakeCell(GRB3016, seed 1), run settings and simulated sensors; the pipeline the demo's
// cell builds is the one still_window builds today; every shipped sim file puts the set-up frames
// where it says (checked on a second model whose nominal frames are the truth); bad files and
// truths that do not fit their cell are refused naming the key.
#include "rcal/cell/cell_sim_yaml.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <set>
#include <string>

#include "../io/settings_eq.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "rcal/sim/effects.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/sim/sensor_sim.hpp"

namespace rcal::cell {
namespace {

std::filesystem::path CellsDir() {
  return std::filesystem::path(RCAL_SOURCE_DIR) / "config" / "cells";
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "<no error>";
}

void Replace(std::string& text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  ASSERT_NE(at, std::string::npos) << from;
  text.replace(at, from.size(), to);
}

struct Loaded {
  io::BuiltCell cell;
  CellSimSpec sim;
};

Loaded Load(const std::string& name) {
  CellSimSpec sim = LoadCellSimSpec(CellsDir() / (name + ".sim.yaml"));
  EXPECT_EQ(sim.cell, (CellsDir() / (name + ".yaml")).lexically_normal());
  return {io::LoadCell(sim.cell), sim};
}

TEST(CellSimYaml, DemoSimFileIsTodaysSimulatedCell) {
  const Loaded d = Load("grb3016");
  const Cell a = MakeSimCell(d.cell, d.sim);
  const Cell b = MakeCell(d.cell.robot.spec,
                          1);  // the seed-built cell of sim_cell (rcal experiment paper --sensors)
  ASSERT_EQ(a.model.num_params(), b.model.num_params());
  for (int i = 0; i < a.model.num_params(); ++i) {
    EXPECT_EQ(a.model.parameters()[i].name, b.model.parameters()[i].name);
    EXPECT_EQ(a.model.parameters()[i].nominal, b.model.parameters()[i].nominal);
    // The truth written as frames: truth − nominal, exact to a rounding.
    EXPECT_NEAR(a.x_true(i), b.x_true(i), 1e-15) << a.model.parameters()[i].name;
  }
  EXPECT_EQ(a.base, b.base);
  EXPECT_EQ(a.setup, b.setup);
  EXPECT_EQ(a.ident.rank, b.ident.rank);
  EXPECT_LT((a.x_eq - b.x_eq).cwiseAbs().maxCoeff(), 1e-12);

  // The run: RunSettings{} (the demo's programme, seed 1).
  const RunSettings rs = SimRunSettings(d.cell, d.sim), today;
  EXPECT_EQ(rs.seed, today.seed);
  EXPECT_EQ(rs.num_cal, today.num_cal);
  EXPECT_EQ(rs.num_test, today.num_test);
  EXPECT_EQ(rs.num_extra, today.num_extra);
  EXPECT_EQ(rs.noise_scale, today.noise_scale);
  EXPECT_EQ(rs.still_time, today.still_time);
  EXPECT_EQ(rs.gyro_bias, today.gyro_bias);
  EXPECT_EQ(rs.mag_disturbance, today.mag_disturbance);
  EXPECT_EQ(rs.dropout, today.dropout);
  EXPECT_EQ(rs.orientation, today.orientation);

  // The sensors: what SimulateWindows builds for RunSettings{} (SensorSimSettings{}, no dropout).
  const sim::SensorSimSettings s = SimSensorSettings(d.cell, d.sim), t;
  EXPECT_EQ(s.rate_hz, t.rate_hz);
  EXPECT_EQ(s.imu.rate_hz, t.imu.rate_hz);
  EXPECT_EQ(s.imu.g_W, t.imu.g_W);
  EXPECT_EQ(s.imu.m_W, t.imu.m_W);
  EXPECT_EQ(s.imu.white_noise, t.imu.white_noise);
  EXPECT_EQ(s.imu.gyro_noise_density, t.imu.gyro_noise_density);
  EXPECT_EQ(s.imu.accel_noise_density, t.imu.accel_noise_density);
  EXPECT_DOUBLE_EQ(s.imu.mag_noise_density, t.imu.mag_noise_density);  // T → µT
  EXPECT_EQ(s.imu.constant_bias, t.imu.constant_bias);
  EXPECT_EQ(s.imu.bias_random_walk, t.imu.bias_random_walk);
  EXPECT_EQ(s.imu.mounting, t.imu.mounting);
  EXPECT_EQ(s.position.rate_hz, t.position.rate_hz);
  EXPECT_EQ(s.position.noise, t.position.noise);
  EXPECT_EQ(s.position.sigma, t.position.sigma);
  EXPECT_EQ(s.position.dropouts, false);
  EXPECT_EQ(s.position.dropout_probability, 0.0);
  EXPECT_EQ(s.mag_disturbance, t.mag_disturbance);

  // The pose pipeline of the demo's cell is still_window's today (services/still_window/main.cpp:
  // PosePipelineSettings{} with the simulator's position σ and gyro noise density).
  estimation::PosePipelineSettings ps;
  ps.position.position_sigma = t.position.sigma;
  ps.orientation.gyro_noise_density = t.imu.gyro_noise_density;
  ps.use_orientation = true;
  rcal::testing::ExpectSameSettings(d.cell.pipeline, ps);
}

TEST(CellSimYaml, SwitchesReachTheSensors) {
  Loaded d = Load("grb3016");
  d.sim.noise_scale = 2.0;
  d.sim.gyro_bias = true;
  d.sim.mag_disturbance = true;
  d.sim.dropout = 0.1;
  const sim::SensorSimSettings s = SimSensorSettings(d.cell, d.sim), t;
  EXPECT_EQ(s.imu.gyro_noise_density, 2.0 * t.imu.gyro_noise_density);
  EXPECT_EQ(s.imu.accel_noise_density, 2.0 * t.imu.accel_noise_density);
  EXPECT_DOUBLE_EQ(s.imu.mag_noise_density, 2.0 * t.imu.mag_noise_density);
  EXPECT_EQ(s.position.sigma, 2.0 * t.position.sigma);
  EXPECT_TRUE(s.imu.constant_bias && s.imu.bias_random_walk);
  EXPECT_EQ(s.imu.gyro_bias, Eigen::Vector3d(0.004, -0.003, 0.005));  // SimulateWindows' bias
  EXPECT_TRUE(s.mag_disturbance);
  EXPECT_TRUE(s.position.dropouts);
  EXPECT_EQ(s.position.dropout_probability, 0.1);
  const RunSettings rs = SimRunSettings(d.cell, d.sim);
  EXPECT_EQ(rs.noise_scale, 2.0);
  EXPECT_TRUE(rs.gyro_bias && rs.mag_disturbance);
  EXPECT_EQ(rs.dropout, 0.1);
}

// The IMU's lever arm to the marker reaches the live sources' truth (MakeSimProgramme); absent,
// the IMU sits at the marker.
TEST(CellSimYaml, TheImuToMarkerLeverArmReachesTheProgrammesTruth) {
  Loaded d = Load("grb3016");
  EXPECT_TRUE(MakeSimProgramme(d.cell, d.sim, 1, 2, 0).truth.imu_to_marker_I().isZero());
  std::string text = io::ReadFile(RCAL_SOURCE_DIR "/config/cells/grb3016.sim.yaml");
  const std::string marker = "    - {id: 0, xyz: [0.034, -0.003, 0.122]}";
  const auto at = text.find(marker);
  ASSERT_NE(at, std::string::npos);
  text.insert(at + marker.size(), "\n  imu_to_marker: [0.1, -0.05, 0.08]");
  const CellSimSpec sim = ParseCellSimYaml(text, "lever.sim.yaml");
  EXPECT_EQ(sim.imu_to_marker_I, Eigen::Vector3d(0.1, -0.05, 0.08));
  EXPECT_EQ(MakeSimProgramme(d.cell, sim, 1, 2, 0).truth.imu_to_marker_I(),
            Eigen::Vector3d(0.1, -0.05, 0.08));
}

// --sim-effect on a tracker per marker (ros2_sim_drivers): the UR10's two markers, each its own
// truth on the programme's motion, grow with the arm as it warms. At any time, each marker's truth
// is where the extended model of the arm (sim::MakeEffectTruth on the arm, then its marker view)
// puts that marker at the true conditions, and the growth shows (the ungrown truth is > 0.1 mm
// off by the end); the IMU's truth (the programme's) grows too.
TEST(SimArmConditions, EveryMarkersTruthGrowsWithTheArm) {
  Loaded d = Load("ur10");
  SimProgramme programme = MakeSimProgramme(d.cell, d.sim, 1, 4, 0);
  const kinematics::KinematicModel& model = programme.cell.model;
  ASSERT_EQ(model.markers().size(), 2u);
  std::vector<sim::ToolMotionTruth> markers, ungrown;
  for (const kinematics::Marker& m : model.markers())
    markers.emplace_back(model.ForMarker(model.MarkerSlot(m.id)), programme.cell.x_true,
                         programme.truth.trajectory());
  ungrown = markers;
  const sim::ToolMotionTruth programme_ungrown = programme.truth;
  const SimArmConditions conditions(100.0, 0, 1);
  std::vector<sim::ToolMotionTruth*> truths = {&programme.truth};
  for (sim::ToolMotionTruth& m : markers) truths.push_back(&m);
  const std::vector<std::string> lines = conditions.ApplyEffects({"thermal=5e-5"}, truths);
  ASSERT_EQ(lines.size(), 1u);
  const sim::EffectTruth arm =
      sim::MakeEffectTruth(model, {sim::ParseEffectSpec("thermal=5e-5", model)});
  const double end = programme.truth.trajectory().duration();
  double growth = 0;
  for (double t = 0.0; t <= end; t += end / 37) {
    const kinematics::EffectContext c = conditions.At(t);
    for (size_t i = 0; i < markers.size(); ++i) {
      const sim::ToolState s = markers[i].At(t);
      const int slot = model.MarkerSlot(model.markers()[i].id);
      const Eigen::Vector3d expected =
          arm.model.ForMarker(slot).Forward(s.q, c, programme.cell.x_true, arm.e).p_WM_W;
      EXPECT_LT((s.p_WM_W - expected).norm(), 1e-12) << "marker " << i << " at " << t << " s";
      growth = std::max(growth, (s.p_WM_W - ungrown[i].At(t).p_WM_W).norm());
    }
    EXPECT_LT((programme.truth.At(t).p_WM_W -
               arm.model.Forward(programme.truth.At(t).q, c, programme.cell.x_true, arm.e).p_WM_W)
                  .norm(),
              1e-12);
  }
  EXPECT_GT(growth, 1e-4);
  EXPECT_GT((programme.truth.At(end).p_WM_W - programme_ungrown.At(end).p_WM_W).norm(), 1e-4);
  // A cause that is no effect of the arm is refused.
  EXPECT_THROW(conditions.ApplyEffects({"time_offset=0.01"}, truths), std::invalid_argument);
}

// Backlash at sensor level (sim::ToolMotionTruth::set_backlash): through each stop's still
// interval the truth is the extended model with the approach direction still_window publishes (the
// sign of each joint's net move from the stop before) to 1e-12 m; the offset is b·s there, and
// crossing the dead band as a move reverses it blends over the motor's first 2|b| of travel, so
// the tool's acceleration, which the IMU feels, jolts by a bounded amount (under 20 m/s² at
// 2e-4 rad) instead of a differencing spike.
TEST(SimArmConditions, BacklashStandsEachJointOffByItsApproachAndCrossesTheDeadBandSmoothly) {
  Loaded d = Load("grb3016");
  SimProgramme programme = MakeSimProgramme(d.cell, d.sim, 1, 8, 1);
  const sim::ToolMotionTruth plain = programme.truth;
  const SimArmConditions conditions(100.0, 0, 1);
  constexpr double kB = 2e-4;  // [rad]
  const std::vector<std::string> lines =
      conditions.ApplyEffects({"backlash:j2=2e-4", "backlash:j3=-1e-4"}, programme);
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_NE(lines[0].find("backlash"), std::string::npos);
  const kinematics::KinematicModel& model = programme.cell.model;
  const sim::EffectTruth arm =
      sim::MakeEffectTruth(model, {sim::ParseEffectSpec("backlash:j2=2e-4", model),
                                   sim::ParseEffectSpec("backlash:j3=-1e-4", model)});
  const sim::JointTrajectory& trajectory = programme.truth.trajectory();
  int reversals = 0;
  double jolt = 0, moved = 0;
  for (int k = 1; k < trajectory.num_waypoints(); ++k) {
    kinematics::EffectContext c = conditions.At(0.0);
    c.dq_sign = Eigen::VectorXi::Zero(model.num_joints());
    for (int j = 0; j < model.num_joints(); ++j) {
      const double step = trajectory.waypoint(k)(j) - trajectory.waypoint(k - 1)(j);
      c.dq_sign(j) = (step > 0) - (step < 0);
    }
    const auto [a, b] = trajectory.StillInterval(k);
    for (double t = a; t <= b; t += (b - a) / 4) {
      const sim::ToolState s = programme.truth.At(t);
      EXPECT_LT((s.p_WM_W - arm.model.Forward(s.q, c, programme.cell.x_true, arm.e).p_WM_W).norm(),
                1e-12)
          << "stop " << k << " at " << t << " s";
      EXPECT_NEAR(programme.truth.BacklashOffset(s.q, t)(1), kB * c.dq_sign(1), 1e-15);
      moved = std::max(moved, (s.p_WM_W - plain.At(t).p_WM_W).norm());
    }
    if (k + 1 < trajectory.num_waypoints() &&
        (trajectory.waypoint(k + 1)(1) - trajectory.waypoint(k)(1)) * c.dq_sign(1) < 0)
      ++reversals;
    // Through the start of the move on (where the dead band is crossed), finely.
    for (double t = b; t < b + 0.4 && k + 1 < trajectory.num_waypoints(); t += 0.002)
      jolt = std::max(jolt, (programme.truth.At(t).a_WM_W - plain.At(t).a_WM_W).norm());
  }
  std::printf(
      "backlash: %d reversals of joint 2; the tool up to %.4f mm off the plain arm at the "
      "stops; the acceleration's jolt up to %.3f m/s^2\n",
      reversals, moved * 1e3, jolt);
  EXPECT_GE(reversals, 2);
  EXPECT_GT(moved, 1e-4);
  EXPECT_GT(jolt, 0.0);
  EXPECT_LT(jolt, 20.0);
  EXPECT_THROW(programme.truth.set_backlash(Eigen::VectorXd::Zero(2)), std::invalid_argument);
}

// Gear (joint_periodic) and scale (joint_scale) errors at sensor level: functions of the joint
// angle alone, so the truth along the whole motion is the extended model at the joints (1e-12 m),
// they move the tool by several hundredths of a millimetre (0.075 mm at 1e-4 rad of gear error and
// 2e-4 of scale), and what the IMU feels changes smoothly with them (the tool's acceleration within
// 0.05 m/s² of the plain arm's; measured 1e-4).
TEST(SimArmConditions, GearAndScaleErrorsMoveTheSensorLevelTruthAsTheExtendedModel) {
  Loaded d = Load("grb3016");
  SimProgramme programme = MakeSimProgramme(d.cell, d.sim, 1, 6, 1);
  const sim::ToolMotionTruth plain = programme.truth;
  const SimArmConditions conditions(100.0, 0, 1);
  const std::vector<std::string> texts = {"joint_periodic:j3=1e-4,5e-5", "joint_scale:j4=2e-4"};
  const std::vector<std::string> lines = conditions.ApplyEffects(texts, programme);
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_NE(lines[0].find("gear errs periodically"), std::string::npos);
  EXPECT_NE(lines[1].find("scale off its reading"), std::string::npos);
  const kinematics::KinematicModel& model = programme.cell.model;
  std::vector<sim::TruthEffect> effects;
  for (const std::string& t : texts) effects.push_back(sim::ParseEffectSpec(t, model));
  const sim::EffectTruth arm = sim::MakeEffectTruth(model, effects);
  const double end = programme.truth.trajectory().duration();
  double moved = 0, accel_change = 0;
  for (double t = 0.0; t <= end; t += end / 101) {
    const sim::ToolState s = programme.truth.At(t);
    EXPECT_LT(
        (s.p_WM_W - arm.model.Forward(s.q, conditions.At(t), programme.cell.x_true, arm.e).p_WM_W)
            .norm(),
        1e-12)
        << t << " s";
    moved = std::max(moved, (s.p_WM_W - plain.At(t).p_WM_W).norm());
    accel_change = std::max(accel_change, (s.a_WM_W - plain.At(t).a_WM_W).norm());
  }
  std::printf(
      "gear and scale errors: the tool up to %.4f mm off the plain arm, its acceleration "
      "up to %.4f m/s^2\n",
      moved * 1e3, accel_change);
  EXPECT_GT(moved, 5e-5);
  EXPECT_LT(accel_change, 0.05);
}

// A pick-and-place arm at sensor level (SetPayloads): each stop holds its drawn payload, constant
// and reported as it is from before its still interval until halfway through the next move; the
// change blends in over half a second from the move's midpoint (quintic smoothstep). With
// joint_compliance the truth is the extended model at the true payload (1e-12 m), the payload shows
// at the loaded stops (5 or 10 kg at c = 2e-6 rad/(N·m) on joint 2: about 0.1 mm) and not at the
// empty ones, and the tool's acceleration, which the IMU feels, differs from the unloaded arm's by
// the sag's smooth change only (a step would be hundreds of m/s² at the simulator's differencing
// step).
TEST(SimArmConditions, APayloadPerStopBlendsInHalfwayThroughTheMoveToIt) {
  Loaded d = Load("grb3016");
  SimProgramme programme = MakeSimProgramme(d.cell, d.sim, 1, 8, 1);
  const sim::ToolMotionTruth unloaded = programme.truth;
  const sim::JointTrajectory& trajectory = programme.truth.trajectory();
  SimArmConditions conditions(100.0, 0, 1);
  conditions.SetPayloads(trajectory, {0.0, 5.0, 10.0});
  const int n = trajectory.num_waypoints();
  ASSERT_EQ(n, 10);  // home, 8 calibration stops, the first test stop
  std::set<double> held;
  for (int k = 0; k < n; ++k) {
    held.insert(conditions.PayloadAt(k));
    // From the end of the blend into this stop (at the latest three quarters into the move) to
    // just before halfway into the next move.
    const auto [a, b] = trajectory.StillInterval(k);
    const double from_t = k == 0 ? 0.0 : a - 0.25 * (a - trajectory.StillInterval(k - 1).second);
    const double until_t = k + 1 < n ? 0.5 * (b + trajectory.StillInterval(k + 1).first) - 1e-6 : b;
    for (double t = from_t; t <= until_t; t += (until_t - from_t) / 9) {
      EXPECT_EQ(conditions.At(t).payload_kg, conditions.PayloadAt(k)) << "stop " << k << " " << t;
      EXPECT_EQ(conditions.ReportedPayload(t), conditions.PayloadAt(k)) << "stop " << k << " " << t;
    }
  }
  EXPECT_EQ(held, (std::set<double>{0.0, 5.0, 10.0}));  // seeded: every payload drawn
  // The blend: from the old payload to the new within the move's first half-second, monotone, its
  // second derivative within the quintic's 10/√3 Δm/T²; reported as the new one from the start.
  for (int k = 1; k < n; ++k) {
    const double from = conditions.PayloadAt(k - 1), to = conditions.PayloadAt(k);
    const double leave = trajectory.StillInterval(k - 1).second;
    const double arrive = trajectory.StillInterval(k).first;
    const double t0 = 0.5 * (leave + arrive);
    const double T = std::min(0.5, 0.25 * (arrive - leave));
    ASSERT_LT(t0 + T, arrive);
    EXPECT_EQ(conditions.At(t0).payload_kg, from);
    EXPECT_EQ(conditions.At(t0 + T).payload_kg, to);
    EXPECT_EQ(conditions.ReportedPayload(t0 + 1e-9), to);
    const double h = 1e-3;
    double last = from;
    for (double t = t0 + h; t < t0 + T; t += 0.01) {
      const double m = conditions.At(t).payload_kg;
      EXPECT_GE((m - last) * (to - from), 0.0) << "stop " << k << " at " << t;
      last = m;
      const double m2 =
          (conditions.At(t + h).payload_kg - 2 * m + conditions.At(t - h).payload_kg) / (h * h);
      EXPECT_LE(std::abs(m2), 5.78 * std::abs(to - from) / (T * T) + 1e-6) << "stop " << k;
    }
  }
  // Joint compliance under the payload.
  const std::vector<std::string> lines =
      conditions.ApplyEffects({"joint_compliance:j2=2e-6"}, programme);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_NE(lines[0].find("give way under gravity and its payload"), std::string::npos);
  const kinematics::KinematicModel& model = programme.cell.model;
  const sim::EffectTruth arm =
      sim::MakeEffectTruth(model, {sim::ParseEffectSpec("joint_compliance:j2=2e-6", model)});
  kinematics::EffectContext empty = conditions.At(0.0);
  double sag_loaded = 0, sag_empty = 0;
  for (int k = 1; k < n; ++k) {
    const auto [a, b] = trajectory.StillInterval(k);
    const double t = 0.5 * (a + b);
    const sim::ToolState s = programme.truth.At(t);
    const kinematics::EffectContext c = conditions.At(t);
    EXPECT_LT((s.p_WM_W - arm.model.Forward(s.q, c, programme.cell.x_true, arm.e).p_WM_W).norm(),
              1e-12)
        << "stop " << k;
    empty.time_s = c.time_s;
    empty.temperature_c = c.temperature_c;
    empty.payload_kg = 0.0;
    const double payload_sag =
        (s.p_WM_W - arm.model.Forward(s.q, empty, programme.cell.x_true, arm.e).p_WM_W).norm();
    double& sag = c.payload_kg > 0.0 ? sag_loaded : sag_empty;
    sag = std::max(sag, payload_sag);
  }
  std::printf("the payload's sag at the stops: up to %.4f mm loaded, %.4f mm empty\n",
              sag_loaded * 1e3, sag_empty * 1e3);
  EXPECT_GT(sag_loaded, 5e-5);  // the demo cell's still windows: about 0.05 mm
  EXPECT_EQ(sag_empty, 0.0);
  double accel_change = 0;
  for (double t = 0.0; t <= trajectory.duration(); t += 0.01)
    accel_change =
        std::max(accel_change, (programme.truth.At(t).a_WM_W - unloaded.At(t).a_WM_W).norm());
  std::printf("largest change of the tool's acceleration against the unloaded arm: %.4f m/s^2\n",
              accel_change);
  EXPECT_LT(accel_change, 0.05);
  // Refused: no payloads, a negative one, a NaN.
  EXPECT_THROW(conditions.SetPayloads(trajectory, {}), std::invalid_argument);
  EXPECT_THROW(conditions.SetPayloads(trajectory, {5.0, -1.0}), std::invalid_argument);
  EXPECT_THROW(conditions.SetPayloads(trajectory, {std::nan("")}), std::invalid_argument);
}

// A grasp at the measurement stop (PayloadChangeAt::kAtStop): the new payload blends in from the
// middle of the stop's still interval, within it, and is reported from there; in the move to the
// stop and in its first half the arm still holds the payload of the stop before.
TEST(SimArmConditions, AGraspAtTheStopChangesThePayloadInsideItsStillInterval) {
  Loaded d = Load("grb3016");
  const SimProgramme programme = MakeSimProgramme(d.cell, d.sim, 1, 8, 1);
  const sim::JointTrajectory& trajectory = programme.truth.trajectory();
  SimArmConditions at_stop(100.0, 0, 1), mid_move(100.0, 0, 1);
  at_stop.SetPayloads(trajectory, {0.0, 5.0, 10.0}, SimArmConditions::PayloadChangeAt::kAtStop);
  mid_move.SetPayloads(trajectory, {0.0, 5.0, 10.0});
  int changes = 0;
  std::vector<double> steps;  // where the report steps: the drivers publish a change there
  for (int k = 1; k < trajectory.num_waypoints(); ++k) {
    EXPECT_EQ(at_stop.PayloadAt(k), mid_move.PayloadAt(k));  // the same draws
    const double from = at_stop.PayloadAt(k - 1), to = at_stop.PayloadAt(k);
    const auto [a, b] = trajectory.StillInterval(k);
    const double t0 = 0.5 * (a + b), T = std::min(0.5, 0.25 * (b - a));
    EXPECT_EQ(at_stop.At(a).payload_kg, from) << "stop " << k;
    EXPECT_EQ(at_stop.ReportedPayload(t0 - 1e-9), from) << "stop " << k;
    EXPECT_EQ(at_stop.ReportedPayload(t0 + 1e-9), to) << "stop " << k;
    EXPECT_EQ(at_stop.At(t0 + T).payload_kg, to) << "stop " << k;
    ASSERT_LT(t0 + T, b);
    if (from != to) {
      ++changes;
      steps.push_back(t0);
      EXPECT_GT(std::abs(at_stop.At(t0 + 0.5 * T).payload_kg - from), 0.0);
    }
  }
  EXPECT_GE(changes, 3);
  const std::vector<double> reported = at_stop.PayloadReportTimes();
  ASSERT_EQ(reported.size(), steps.size());
  for (size_t i = 0; i < steps.size(); ++i) EXPECT_NEAR(reported[i], steps[i], 1e-12) << i;
  EXPECT_TRUE(SimArmConditions(100.0, 0, 1).PayloadReportTimes().empty());  // no payloads
}

// The panda's IMU has turned axes, the UR10 none: the simulator's mounting and the run's
// orientation follow.
TEST(CellSimYaml, ImuAxesAndPositionOnlyCells) {
  const Loaded p = Load("panda");
  const sim::SensorSimSettings s = SimSensorSettings(p.cell, p.sim);
  EXPECT_TRUE(s.imu.mounting);
  // axes [-y, x, z]: a vector along the mounting frame's x reads along the sensor's −y.
  EXPECT_EQ(s.imu.R_SI * Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitY());
  EXPECT_EQ(s.imu.gyro_noise_density, 1.5e-4);
  EXPECT_EQ(s.position.sigma, 3e-5);
  EXPECT_TRUE(SimRunSettings(p.cell, p.sim).orientation);
  const Loaded u = Load("ur10");
  EXPECT_FALSE(SimRunSettings(u.cell, u.sim).orientation);
  // The tracker's worst axis (the simulator draws one σ for all three).
  EXPECT_EQ(SimSensorSettings(u.cell, u.sim).position.sigma, 2e-4);
  EXPECT_EQ(SimRunSettings(u.cell, u.sim).num_cal, 40);
}

// Independent truth: a second model whose nominal set-up frames are the sim file's truth, at the
// arm's errors only, must put every marker and the IMU where the cell's model at TrueErrors does.
TEST(CellSimYaml, TruthFramesAreWhereTheSimFileSaysThem) {
  for (const std::string name : {"grb3016", "ur10", "panda"}) {
    SCOPED_TRACE(name);
    const Loaded d = Load(name);
    const Eigen::VectorXd x = TrueErrors(d.cell, d.sim);
    io::RobotSpec truth = d.cell.robot_spec;
    truth.base->xyz = d.sim.world_from_base->xyz;
    truth.base->rpy = d.sim.world_from_base->rpy;
    for (auto& m : truth.markers)
      for (const auto& [id, p] : d.sim.markers)
        if (id == m.id) m.xyz = p;
    if (truth.imu) truth.imu->rpy = d.sim.flange_to_imu->rpy;
    if (truth.earth) truth.earth->rpy = d.sim.earth_from_world->rpy;
    const kinematics::KinematicModel other = io::BuildModel(truth);
    ASSERT_EQ(other.num_params(), d.cell.model.num_params());
    Eigen::VectorXd x_other = other.Nominal();
    for (int i = 0; i < other.num_params(); ++i)
      if (!kinematics::IsSetupGroup(other.parameters()[i].group)) x_other(i) = x(i);
    // The arm's errors are what the file asks for.
    if (d.sim.arm_errors == ArmErrorsKind::kTable3) {
      EXPECT_DOUBLE_EQ(x(d.cell.model.FindParameter("a1")), 3.596e-3);
    } else {
      double sum2 = 0;
      int n = 0;
      for (int i = 0; i < x.size(); ++i)
        if (!kinematics::IsSetupGroup(other.parameters()[i].group) &&
            !other.parameters()[i].is_angle) {
          sum2 += x(i) * x(i);
          ++n;
        }
      EXPECT_GT(std::sqrt(sum2 / n), 0.3 * d.sim.sigma_length);
      EXPECT_LT(std::sqrt(sum2 / n), 3.0 * d.sim.sigma_length);
    }
    sim::Rng rng(5);
    for (const Eigen::VectorXd& q : sim::SampleJoints(d.cell.model, 10, rng))
      for (size_t slot = 0; slot < d.cell.model.markers().size(); ++slot) {
        const auto a = d.cell.model.ForMarker(static_cast<int>(slot)).Forward(q, x);
        const auto b = other.ForMarker(static_cast<int>(slot)).Forward(q, x_other);
        EXPECT_LT((a.p_WM_W - b.p_WM_W).norm(), 1e-12);
        EXPECT_LT((a.R_EI - b.R_EI).norm(), 1e-12);
      }
  }
}

// The truth on the base set reproduces the truth robot for every shipped sim cell, full poses
// (Panda) or positions only (UR10), and the set-up frames are in the base set. Except marker 2 of
// the UR10: today's simulated cell measures the model's first marker only (MakeCell's
// identifiability over joints, SimulateWindows' windows), so a second marker's offset is not seen.
// Measuring every marker is for the sim source's integration; this test then loses its exception.
TEST(CellSimYaml, EveryShippedSimCellHasItsSetUpInTheBaseSet) {
  for (const std::string name : {"ur10", "panda"}) {
    SCOPED_TRACE(name);
    const Loaded d = Load(name);
    const Cell c = MakeSimCell(d.cell, d.sim);
    EXPECT_EQ(static_cast<int>(c.base.size()), c.ident.rank);
    EXPECT_LT(c.eq_residual_m, 1e-6);
    std::vector<std::string> unseen;
    for (int i : c.setup)
      if (!std::binary_search(c.base.begin(), c.base.end(), i))
        unseen.push_back(c.model.parameters()[i].name);
    const std::vector<std::string> expected =
        name == "ur10" ? std::vector<std::string>{"marker2_x", "marker2_y", "marker2_z"}
                       : std::vector<std::string>{};
    EXPECT_EQ(unseen, expected);
  }
}

// The pose-level sim file (sensor_acquisition --level poses): the paper's GRB3016 with its Table 3
// errors and nothing else (every frame of grb3016_poses.yaml is fixed at the identity), measured
// as the cell's 6-DoF tracker measures: the truth is sim::Table3Errors of the robot file's model.
TEST(CellSimYaml, PoseLevelSimFileIsTheTable3Arm) {
  const Loaded d = Load("grb3016_poses");
  EXPECT_EQ(d.sim.seed, 1u);
  EXPECT_FALSE(d.cell.spec.imu.has_value());
  EXPECT_TRUE(d.cell.spec.position.orientation);
  const io::LoadedRobot robot =
      io::LoadRobot(std::filesystem::path(RCAL_SOURCE_DIR) / "config" / "robots" / "grb3016.yaml");
  const Eigen::VectorXd x = TrueErrors(d.cell, d.sim);
  const Eigen::VectorXd x_paper = sim::Table3Errors(robot.model);
  // The same arm parameters by name; the cell adds no set-up parameter (every frame fixed).
  ASSERT_EQ(x.size(), d.cell.model.num_params());
  int arm = 0;
  for (int i = 0; i < d.cell.model.num_params(); ++i) {
    const std::string& name = d.cell.model.parameters()[i].name;
    const auto& names = robot.model.parameters();
    const auto it =
        std::find_if(names.begin(), names.end(), [&](const auto& p) { return p.name == name; });
    ASSERT_NE(it, names.end()) << name;
    EXPECT_EQ(x[i], x_paper[it - names.begin()]) << name;
    arm += x[i] != 0.0;
  }
  EXPECT_GT(arm, 0);
  // The tool frame at the truth is the robot file's at the paper's errors, at any joints.
  sim::Rng rng(7);
  for (const Eigen::VectorXd& q : sim::SampleJoints(robot.model, 20, rng)) {
    const kinematics::ToolPose a = d.cell.model.Forward(q, x), b = robot.model.Forward(q, x_paper);
    EXPECT_LT((a.p_WM_W - b.p_WM_W).norm(), 1e-12);
    EXPECT_LT((a.R_EI - b.R_EI).cwiseAbs().maxCoeff(), 1e-12);
  }
}

// A step "at stop 3" starts while the arm moves from stop 2 to stop 3: stop 2's still interval is
// wholly before it, stop 3's wholly after it; a stop the programme does not have is refused.
TEST(CellSimYaml, AnOffsetStepStartsOnTheWayToItsStop) {
  const Loaded d = Load("grb3016");
  const SimProgramme p = MakeSimProgramme(d.cell, d.sim, 1, 5, 2);
  const auto step = OffsetStepInProgramme(p, sim::ParseJointOffsetStep("j2=1e-3@3", p.cell.model));
  EXPECT_EQ(step.joint, 1);
  EXPECT_DOUBLE_EQ(step.delta, 1e-3);
  const auto& trajectory = p.truth.trajectory();
  EXPECT_LE(trajectory.StillInterval(2).second, step.t_s);
  EXPECT_LT(step.t_s, trajectory.StillInterval(3).first);
  EXPECT_EQ(trajectory.StillAt(step.t_s + 0.01), -1);  // moving
  EXPECT_THROW(OffsetStepInProgramme(p, {1, 1e-3, 9}), std::invalid_argument);
}

TEST(CellSimYaml, TruthMustFitTheCell) {
  Loaded d = Load("grb3016");
  CellSimSpec s = d.sim;
  s.flange_to_imu.reset();
  EXPECT_NE(ErrorOf([&] {
              TrueErrors(d.cell, s);
            }).find("grb3016.sim.yaml: truth.flange_to_imu: missing: the cell"),
            std::string::npos);
  s = d.sim;
  s.markers.push_back({5, Eigen::Vector3d::Zero()});
  EXPECT_NE(ErrorOf([&] {
              TrueErrors(d.cell, s);
            }).find("truth.markers: marker 5 is not identified by the cell"),
            std::string::npos);
  s = d.sim;
  s.markers.clear();
  EXPECT_NE(ErrorOf([&] {
              TrueErrors(d.cell, s);
            }).find("truth.markers: marker 0 is identified by the cell"),
            std::string::npos);
  const Loaded u = Load("ur10");
  s = u.sim;
  s.arm_errors = ArmErrorsKind::kTable3;
  EXPECT_NE(ErrorOf([&] {
              TrueErrors(u.cell, s);
            }).find("ur10.sim.yaml: arm_errors: table3 is the GRB3016's D–H table"),
            std::string::npos);
  s = u.sim;
  s.earth_from_world = TrueFrame{};
  EXPECT_NE(ErrorOf([&] { TrueErrors(u.cell, s); }).find("truth.earth_from_world: the cell"),
            std::string::npos);
}

struct BadCase {
  std::string replace, with, expected;
};

void PrintTo(const BadCase& c, std::ostream* os) {
  *os << "'" << c.with << "'";
}

class CellSimYamlBadInput : public ::testing::TestWithParam<BadCase> {};

TEST_P(CellSimYamlBadInput, ErrorNamesFileAndKey) {
  const BadCase& c = GetParam();
  std::string text = io::ReadFile(CellsDir() / "grb3016.sim.yaml");
  Replace(text, c.replace, c.with);
  const std::string msg = ErrorOf([&] { ParseCellSimYaml(text, "grb3016.sim.yaml"); });
  EXPECT_EQ(msg.rfind("grb3016.sim.yaml: ", 0), 0u) << msg;
  EXPECT_NE(msg.find(c.expected), std::string::npos) << msg;
}

INSTANTIATE_TEST_SUITE_P(
    Cases, CellSimYamlBadInput,
    ::testing::Values(
        BadCase{"seed: 1", "seed: 1\nsede: 2", "sede: unknown key"},
        BadCase{"schema: rcal.cell_sim/1", "schema: rcal.cell/1",
                "schema: expected rcal.cell_sim/1"},
        BadCase{"seed: 1\n", "", "seed: missing key"},
        BadCase{"cell: grb3016.yaml\n", "", "cell: missing key"},
        BadCase{"seed: 1", "seed: -3", "seed: expected an integer from 0 to 4294967295"},
        BadCase{"arm_errors: table3", "arm_errors: table4",
                "arm_errors: expected none, table3 or {sigma_length"},
        BadCase{"arm_errors: table3", "arm_errors: {sigma_length: 0.5, sigma_angle: 1e-3}",
                "arm_errors.sigma_length: 0.5 m is beyond"},
        BadCase{"arm_errors: table3", "arm_errors: {sigma_length: 5e-4, sigma_angle: 2}",
                "arm_errors.sigma_angle: 2 rad is beyond"},
        BadCase{"arm_errors: table3", "arm_errors: {sigma_length: 5e-4}",
                "arm_errors.sigma_angle: missing key"},
        BadCase{"rpy: [-0.01, 0.017, 0.87]", "rpy: [-0.01, 0.017, 50]",
                "truth.earth_from_world.rpy[2]: beyond 2π: degrees?"},
        BadCase{"{xyz: [1.6, -0.35, 0.42],", "{xyz: [1600, -0.35, 0.42],",
                "truth.world_from_base.xyz[0]: '1600' is beyond 100 m"},
        BadCase{"{id: 0, xyz: [0.034, -0.003, 0.122]}", "{id: 0, xyz: [34, -3, 22]}",
                "truth.markers[0].xyz: beyond 2 m from the flange: millimetres?"},
        BadCase{"flange_to_imu: {rpy:", "flange_to_imu: {xyz: [0, 0, 0], rpy:",
                "truth.flange_to_imu.xyz: unknown key"},
        BadCase{"    - {id: 0, xyz: [0.034, -0.003, 0.122]}",
                "    - {id: 0, xyz: [0.034, -0.003, 0.122]}\n  imu_to_marker: [0, 0, 1.2]",
                "truth.imu_to_marker: beyond 1 m from the IMU: millimetres?"},
        BadCase{"  still_time: 1.5 ", "  still_time: 1500 ", "run.still_time: 1500 s is beyond"},
        BadCase{"  test_poses: 50", "  test_poses: 50.5",
                "run.test_poses: expected an integer from 0 to 100000"},
        BadCase{"  test_poses: 50", "  dropout: 10", "run.dropout: 10 is beyond"},
        BadCase{"  test_poses: 50", "  gyro_bias: on", "run.gyro_bias: expected true or false"},
        BadCase{"  test_poses: 50", "  noise: 2", "run.noise: unknown key"}));

// Every shipped sim cell runs through today's simulated cell and calibrates: the shipped set-ups
// are reachable, every stop gives a window, and the arm and set-up are identified. A short
// programme (30 + 20 stops); the figures are printed (seed of each file: 0.029, 0.039, 0.050 mm).
// SimulateWindows still simulates its own default sensors (SimSensorSettings is not wired in:
// issue 13's sim source), and RunOnline the experiment's EKF (cell::MakeEkf).
TEST(CellSimYaml, EveryShippedSimCellCalibrates) {
  for (const std::string name : {"grb3016", "ur10", "panda"}) {
    SCOPED_TRACE(name);
    const Loaded d = Load(name);
    const Cell c = MakeSimCell(d.cell, d.sim);
    RunSettings rs = SimRunSettings(d.cell, d.sim);
    rs.num_cal = 30;
    rs.num_test = 20;
    const Windows w = SimulateWindows(c, rs);
    EXPECT_EQ(w.missing, 0);
    std::vector<Eigen::VectorXd> test_q;
    for (const auto& m : w.test) test_q.push_back(m.q);
    const OnlineResult r = RunOnline(c, w.cal, test_q, d.cell.spec.identifier.guess_poses);
    std::printf("%s: windows %.3f mm, %d accepted, %d rejected, test error %.3f mm\n", name.c_str(),
                w.mean_position_error_m * 1e3, r.accepted, r.rejected,
                r.test_error_after_pose_mm.back());
    EXPECT_LT(r.test_error_after_pose_mm.back(), 0.2);  // before: millimetres
  }
}

}  // namespace
}  // namespace rcal::cell
