// The cell file (io/cell_yaml.hpp): every shipped cell loads and builds, with parameter counts
// counted independently from the robots' structure; relative paths; defaults equal to today's
// settings structs field by field; every bad key, type, value and unit refused naming the key.
#include "rcal/io/cell_yaml.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>

#include "io_test_util.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/transport/channels.hpp"
#include "settings_eq.hpp"

namespace rcal::io {
namespace {

using testing::ErrorOf;
using testing::ScratchDir;
using testing::SourceDir;

std::filesystem::path CellPath(const std::string& name) {
  return SourceDir() / "config" / "cells" / name;
}

/// Replaces the first `from` in `text` (which must hold it) by `to`.
void Replace(std::string& text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  ASSERT_NE(at, std::string::npos) << from;
  text.replace(at, from.size(), to);
}

int CountGroup(const kinematics::KinematicModel& m, const std::string& group) {
  int n = 0;
  for (const auto& p : m.parameters()) n += p.group == group ? 1 : 0;
  return n;
}

const ParameterPrior& PriorOf(const BuiltCell& c, const std::string& name) {
  const int i = c.model.FindParameter(name);
  EXPECT_GE(i, 0) << name;
  return c.prior.at(static_cast<size_t>(i));
}

// ---------------------------------------------------------------------------------------------
// The shipped cells.

TEST(CellYaml, Grb3016DemoCellBuildsTheExperimentsModel) {
  const BuiltCell c = LoadCell(CellPath("grb3016.yaml"));
  EXPECT_EQ(c.spec.name, "grb3016_demo");
  EXPECT_FALSE(c.robot.from_urdf);
  // 6 D–H links × (θ, d, a, α) + the 4-parameter tool + world ← base (6) + marker (3) + IMU (3) +
  // earth (3): the 43 of the README's sensor-level experiment.
  EXPECT_EQ(c.model.num_params(), 6 * 4 + 4 + 6 + 3 + 3 + 3);
  EXPECT_EQ(c.model.num_joints(), 6);
  EXPECT_EQ(CountGroup(c.model, "base"), 6);
  EXPECT_EQ(CountGroup(c.model, "marker"), 3);
  EXPECT_EQ(CountGroup(c.model, "imu"), 3);
  EXPECT_EQ(CountGroup(c.model, "earth"), 3);
  ASSERT_EQ(c.model.markers().size(), 1u);
  EXPECT_EQ(c.model.markers()[0].id, 0);
  EXPECT_EQ(c.model.markers()[0].nominal, Eigen::Vector3d(0.03, 0.0, 0.12));
  // Every set-up frame guessed, with the experiment's coarse σ (cell::MakeEkf: 0.05 m, 0.05 rad).
  EXPECT_EQ(c.Guessed().size(), 15u);
  for (int i = 0; i < c.model.num_params(); ++i) {
    const auto& p = c.model.parameters()[i];
    EXPECT_EQ(c.prior[i].kind,
              kinematics::IsSetupGroup(p.group) ? PriorKind::kGuess : PriorKind::kArm)
        << p.name;
    EXPECT_EQ(c.prior[i].sigma, 0.05) << p.name;
  }
  EXPECT_EQ(PriorOf(c, "base_x").key, "identifier.prior_sigma_length");
  EXPECT_EQ(PriorOf(c, "alpha2").key, "identifier.prior_sigma_angle");
  EXPECT_EQ(c.ekf.prior_sigma_length, 0.05);
  EXPECT_EQ(c.ekf.prior_sigma_angle, 0.05);
  EXPECT_EQ(c.ekf.gate_after, 10);
  EXPECT_EQ(c.spec.identifier.guess_poses, 6);
  ASSERT_TRUE(c.spec.imu);
  EXPECT_EQ(c.spec.imu->R_IS, Eigen::Matrix3d::Identity());
  EXPECT_TRUE(c.pipeline.use_orientation);
  EXPECT_EQ(c.pipeline.position.position_sigma, 5e-4);
}

TEST(CellYaml, Ur10CellHasTwoMarkersAndNoOrientation) {
  const BuiltCell c = LoadCell(CellPath("ur10.yaml"));
  EXPECT_TRUE(c.robot.from_urdf);
  EXPECT_EQ(c.robot_spec.base_link, "base_link");
  EXPECT_EQ(c.robot_spec.tip_link, "wrist_3_link");
  // world ← base (6) + 6 revolute joints × 6 placement errors + 2 markers × 3.
  EXPECT_EQ(c.model.num_params(), 6 + 6 * 6 + 2 * 3);
  EXPECT_EQ(c.model.num_joints(), 6);
  EXPECT_EQ(CountGroup(c.model, "imu") + CountGroup(c.model, "earth"), 0);
  ASSERT_EQ(c.model.markers().size(), 2u);
  EXPECT_EQ(c.model.markers()[0].id, 1);
  EXPECT_EQ(c.model.markers()[1].id, 2);
  EXPECT_EQ(c.model.markers()[1].nominal, Eigen::Vector3d(-0.05, 0.03, 0.1));
  EXPECT_FALSE(c.spec.measures_orientation());
  EXPECT_FALSE(c.pipeline.use_orientation);
  // The largest axis σ is the position KF's.
  EXPECT_EQ(c.pipeline.position.position_sigma, 2e-4);
  // Marker 1: value ± 2 mm; marker 2 and the tracker guessed with the identifier's σ.
  EXPECT_EQ(PriorOf(c, "marker1_y").kind, PriorKind::kSetup);
  EXPECT_EQ(PriorOf(c, "marker1_y").sigma, 0.002);
  EXPECT_EQ(PriorOf(c, "marker1_y").key, "frames.markers[0].sigma_xyz");
  EXPECT_EQ(PriorOf(c, "marker2_z").kind, PriorKind::kGuess);
  EXPECT_EQ(PriorOf(c, "marker2_z").sigma, 0.01);
  EXPECT_EQ(PriorOf(c, "base_rz").kind, PriorKind::kGuess);
  EXPECT_EQ(PriorOf(c, "base_rz").sigma, 0.035);
  EXPECT_EQ(c.Guessed().size(), 6u + 3u);
}

TEST(CellYaml, PandaCellHasSevenJointsAnImuAndPriors) {
  const BuiltCell c = LoadCell(CellPath("panda.yaml"));
  // world ← base (6) + 7 joints × 6 + marker (3) + IMU (3) + earth (3).
  EXPECT_EQ(c.model.num_params(), 6 + 7 * 6 + 3 + 3 + 3);
  EXPECT_EQ(c.model.num_joints(), 7);
  ASSERT_TRUE(c.spec.imu);
  // axes [-y, x, z]: the sensor's x axis is the mounting frame's y, its y the mounting −x.
  EXPECT_EQ(c.spec.imu->R_IS * Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY());
  EXPECT_EQ(c.spec.imu->R_IS * Eigen::Vector3d::UnitY(), -Eigen::Vector3d::UnitX());
  EXPECT_EQ(c.spec.imu->R_IS * Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitZ());
  // The nominal set-up is the file's; σ per frame.
  const auto& params = c.model.parameters();
  EXPECT_DOUBLE_EQ(params[c.model.FindParameter("base_rz")].nominal, std::numbers::pi);
  EXPECT_DOUBLE_EQ(params[c.model.FindParameter("base_x")].nominal, 1.2);
  EXPECT_DOUBLE_EQ(params[c.model.FindParameter("imu_rz")].nominal, -std::numbers::pi / 4);
  EXPECT_EQ(PriorOf(c, "base_y").sigma, 0.01);
  EXPECT_EQ(PriorOf(c, "base_rx").sigma, 0.02);
  EXPECT_EQ(PriorOf(c, "imu_ry").sigma, 0.05);
  EXPECT_EQ(PriorOf(c, "marker_z").sigma, 0.001);
  EXPECT_EQ(PriorOf(c, "earth_rz").kind, PriorKind::kGuess);
  EXPECT_EQ(c.Guessed().size(), 3u);
  EXPECT_EQ(c.PriorSigma().size(), c.model.num_params());
  // The pipeline takes the IMU's noise.
  EXPECT_EQ(c.pipeline.orientation.gyro_noise_density, 1.5e-4);
  EXPECT_EQ(c.pipeline.orientation.gyro_range, 34.9);
  EXPECT_EQ(c.pipeline.position.position_sigma, 3e-5);
  EXPECT_EQ(c.pipeline.orientation.max_step, 0.1);  // 100 Hz: the filter's own
}

// An IMU slower than 30 Hz: the orientation KF's longest step is three of its periods
// (estimation::MaxStepForRate), so its every step is not taken for a silence.
TEST(CellYaml, ASlowImuGivesTheOrientationKfThreeOfItsPeriods) {
  std::string text = ReadFile(CellPath("panda.yaml"));
  Replace(text, "    id: mems-imu-sim\n    rate: 100", "    id: mems-imu-sim\n    rate: 10");
  CellSpec spec = ParseCellYaml(text, "panda.yaml");
  spec.robot.file = CellPath("panda.yaml").parent_path() / spec.robot.file;
  ASSERT_TRUE(spec.imu);
  ASSERT_EQ(spec.imu->rate, 10.0);
  EXPECT_NEAR(BuildCell(spec).pipeline.orientation.max_step, 0.3, 1e-15);
}

// The robot file's own set-up entries give way to the cell's.
TEST(CellYaml, CellFramesReplaceTheRobotFilesSetup) {
  ScratchDir dir;
  AtomicWriteFile(dir / "arm.yaml", ReadFile(SourceDir() / "config/robots/seven_dof.yaml"));
  const RobotSpec own = LoadRobotSpec(dir / "arm.yaml");
  ASSERT_TRUE(own.base && own.imu && own.earth && !own.markers.empty());
  std::string text = ReadFile(CellPath("ur10.yaml"));
  Replace(text, "../robots/ur10.urdf", "arm.yaml");
  Replace(text, "  base_link: base_link", "");
  Replace(text, "  tip_link: wrist_3_link", "");
  AtomicWriteFile(dir / "cell.yaml", text);
  const BuiltCell c = LoadCell(dir / "cell.yaml");
  EXPECT_TRUE(c.robot.spec.base.has_value());  // as loaded
  EXPECT_FALSE(c.robot_spec.imu || c.robot_spec.earth);
  EXPECT_EQ(c.robot_spec.base->xyz, Eigen::Vector3d::Zero());
  ASSERT_EQ(c.robot_spec.markers.size(), 2u);
  EXPECT_EQ(c.robot_spec.markers[0].id, 1);
  EXPECT_EQ(c.model.num_params(), 6 + 7 * 4 + 6);
}

TEST(CellYaml, FixedFramesHaveNoParameters) {
  std::string text = ReadFile(CellPath("panda.yaml"));
  Replace(text, "mode: prior, rpy: [0, 0, -pi/4], sigma_rpy: 0.05",
          "mode: fixed, rpy: [0, 0, -pi/4]");
  ScratchDir dir;
  CellSpec spec = ParseCellYaml(text, "panda.yaml");
  spec.robot.file = CellPath("panda.yaml").parent_path() / spec.robot.file;
  const BuiltCell c = BuildCell(spec);
  EXPECT_EQ(c.model.num_params(), 6 + 7 * 6 + 3 + 3);
  EXPECT_EQ(c.model.FindParameter("imu_rz"), -1);
  ASSERT_TRUE(c.robot_spec.imu);
  EXPECT_FALSE(c.robot_spec.imu->identify);
}

// ---------------------------------------------------------------------------------------------
// Paths.

TEST(CellYaml, RelativeRobotPathIsResolvedAgainstTheCellFilesFolder) {
  ScratchDir dir;
  std::filesystem::create_directories(dir / "robots");
  std::filesystem::create_directories(dir / "cells");
  AtomicWriteFile(dir / "robots/arm.yaml", ReadFile(SourceDir() / "config/robots/grb3016.yaml"));
  std::string text = ReadFile(CellPath("grb3016.yaml"));
  Replace(text, "../robots/grb3016.yaml", "../robots/arm.yaml");
  AtomicWriteFile(dir / "cells/cell.yaml", text);
  // From another working directory: the cell file's folder counts, not the process's.
  const auto cwd = std::filesystem::current_path();
  std::filesystem::current_path(dir / "robots");
  const CellSpec spec = LoadCellSpec(dir / "cells/cell.yaml");
  std::filesystem::current_path(cwd);
  EXPECT_EQ(spec.robot.file, (dir / "robots/arm.yaml").lexically_normal());
  EXPECT_EQ(BuildCell(spec).model.num_params(), 43);
  // ParseCellYaml keeps the path as written.
  EXPECT_EQ(ParseCellYaml(text, "x.yaml").robot.file, "../robots/arm.yaml");
  // An absolute path stays.
  std::string abs = text;
  Replace(abs, "../robots/arm.yaml", (dir / "robots/arm.yaml").string());
  AtomicWriteFile(dir / "cells/abs.yaml", abs);
  EXPECT_EQ(LoadCellSpec(dir / "cells/abs.yaml").robot.file, dir / "robots/arm.yaml");
}

TEST(CellYaml, MissingOrBadRobotFileNamesTheCellAndTheKey) {
  ScratchDir dir;
  AtomicWriteFile(dir / "cell.yaml", ReadFile(CellPath("grb3016.yaml")));
  std::string msg = ErrorOf([&] { LoadCell(dir / "cell.yaml"); });
  EXPECT_NE(msg.find("cell.yaml: robot.file: '"), std::string::npos) << msg;
  EXPECT_NE(msg.find("robots/grb3016.yaml' does not exist"), std::string::npos) << msg;
  // A tip link the URDF does not have: the robot file's own error, under the cell's key.
  std::string text = ReadFile(CellPath("ur10.yaml"));
  Replace(text, "tip_link: wrist_3_link", "tip_link: wrist_9_link");
  CellSpec spec = ParseCellYaml(text, "ur10.yaml");
  spec.robot.file = SourceDir() / "config/robots/ur10.urdf";
  msg = ErrorOf([&] { BuildCell(spec); });
  EXPECT_NE(msg.find("ur10.yaml: robot.file: "), std::string::npos) << msg;
  EXPECT_NE(msg.find("wrist_9_link"), std::string::npos) << msg;
}

// ---------------------------------------------------------------------------------------------
// Defaults: today's settings, field by field (a change to either side fails here).

constexpr const char* kMinimalCell = R"(schema: rcal.cell/1
name: minimal
robot: {file: grb3016.yaml}
frames:
  world_from_base: guess
  earth_from_world: guess
  flange_to_imu: guess
  markers: [{id: 0, mode: guess}]
sensors:
  imu:
    rate: 100
    noise_density: {gyro: 1.7453292519943277e-4, accel: 5.886e-4, mag: 2e-8}
    earth: ned
  position: {markers: [0], sigma: [5e-4, 5e-4, 5e-4], rate: 100}
)";

TEST(CellYaml, DefaultsAreTodaysSettings) {
  const CellSpec spec = ParseCellYaml(kMinimalCell, "minimal.yaml");
  const estimation::PosePipelineSettings ps;
  const StillWindowSpec& sw = spec.still_window;
  EXPECT_EQ(sw.joint_rate_threshold, ps.still.joint_rate_threshold);
  EXPECT_EQ(sw.gyro_threshold, ps.still.gyro_threshold);
  EXPECT_EQ(sw.accel_threshold, ps.still.accel_threshold);
  EXPECT_EQ(sw.min_duration, ps.still.min_duration);
  EXPECT_EQ(sw.settle_time, ps.settle_time);
  EXPECT_EQ(sw.min_window_samples, ps.min_window_samples);
  EXPECT_EQ(sw.min_raw_samples, ps.min_raw_samples);
  EXPECT_EQ(sw.max_gap, ps.max_gap);
  EXPECT_EQ(sw.rest_from_joints, ps.rest_from_joints);
  EXPECT_EQ(sw.warmup, 0.0);  // still_window --warmup's default
  const identification::EkfSettings es;
  const IdentifierSpec& id = spec.identifier;
  EXPECT_EQ(id.prior_sigma_length, es.prior_sigma_length);
  EXPECT_EQ(id.prior_sigma_angle, es.prior_sigma_angle);
  EXPECT_EQ(id.drift_sigma_length, es.drift_sigma_length);
  EXPECT_EQ(id.drift_sigma_angle, es.drift_sigma_angle);
  EXPECT_EQ(id.gate_probability, es.gate_probability);
  EXPECT_EQ(id.gate_after, es.gate_after);
  // ekf_identifier's options (services/ekf_identifier/main.cpp Options): --guess-poses 6,
  // --ident-seed 1, --joint-margin 0.1.
  EXPECT_EQ(id.guess_poses, 6);
  EXPECT_EQ(id.base_set_seed, 1u);
  EXPECT_EQ(id.joint_margin, 0.1);
  // The IMU's defaults: gravity and ranges as the filters take them today.
  ASSERT_TRUE(spec.imu);
  EXPECT_EQ(spec.imu->gravity, ps.orientation.gravity);
  EXPECT_EQ(spec.imu->gyro_range, ps.orientation.gyro_range);
  EXPECT_EQ(spec.imu->accel_range, ps.orientation.accel_range);
  EXPECT_EQ(spec.imu->R_IS, Eigen::Matrix3d::Identity());
  EXPECT_FALSE(spec.position.orientation);
  // Channels: services/transport's table.
  namespace ch = transport::channels;
  const CellChannels& c = spec.channels;
  EXPECT_EQ(c.imu, ch::kImu);
  EXPECT_EQ(c.position, ch::kPosition);
  EXPECT_EQ(c.joints, ch::kJoints);
  EXPECT_EQ(c.orientation, ch::kOrientation);
  EXPECT_EQ(c.tool_position, ch::kToolPosition);
  EXPECT_EQ(c.ins_orientation, ch::kInsOrientation);
  EXPECT_EQ(c.ins_tool_position, ch::kInsToolPosition);
  EXPECT_EQ(c.pose_measurement, ch::kPoseMeasurement);
  EXPECT_EQ(c.kinematic_params, ch::kKinematicParams);
  EXPECT_EQ(c.calibration_status, ch::kCalibrationStatus);
  EXPECT_EQ(c.ik_request, ch::kIkRequest);
  EXPECT_EQ(c.ik_command, ch::kIkCommand);
  EXPECT_EQ(c.health, ch::kHealth);
  EXPECT_EQ(c.supervisor_state, ch::kSupervisorState);
  EXPECT_EQ(c.clock_offset, ch::kClockOffset);
  EXPECT_EQ(c.next_poses, ch::kNextPoses);
  EXPECT_EQ(c.model_discrepancy, ch::kModelDiscrepancy);
  EXPECT_EQ(c.arm_conditions, ch::kArmConditions);
}

// A cell that sets nothing but the sensors today's defaults describe builds exactly today's
// pipeline and EKF settings.
TEST(CellYaml, MinimalCellBuildsTodaysPipelineAndEkfSettings) {
  CellSpec spec = ParseCellYaml(kMinimalCell, "minimal.yaml");
  spec.robot.file = SourceDir() / "config/robots/grb3016.yaml";
  const BuiltCell c = BuildCell(spec);
  rcal::testing::ExpectSameSettings(c.pipeline, estimation::PosePipelineSettings{});
  rcal::testing::ExpectSameSettings(c.ekf, identification::EkfSettings{});
}

TEST(CellYaml, SetValuesReachTheSettings) {
  std::string text = kMinimalCell;
  text +=
      "still_window: {joint_rate_threshold: 2e-3, gyro_threshold: 0.03, accel_threshold: 0.4,\n"
      "  min_duration: 0.7, settle_time: 0.3, min_window_samples: 30, min_raw_samples: 12,\n"
      "  max_gap: 0.25, rest_from_joints: false, warmup: 2}\n"
      "identifier: {prior_sigma_length: 0.02, prior_sigma_angle: 0.04, drift_sigma_length: 1e-6,\n"
      "  drift_sigma_angle: 2e-6, gate_probability: 0.999, gate_after: 5, guess_poses: 8,\n"
      "  base_set_seed: 7, joint_margin: 0.05}\n"
      "channels: {imu: CELL2_IMU, pose_measurement: cell2/POSE}\n";
  Replace(text, "earth: ned",
          "earth: enu\n    gravity: 9.80\n    to_marker: [0.01, -0.02, 0.03]\n"
          "    accel_bias: {sigma: 1.5e-4, random_walk: 2e-5}\n    accel_delay: 0.00225");
  CellSpec spec = ParseCellYaml(text, "set.yaml");
  ASSERT_TRUE(spec.imu.has_value());
  EXPECT_EQ(spec.imu->to_marker_I, Eigen::Vector3d(0.01, -0.02, 0.03));
  EXPECT_FALSE(spec.imu->estimate_to_marker);
  EXPECT_EQ(spec.imu->accel_delay, 0.00225);
  {
    std::string estimated = text;
    Replace(estimated, "to_marker: [0.01, -0.02, 0.03]", "to_marker: estimate");
    const CellSpec e = ParseCellYaml(estimated, "estimated.yaml");
    EXPECT_TRUE(e.imu->estimate_to_marker);
    EXPECT_TRUE(e.imu->to_marker_I.isZero());
  }
  spec.robot.file = SourceDir() / "config/robots/grb3016.yaml";
  const BuiltCell c = BuildCell(spec);
  const auto& p = c.pipeline;
  EXPECT_EQ(p.still.joint_rate_threshold, 2e-3);
  EXPECT_EQ(p.still.gyro_threshold, 0.03);
  EXPECT_EQ(p.still.accel_threshold, 0.4);
  EXPECT_EQ(p.still.min_duration, 0.7);
  EXPECT_EQ(p.still.gravity, 9.80);
  EXPECT_EQ(p.settle_time, 0.3);
  EXPECT_EQ(p.min_window_samples, 30);
  EXPECT_EQ(p.min_raw_samples, 12);
  EXPECT_EQ(p.max_gap, 0.25);
  EXPECT_FALSE(p.rest_from_joints);
  EXPECT_EQ(p.orientation.earth, estimation::EarthFrame::kEnu);
  EXPECT_EQ(p.accel_bias_sigma, 1.5e-4);
  EXPECT_EQ(p.accel_bias_random_walk, 2e-5);
  EXPECT_EQ(p.position.earth, estimation::EarthFrame::kEnu);
  EXPECT_EQ(p.orientation.gravity, 9.80);
  EXPECT_EQ(p.position.gravity, 9.80);
  EXPECT_EQ(p.position.accel_delay, 0.00225);
  EXPECT_EQ(c.spec.still_window.warmup, 2.0);
  EXPECT_EQ(c.ekf.prior_sigma_length, 0.02);
  EXPECT_EQ(c.ekf.prior_sigma_angle, 0.04);
  EXPECT_EQ(c.ekf.drift_sigma_length, 1e-6);
  EXPECT_EQ(c.ekf.drift_sigma_angle, 2e-6);
  EXPECT_EQ(c.ekf.gate_probability, 0.999);
  EXPECT_EQ(c.ekf.gate_after, 5);
  EXPECT_EQ(c.spec.identifier.guess_poses, 8);
  EXPECT_EQ(c.spec.identifier.base_set_seed, 7u);
  EXPECT_EQ(c.spec.identifier.joint_margin, 0.05);
  EXPECT_EQ(c.spec.channels.imu, "CELL2_IMU");
  EXPECT_EQ(c.spec.channels.pose_measurement, "cell2/POSE");
  EXPECT_EQ(c.spec.channels.joints, "JOINTS");
  // The arm's σ follow the identifier's.
  EXPECT_EQ(PriorOf(c, "a1").sigma, 0.02);
  EXPECT_EQ(PriorOf(c, "theta1").sigma, 0.04);
}

TEST(CellYaml, FrameForms) {
  std::string text = kMinimalCell;
  Replace(text, "  world_from_base: guess",
          "  world_from_base: {mode: prior, xyz: [1, 2, 0.5], rpy: [0, 0, pi/2],\n"
          "                    sigma_xyz: [0.01, 0.02, 0.03], sigma_rpy: 0.1}");
  Replace(text, "  flange_to_imu: guess",
          "  flange_to_imu: {mode: guess, rpy: [0, 0, pi], sigma_rpy: [0.1, 0.2, 0.3]}");
  Replace(text, "{id: 0, mode: guess}", "{id: 0, mode: fixed, xyz: [0, 0, 0.1]}");
  const CellSpec s = ParseCellYaml(text, "forms.yaml");
  const SetupFrameSpec& b = s.frames.world_from_base;
  EXPECT_EQ(b.mode, SetupMode::kPrior);
  EXPECT_EQ(b.xyz, Eigen::Vector3d(1, 2, 0.5));
  EXPECT_DOUBLE_EQ(b.rpy(2), std::numbers::pi / 2);
  EXPECT_EQ(*b.sigma_xyz, Eigen::Vector3d(0.01, 0.02, 0.03));
  EXPECT_EQ(*b.sigma_rpy, Eigen::Vector3d::Constant(0.1));
  ASSERT_TRUE(s.frames.flange_to_imu);
  EXPECT_EQ(s.frames.flange_to_imu->mode, SetupMode::kGuess);
  EXPECT_EQ(*s.frames.flange_to_imu->sigma_rpy, Eigen::Vector3d(0.1, 0.2, 0.3));
  EXPECT_FALSE(s.frames.flange_to_imu->sigma_xyz);
  EXPECT_EQ(s.frames.earth_from_world->mode, SetupMode::kGuess);
  EXPECT_EQ(s.frames.earth_from_world->rpy, Eigen::Vector3d::Zero());
  EXPECT_EQ(s.frames.markers[0].frame.mode, SetupMode::kFixed);
  CellSpec spec = s;
  spec.robot.file = SourceDir() / "config/robots/grb3016.yaml";
  const BuiltCell c = BuildCell(spec);
  // sigma_rpy is (roll, pitch, yaw): imu_rx takes 0.1, imu_rz 0.3.
  EXPECT_EQ(PriorOf(c, "imu_rx").sigma, 0.1);
  EXPECT_EQ(PriorOf(c, "imu_ry").sigma, 0.2);
  EXPECT_EQ(PriorOf(c, "imu_rz").sigma, 0.3);
  EXPECT_EQ(PriorOf(c, "base_z").sigma, 0.03);
  EXPECT_EQ(PriorOf(c, "base_z").key, "frames.world_from_base.sigma_xyz");
  EXPECT_EQ(c.model.FindParameter("marker_x"), -1);  // fixed
}

// A 6-DoF tracker is the orientation source when there is no IMU: flange → tracked body, no
// earth frame.
TEST(CellYaml, TrackerOrientationWithoutImu) {
  std::string text = ReadFile(CellPath("ur10.yaml"));
  Replace(text, "    orientation: false", "    orientation: true\n    orientation_sigma: 2e-4");
  Replace(text, "  markers:\n    - {id: 1", "  flange_to_imu: guess\n  markers:\n    - {id: 1");
  const CellSpec s = ParseCellYaml(text, "ur10.yaml");
  EXPECT_TRUE(s.measures_orientation());
  EXPECT_FALSE(s.imu);
  EXPECT_EQ(s.position.orientation_sigma, 2e-4);
  ASSERT_TRUE(s.frames.flange_to_imu);
  EXPECT_FALSE(s.frames.earth_from_world);
}

// ---------------------------------------------------------------------------------------------
// Bad input: each case edits a shipped cell and must be refused naming the key path.

struct BadCase {
  std::string file;     // the shipped cell edited
  std::string replace;  // text in it
  std::string with;     // replacement
  std::string expected;
};

void PrintTo(const BadCase& c, std::ostream* os) {
  *os << c.file << ": '" << c.with << "'";
}

class CellYamlBadInput : public ::testing::TestWithParam<BadCase> {};

TEST_P(CellYamlBadInput, ErrorNamesFileAndKey) {
  const BadCase& c = GetParam();
  std::string text = ReadFile(CellPath(c.file));
  const auto at = text.find(c.replace);
  ASSERT_NE(at, std::string::npos) << "test case text not found: " << c.replace;
  text.replace(at, c.replace.size(), c.with);
  const std::string msg = ErrorOf([&] { ParseCellYaml(text, c.file); });
  EXPECT_EQ(msg.rfind(c.file + ": ", 0), 0u) << msg;
  EXPECT_NE(msg.find(c.expected), std::string::npos) << msg;
  if (msg.find("malformed YAML") == std::string::npos) {
    EXPECT_NE(msg.find(" (line "), std::string::npos) << msg;
  }
}

const std::string kG = "grb3016.yaml", kU = "ur10.yaml", kP = "panda.yaml";

INSTANTIATE_TEST_SUITE_P(
    Cases, CellYamlBadInput,
    ::testing::Values(
        // unknown keys
        BadCase{kG, "name: grb3016_demo", "name: grb3016_demo\nnmae: x", "nmae: unknown key"},
        BadCase{kG, "schema: rcal.cell/1", "schema: rcal.cell/1\nunits: mm",
                "units: unknown key (cell files are SI only"},
        BadCase{kG, "  world_from_base: guess", "  world_from_tracker: guess",
                "frames.world_from_tracker: unknown key"},
        BadCase{kG, "xyz: [0.03, 0, 0.12]}", "xyz: [0.03, 0, 0.12], rpy: [0, 0, 0]}",
                "frames.markers[0].rpy: unknown key"},
        BadCase{kP, "flange_to_imu: {mode: prior, rpy",
                "flange_to_imu: {mode: prior, xyz: [0, 0, 0], rpy",
                "frames.flange_to_imu.xyz: unknown key"},
        BadCase{kG, "    earth: ned", "    earth: ned\n    temperature: 20",
                "sensors.imu.temperature: unknown key"},
        BadCase{kG, "  gate_after: 10", "  gate_after: 10\n  gate_afterwards: 3",
                "identifier.gate_afterwards: unknown key"},
        BadCase{kP, "  settle_time: 0.2 ", "  settle: 0.2 ", "still_window.settle: unknown key"},
        BadCase{kG,
                "identifier:", "channels: {imus: IMU}\nidentifier:", "channels.imus: unknown key"},
        BadCase{kG, "noise_density: {gyro", "noise_density: {gyros: 1e-4, gyro",
                "sensors.imu.noise_density.gyros: unknown key"},
        // missing keys
        BadCase{kG, "schema: rcal.cell/1\n", "", "schema: missing key"},
        BadCase{kG, "name: grb3016_demo\n", "", "name: missing key"},
        BadCase{kG, "  file: ../robots/grb3016.yaml   # relative to this file\n", "",
                "robot.file: missing key"},
        BadCase{kG, "  world_from_base: guess ", "  # ", "frames.world_from_base: missing key"},
        BadCase{kG, "  earth_from_world: guess ", "  # ", "frames.earth_from_world: missing key"},
        BadCase{kG, "  flange_to_imu: guess ", "  # ", "frames.flange_to_imu: missing key"},
        BadCase{kG, "    sigma: [5e-4, 5e-4, 5e-4]", "", "sensors.position.sigma: missing key"},
        BadCase{kG, "    rate: 100                    # [Hz]\n    axes", "    axes",
                "sensors.imu.rate: missing key"},
        BadCase{kG, ", mag: 2e-8}", "}", "sensors.imu.noise_density.mag: missing key"},
        BadCase{kP, "sigma_xyz: 0.001}", "}", "frames.markers[0].sigma_xyz: missing key"},
        BadCase{kP, "    mode: prior\n    xyz: [1.2, 0.4, 0]", "    mode: prior",
                "frames.world_from_base.xyz: missing key"},
        BadCase{kG, "{id: 0, mode: guess,", "{mode: guess,", "frames.markers[0].id: missing key"},
        BadCase{kG, "{id: 0, mode: guess,", "{id: 0,", "frames.markers[0].mode: missing key"},
        // wrong types and values
        BadCase{kG, "schema: rcal.cell/1", "schema: rcal.cell/2", "schema: expected rcal.cell/1"},
        BadCase{kG, "name: grb3016_demo", "name: grb 3016",
                "name: 'grb 3016' is not a safe identifier"},
        BadCase{kG, "name: grb3016_demo", "name: ../etc", "name: '../etc' is not a safe"},
        BadCase{kG, "file: ../robots/grb3016.yaml", "file: ../robots/grb3016.txt",
                "robot.file: '../robots/grb3016.txt': expected a .yaml (rcal.robot/1) or .urdf"},
        BadCase{kG, "  id: grb3016-sim", "  id: grb3016-sim\n  tip_link: flange",
                "robot.tip_link: only for a URDF robot"},
        BadCase{kG, "  world_from_base: guess ", "  world_from_base: unknown ",
                "frames.world_from_base: expected `guess` or a map"},
        BadCase{kG, "{id: 0, mode: guess,", "{id: 0, mode: maybe,",
                "frames.markers[0].mode: expected fixed, prior or guess, got 'maybe'"},
        BadCase{kP, "{mode: prior, rpy: [0, 0, -pi/4], sigma_rpy: 0.05}",
                "{mode: fixed, rpy: [0, 0, -pi/4], sigma_rpy: 0.05}",
                "frames.flange_to_imu.sigma_rpy: a fixed frame has no σ"},
        BadCase{kG, "{id: 0, mode: guess,", "{id: 0.5, mode: guess,",
                "frames.markers[0].id: expected an integer from 0 to 1000000, got '0.5'"},
        BadCase{kG, "{id: 0, mode: guess,", "{id: 2000000, mode: guess,",
                "frames.markers[0].id: expected an integer from 0 to 1000000"},
        BadCase{kU, "    - {id: 2, mode: guess", "    - {id: 1, mode: guess",
                "frames.markers[1].id: marker id 1 twice"},
        BadCase{kU, "markers: [1, 2]", "markers: [1, 2, 3]",
                "sensors.position.markers: marker 3 has no frames.markers entry"},
        BadCase{kU, "markers: [1, 2]", "markers: [1]",
                "frames.markers: marker 2 is not measured by the position sensor"},
        BadCase{kU, "markers: [1, 2]", "markers: [1, 1]",
                "sensors.position.markers[1]: marker id 1 twice"},
        BadCase{kG, "    rate: 100                    # [Hz]\n    axes",
                "    rate: [100]\n    axes",
                "sensors.imu.rate: expected a number [Hz], got a list"},
        BadCase{kG, "    orientation: false", "    orientation: maybe",
                "sensors.position.orientation: expected true or false, got 'maybe'"},
        BadCase{kG, "    earth: ned", "    earth: north", "sensors.imu.earth: expected ned or enu"},
        BadCase{kG, "axes: [x, y, z]", "axes: [y, x, z]", "sensors.imu.axes: a mirror"},
        BadCase{kG, "axes: [x, y, z]", "axes: [x, x, z]", "sensors.imu.axes[1]: axis x used twice"},
        BadCase{kG, "axes: [x, y, z]", "axes: [x, y, w]",
                "sensors.imu.axes[2]: expected x, y or z"},
        BadCase{kG, "axes: [x, y, z]", "axes: [x, y]", "sensors.imu.axes: expected a list of 3"},
        BadCase{kG, "sigma: [5e-4, 5e-4, 5e-4]", "sigma: 5e-4",
                "sensors.position.sigma: expected a list of 3"},
        BadCase{kG, "    orientation: false", "    orientation: false\n    orientation_sigma: 1e-3",
                "sensors.position.orientation_sigma: only with orientation: true"},
        BadCase{kG, "    orientation: false", "    orientation: true\n    orientation_sigma: 1e-3",
                "sensors.position.orientation: a cell has one orientation source"},
        BadCase{kU, "    orientation: false", "    orientation: true",
                "sensors.position.orientation_sigma: missing key"},
        BadCase{kU, "  world_from_base: guess ",
                "  earth_from_world: guess\n  world_from_base: guess ",
                "frames.earth_from_world: there is no IMU"},
        BadCase{kU, "  world_from_base: guess ",
                "  flange_to_imu: guess\n  world_from_base: guess ",
                "frames.flange_to_imu: nothing measures orientation"},
        BadCase{kG, "  gate_after: 10", "  gate_after: 10\n  gate_after: 11",
                "identifier.gate_after: duplicate key"},
        BadCase{kG, "  guess_poses: 6", "  guess_poses: 2",
                "identifier.guess_poses: 2: a guessed frame needs at least 3 poses"},
        BadCase{kG, "  guess_poses: 6", "  guess_poses: 6.5",
                "identifier.guess_poses: expected an integer from 1 to 10000"},
        BadCase{kG, "  guess_poses: 6", "  base_set_seed: -1",
                "identifier.base_set_seed: expected an integer from 0 to 4294967295"},
        BadCase{kG, "identifier:", "channels: {imu: POSITION}\nidentifier:",
                "channels.position: channel 'POSITION' is also channels.imu"},
        BadCase{kG, "identifier:", "channels: {imu: 'IMU DATA'}\nidentifier:",
                "channels.imu: 'IMU DATA' is not a channel name"},
        BadCase{kG, "  id: grb3016-sim", "  id: [1, 2]", "robot.id: expected a text"},
        // units written into values, non-finite values
        BadCase{kG, "    rate: 100                    # [Hz]\n    axes",
                "    rate: 100 Hz\n    axes",
                "sensors.imu.rate: expected a number [Hz], got '100 Hz': numbers carry no units"},
        BadCase{kG, "sigma: [5e-4, 5e-4, 5e-4]", "sigma: [0.5mm, 5e-4, 5e-4]",
                "sensors.position.sigma[0]: expected a number [m], got '0.5mm': numbers carry no "
                "units"},
        BadCase{kG, "    gravity: 9.81", "    gravity: .nan",
                "sensors.imu.gravity: value is not finite"},
        BadCase{kG, "  prior_sigma_angle: 0.05", "  prior_sigma_angle: .inf",
                "identifier.prior_sigma_angle: value is not finite"},
        BadCase{kG, "sigma: [5e-4, 5e-4, 5e-4]", "sigma: [5e-4, nan, 5e-4]",
                "sensors.position.sigma[1]: value is not finite"},
        // absurd values and the likely unit mistake
        BadCase{kG, "    rate: 100                    # [Hz]\n    axes", "    rate: 1e9\n    axes",
                "sensors.imu.rate: 1e+09 Hz is beyond 10000 Hz"},
        BadCase{kG, "    rate: 100                    # [Hz]\n    orientation",
                "    rate: 0\n    orientation", "sensors.position.rate: 0 Hz is below 1 Hz"},
        BadCase{kG, "sigma: [5e-4, 5e-4, 5e-4]", "sigma: [0.05, 0.05, 0.05]",
                "sensors.position.sigma[0]: 0.05 m is beyond 0.01 m: millimetres?"},
        BadCase{kG, "sigma: [5e-4, 5e-4, 5e-4]", "sigma: [5e-4, -5e-4, 5e-4]",
                "sensors.position.sigma[1]: -5e-04 m is below 1e-07 m"},
        BadCase{kG, "  prior_sigma_length: 0.05", "  prior_sigma_length: 5",
                "identifier.prior_sigma_length: 5 m is beyond 1 m: millimetres?"},
        BadCase{kG, "  prior_sigma_angle: 0.05", "  prior_sigma_angle: 2",
                "identifier.prior_sigma_angle: 2 rad is beyond 1 rad: degrees?"},
        BadCase{kG, "  prior_sigma_angle: 0.05", "  prior_sigma_angle: 0",
                "identifier.prior_sigma_angle: 0 rad is not above 0 rad"},
        BadCase{kG, "  gate_after: 10", "  gate_probability: 99.999",
                "identifier.gate_probability: 99.999 is beyond 1: a percentage?"},
        BadCase{kG, "{gyro: 1.7453292519943277e-4,", "{gyro: 1,",
                "sensors.imu.noise_density.gyro: 1 rad/s/√Hz is beyond 0.005 rad/s/√Hz: °/s/√Hz?"},
        BadCase{kG, "{gyro: 1.7453292519943277e-4,", "{gyro: 0.01,",
                "sensors.imu.noise_density.gyro: 0.01 rad/s/√Hz is beyond"},
        BadCase{kG, "accel: 5.886e-4,", "accel: 60,",
                "sensors.imu.noise_density.accel: 60 m/s²/√Hz is beyond 0.05 m/s²/√Hz: µg/√Hz"},
        BadCase{kG, "mag: 2e-8}", "mag: 0.02}",
                "sensors.imu.noise_density.mag: 0.02 T/√Hz is beyond 1e-05 T/√Hz: µT/√Hz"},
        BadCase{kG, "    earth: ned", "    earth: ned\n    range: {accel: 2}",
                "sensors.imu.range.accel: 2 m/s² is below 14.715 m/s²: it would not read gravity: "
                "in g?"},
        BadCase{kG, "    earth: ned", "    earth: ned\n    range: {gyro: 2000}",
                "sensors.imu.range.gyro: 2000 rad/s is beyond 100 rad/s: °/s?"},
        BadCase{kG, "    earth: ned", "    earth: ned\n    range: {mag: 4900}",
                "sensors.imu.range.mag: 4900 T is beyond 0.1 T: µT or gauss?"},
        BadCase{kG, "    gravity: 9.81", "    gravity: 981",
                "sensors.imu.gravity: 981 m/s² is beyond 9.9 m/s²"},
        BadCase{kG, "    gravity: 9.81", "    gravity: 9.81\n    to_marker: [0.01, 0, 1.2]",
                "sensors.imu.to_marker: beyond 1 m from the IMU: millimetres?"},
        BadCase{kG, "    gravity: 9.81", "    gravity: 9.81\n    to_marker: [0.01, .nan, 0]",
                "sensors.imu.to_marker[1]: value is not finite"},
        BadCase{kG, "    gravity: 9.81", "    gravity: 9.81\n    accel_delay: 2.25",
                "sensors.imu.accel_delay: 2.25 s is beyond 0.05 s: ms?"},
        BadCase{kG, "    gravity: 9.81", "    gravity: 9.81\n    accel_delay: -0.001",
                "sensors.imu.accel_delay: -0.001 s is below 0 s"},
        BadCase{kG, "    gravity: 9.81", "    gravity: 9.81\n    to_marker: guess",
                "sensors.imu.to_marker: expected a list of 3 numbers"},
        BadCase{kG, "    gravity: 9.81", "    gravity: 9.81\n    accel_bias: {sigma: 15}",
                "sensors.imu.accel_bias.sigma: 15"},
        BadCase{kG, "    gravity: 9.81", "    gravity: 9.81\n    accel_bias: {random_walk: .nan}",
                "sensors.imu.accel_bias.random_walk"},
        BadCase{kG, "    gravity: 9.81", "    gravity: 9.81\n    accel_bias: {stability: 1e-4}",
                "sensors.imu.accel_bias"},
        BadCase{kG, "    gravity: 9.81", "    gravity: 1",
                "sensors.imu.gravity: 1 m/s² is below 9.7"},
        BadCase{kP, "rpy: [0, 0, -pi/4]", "rpy: [0, 0, -45]",
                "frames.flange_to_imu.rpy[2]: -45 rad is beyond 2π: degrees?"},
        BadCase{kP, "    rpy: [0, 0, pi]", "    rpy: [0, 0, 180]",
                "frames.world_from_base.rpy[2]: 180 rad is beyond 2π: degrees?"},
        BadCase{kP, "xyz: [0, 0.04, 0.05]", "xyz: [0, 40, 50]",
                "frames.markers[0].xyz: 64.03124237432849 m from its origin is beyond 2 m: "
                "millimetres?"},
        BadCase{kP, "    xyz: [1.2, 0.4, 0]", "    xyz: [1200, 400, 0]",
                "frames.world_from_base.xyz[0]: '1200' is beyond 100 m"},
        BadCase{kP, "    sigma_xyz: 0.01 ", "    sigma_xyz: 10 ",
                "frames.world_from_base.sigma_xyz: 10 m is beyond 1 m: millimetres?"},
        BadCase{kP, "    sigma_rpy: 0.02 ", "    sigma_rpy: [0.02, 2, 0.02] ",
                "frames.world_from_base.sigma_rpy[1]: 2 rad is beyond 1 rad: degrees?"},
        BadCase{kP, "  min_duration: 0.5 ", "  min_duration: 500 ",
                "still_window.min_duration: 500 s is beyond 60 s: milliseconds?"},
        BadCase{kP, "  settle_time: 0.2 ", "  joint_rate_threshold: 5 ",
                "still_window.joint_rate_threshold: 5 rad/s is beyond 0.1 rad/s: °/s?"},
        BadCase{kP, "  settle_time: 0.2 ", "  min_window_samples: 0 ",
                "still_window.min_window_samples: expected an integer from 1"},
        BadCase{kP, "  settle_time: 0.2 ", "  rest_from_joints: yes ",
                "still_window.rest_from_joints: expected true or false"},
        // duplicate key, malformed YAML
        BadCase{kG, "  guess_poses: 6", "  guess_poses: 6\n  guess_poses: 7",
                "identifier.guess_poses: duplicate key"},
        BadCase{kG, "schema: rcal.cell/1", "schema: [rcal", "malformed YAML"},
        BadCase{kG, "identifier:", "channels: 5\nidentifier:", "channels: expected a map"},
        // ros2
        BadCase{kG, "  domain: 0", "  domain: 300", "ros2.domain: expected an integer from 0"},
        BadCase{kG, "  imu: /imu/data", "  imu: imu/data",
                "ros2.imu: 'imu/data' is not a ROS 2 topic name"},
        BadCase{kG, "  imu: /imu/data", "  imu: /imu//data", "is not a ROS 2 topic name"},
        BadCase{kG, "  imu: /imu/data\n", "", "ros2.imu: missing key (the cell has an IMU"},
        BadCase{kG, "temperature: /arm/temperature", "temperature: arm temperature",
                "ros2.temperature: 'arm temperature' is not a ROS 2 topic name"},
        BadCase{kG, "payload: /arm/payload", "payload: 5 kg",
                "ros2.payload: '5 kg' is not a ROS 2 topic name"},
        BadCase{kG, "  domain: 0", "  domain: 0\n  topics: x", "ros2.topics: unknown key"},
        BadCase{kG, "type: PointStamped", "type: Point", "ros2.positions[0].type: expected"},
        BadCase{kG, "{marker: 0, topic: /tracker", "{marker: 4, topic: /tracker",
                "ros2.positions[0].marker: marker 4 is not in sensors.position.markers"},
        BadCase{kG, "  max_clock_offset: 0.5 ", "  max_clock_offset: 120 ",
                "ros2.max_clock_offset: 120 s is beyond 10 s: milliseconds?"},
        BadCase{kG, "  clock_offsets: estimate ", "  clock_offsets: guess ",
                "ros2.clock_offsets: expected estimate or none"},
        BadCase{kP, "panda_joint1, panda_joint2", "panda_joint1, panda_joint1",
                "ros2.joint_names[1]: 'panda_joint1' twice"}));

TEST(CellYaml, Ros2SectionNamesTheDriversTopics) {
  const BuiltCell g = LoadCell(CellPath("grb3016.yaml"));
  ASSERT_TRUE(g.spec.ros2);
  const Ros2Spec& r = *g.spec.ros2;
  EXPECT_EQ(r.domain, 0);
  EXPECT_EQ(r.joint_states, "/joint_states");
  EXPECT_EQ(r.imu, "/imu/data");
  EXPECT_EQ(r.magnetic_field, "/imu/mag");
  EXPECT_EQ(r.imu_frame, "imu_link");
  EXPECT_EQ(r.temperature, "/arm/temperature");
  EXPECT_EQ(r.payload, "/arm/payload");
  ASSERT_EQ(r.positions.size(), 1u);
  EXPECT_EQ(r.positions[0].topic, "/tracker/point");
  EXPECT_FALSE(r.positions[0].pose);
  EXPECT_EQ(r.positions[0].frame_id, "tracker");
  EXPECT_TRUE(r.estimate_clock_offsets);
  EXPECT_EQ(r.max_clock_offset, 0.5);
  // No joint_names: the robot file's.
  EXPECT_EQ(g.ros2_joint_names, (std::vector<std::string>{"j1", "j2", "j3", "j4", "j5", "j6"}));

  const BuiltCell p = LoadCell(CellPath("panda.yaml"));
  ASSERT_TRUE(p.spec.ros2);
  EXPECT_TRUE(p.spec.ros2->positions[0].pose);
  EXPECT_EQ(p.ros2_joint_names.size(), 7u);
  EXPECT_EQ(p.ros2_joint_names[6], "panda_joint7");
  EXPECT_EQ(p.model.joints()[6].name, "joint7");  // the model keeps the URDF's names

  // A cell without the section has none; a count that disagrees with the arm is refused.
  EXPECT_FALSE(LoadCell(CellPath("ur10.yaml")).spec.ros2);
  CellSpec bad = LoadCellSpec(CellPath("panda.yaml"));
  bad.ros2->joint_names.pop_back();
  const std::string msg = ErrorOf([&] { BuildCell(bad); });
  EXPECT_NE(msg.find("ros2.joint_names: 6 names, the arm has 7 joints"), std::string::npos) << msg;
}

// The README's annotated example is a valid cell.
TEST(CellYaml, ReadmeExampleParses) {
  const std::string readme = ReadFile(SourceDir() / "README.md");
  const auto section = readme.find("### The cell file");
  ASSERT_NE(section, std::string::npos);
  const auto begin = readme.find("```yaml\n", section);
  ASSERT_NE(begin, std::string::npos);
  const auto end = readme.find("```", begin + 8);
  const CellSpec s = ParseCellYaml(readme.substr(begin + 8, end - begin - 8), "README.md");
  EXPECT_EQ(s.frames.markers.at(0).frame.mode, SetupMode::kFixed);
  EXPECT_EQ(s.position.sigma, Eigen::Vector3d(5e-5, 5e-5, 1e-4));
  ASSERT_TRUE(s.imu);
  EXPECT_EQ(s.imu->R_IS * Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY());
}

TEST(CellYaml, EmptyAndNonMapFilesAreRefused) {
  EXPECT_NE(ErrorOf([] { ParseCellYaml("", "e.yaml"); }).find("e.yaml: empty file"),
            std::string::npos);
  EXPECT_NE(
      ErrorOf([] { ParseCellYaml("- 1\n- 2\n", "l.yaml"); }).find("l.yaml: <top>: expected a map"),
      std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// constraints: (issue 16): where plan-poses may send the arm.

TEST(CellYaml, ConstraintsAreReadInSi) {
  const std::string text = std::string(kMinimalCell) + R"(constraints:
  tool_box: {min: [-1, -1.5, 0.1], max: [1.2, 1.5, 2]}
  min_base_distance: 0.4
  home: {joints: [0, -pi/2, pi/2, 0, 0.5, 0], tolerance: [3, 1, 1, 2, 2, 3]}
  task_region: {min: [0.4, -0.3, 0.2], max: [0.8, 0.3, 0.6]}
)";
  const CellSpec s = ParseCellYaml(text, "c.yaml");
  const auto& c = s.constraints;
  ASSERT_TRUE(c.tool_box && c.task_region);
  EXPECT_EQ(c.tool_box->min, Eigen::Vector3d(-1, -1.5, 0.1));
  EXPECT_EQ(c.tool_box->max, Eigen::Vector3d(1.2, 1.5, 2));
  EXPECT_EQ(c.task_region->max, Eigen::Vector3d(0.8, 0.3, 0.6));
  EXPECT_EQ(c.min_base_distance, 0.4);
  ASSERT_EQ(c.home.size(), 6);
  EXPECT_DOUBLE_EQ(c.home(1), -std::numbers::pi / 2);
  EXPECT_EQ(c.home_tolerance(0), 3.0);
  // One tolerance for all joints; no section: no constraint.
  const CellSpec one =
      ParseCellYaml(std::string(kMinimalCell) +
                        "constraints: {home: {joints: [0, 0, 0, 0, 0, 0], tolerance: 1}}\n",
                    "c.yaml");
  EXPECT_EQ(one.constraints.home_tolerance, Eigen::VectorXd::Ones(6));
  const CellSpec none = ParseCellYaml(kMinimalCell, "c.yaml");
  EXPECT_FALSE(none.constraints.tool_box || none.constraints.task_region);
  EXPECT_EQ(none.constraints.home.size(), 0);
  EXPECT_EQ(none.constraints.min_base_distance, 0.0);
  // NEXT_POSES' channel, renamed like the others.
  EXPECT_EQ(none.channels.next_poses, transport::channels::kNextPoses);
  EXPECT_EQ(ParseCellYaml(std::string(kMinimalCell) + "channels: {next_poses: PLAN_7}\n", "c.yaml")
                .channels.next_poses,
            "PLAN_7");
}

TEST(CellYaml, BadConstraintsNameTheKey) {
  const auto error = [](const std::string& block) {
    return ErrorOf([&] { ParseCellYaml(std::string(kMinimalCell) + block, "c.yaml"); });
  };
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"constraints: {tool_bx: {min: [0, 0, 0], max: [1, 1, 1]}}\n",
       "constraints.tool_bx: unknown key"},
      {"constraints: {tool_box: {min: [0, 0, 0], max: [1, 1, 1], mid: 0}}\n",
       "constraints.tool_box.mid: unknown key"},
      {"constraints: {tool_box: {min: [0, 2, 0], max: [1, 1, 1]}}\n",
       "constraints.tool_box: min[1] 2 m is not below max[1] 1 m"},
      {"constraints: {task_region: {min: [0, 0, 0]}}\n",
       "constraints.task_region.max: missing key"},
      {"constraints: {task_region: {min: [0, 0, 0], max: [1, .nan, 1]}}\n",
       "constraints.task_region.max[1]"},
      {"constraints: {min_base_distance: 300}\n", "constraints.min_base_distance: 300 m is beyond"},
      {"constraints: {min_base_distance: -1}\n", "constraints.min_base_distance: -1 m is below"},
      {"constraints: {home: {joints: [0, 0], tolerance: [1, 1, 1]}}\n",
       "constraints.home.tolerance: 3 tolerances for 2 joints"},
      {"constraints: {home: {joints: [0, 0], tolerance: 0}}\n",
       "constraints.home.tolerance: 0 rad | m is not above 0"},
      {"constraints: {home: {tolerance: 1}}\n", "constraints.home.joints: missing key"},
  };
  for (const auto& [block, expected] : cases) {
    const std::string msg = error(block);
    EXPECT_EQ(msg.rfind("c.yaml: ", 0), 0u) << msg;
    EXPECT_NE(msg.find(expected), std::string::npos) << block << " → " << msg;
  }
}

TEST(CellYaml, HomeWithTheWrongJointCountIsRefusedWhenBuilt) {
  std::string text = ReadFile(CellPath("grb3016.yaml"));
  text += "constraints: {home: {joints: [0, 0, 0], tolerance: 1}}\n";
  CellSpec spec = ParseCellYaml(text, "grb3016.yaml");
  spec.robot.file = CellPath("grb3016.yaml").parent_path() / spec.robot.file;
  const std::string msg = ErrorOf([&] { BuildCell(spec); });
  EXPECT_NE(msg.find("constraints.home.joints: 3 values, the arm has 6 joints"), std::string::npos)
      << msg;
}

}  // namespace
}  // namespace rcal::io
