// The cell file: one user's calibration cell (config/cells/*.yaml), what every process and `rcal`
// command is given with --cell FILE.
//
// Schema `rcal.cell/1`. SI units only: m, rad, s, Hz, T, m/s². Numbers are plain (a value
// carrying a unit, "100 Hz", "5 mm", is refused); angles may be written as multiples of π
// (`pi/2`, robot_yaml.hpp). Unknown keys, missing required keys, wrong types, non-finite values
// and implausible values are errors naming the file and the key path, e.g.
//   `grb3016.yaml: sensors.position.sigma[0]: 0.05 m is beyond 0.01 m: millimetres? (write
//   metres: 0.05 mm = 5e-5) (line 33)`.
// Paths inside the file are relative to the file's folder (LoadCellSpec).
//
//   schema: rcal.cell/1                    # required, exactly this
//   name: grb3016_demo                     # required: the cell's id in reports and topics,
//                                          # [A-Za-z][A-Za-z0-9_-]*, at most 64 characters
//   robot:                                 # required
//     file: ../robots/grb3016.yaml         # required: rcal.robot/1 YAML (.yaml, .yml) or .urdf
//     base_link: base_link                 # URDF only, optional (default: the URDF's root link)
//     tip_link: wrist_3_link               # URDF only, optional (default: robot_urdf.hpp)
//     id: "GRB3016 SN 1234"                # optional: the robot's own id or serial (text)
//   frames:                                # required: the set-up frames, identified with the arm
//     world_from_base: guess               # required: T_WB, world (the position sensor's frame)
//                                          #   ← robot base
//     earth_from_world: guess              # with an IMU (required), else refused: R_EW, the IMU's
//                                          #   earth frame (NED/ENU, magnetic north) ← world
//     flange_to_imu: {mode: prior, rpy: [0, 0, pi/2], sigma_rpy: 0.05}
//                                          # with an orientation source (required), else refused:
//                                          #   R_FI, flange (tip link) → IMU (or the tracker's
//                                          #   measured body when the tracker gives orientation)
//     markers:                             # required, 1 to 100, ids distinct: p_FM, flange →
//     marker
//       - {id: 0, mode: guess, xyz: [0.03, 0, 0.12]}
//   # A frame is `guess` (short for {mode: guess}) or a map:
//   #   mode: fixed | prior | guess        required
//   #     fixed: known, not identified     prior: value ± σ, identified
//   #     guess: guessed from the first poses (identification::GuessSetup), then identified
//   #   xyz: [x, y, z]                     [m] nominal p (world_from_base, markers); required
//   #                                      with fixed and prior, optional with guess (default 0:
//   #                                      the guess keeps what the poses do not show)
//   #   rpy: [roll, pitch, yaw]            [rad] nominal R = Rz(yaw)·Ry(pitch)·Rx(roll) (all but
//   #                                      markers); required/optional as xyz
//   #   sigma_xyz: σ | [σx, σy, σz]         [m] prior: required; guess: optional σ of the start
//   #                                      (default identifier.prior_sigma_length); fixed: refused
//   #   sigma_rpy: σ | [σr, σp, σy]         [rad] as sigma_xyz (default prior_sigma_angle)
//   #   markers[i].id                      required, integer 0 to 1000000 (the datasets' marker)
//   sensors:                               # required
//     imu:                                 # optional; absent: no IMU
//       id: "MTi-100 03301234"             # optional (text)
//       rate: 100                          # required [Hz], 1 to 10000
//       axes: [x, y, z]                    # optional (default [x, y, z]): the mounting frame's
//                                          #   x, y, z axes as signed sensor axes, e.g. [-y, x, z]
//                                          #   (a right-handed signed permutation)
//       noise_density: {gyro: 1.745e-4, accel: 5.886e-4, mag: 2e-8}
//                                          # required [rad/s/√Hz, m/s²/√Hz, T/√Hz]
//       range: {gyro: 7.85, accel: 200, mag: 8e-5}    # optional [rad/s, m/s², T] (full scale)
//       accel_bias: {sigma: 1.5e-4, random_walk: 0}  # optional [m/s², m/s²/√s] (datasheet:
//                                          #   bias stability, bias random walk); the still
//                                          #   windows' orientation covariance carries the bias
//                                          #   (PosePipelineSettings::accel_bias_*); absent: 0
//       earth: ned                         # required: ned | enu (the earth frame of R_EW)
//       gravity: 9.81                      # optional [m/s²], local gravity, 9.7 to 9.9
//       to_marker: [0.01, 0, 0.02]         # optional [m]: the lever arm r_IM_I from the IMU to
//                                          #   the first marker, in the mounting frame (|r| ≤ 1 m),
//                                          #   or `estimate` (position_kf estimates it); absent:
//                                          #   zero, the IMU taken at the marker (the paper's)
//       accel_delay: 0.00225               # optional [s], 0 to 0.05: the accelerometer's lag
//                                          #   behind its stamps (rcal fuse measures it from a
//                                          #   recording: accel_lag); position_kf takes it out;
//                                          #   absent: 0, samples taken as stamped
//     position:                            # required: the position sensor (tracker, camera)
//       id: "AT960 123"                    # optional (text)
//       markers: [0]                       # required: the marker ids it measures, exactly the
//                                          #   ids of frames.markers
//       sigma: [5e-4, 5e-4, 5e-4]          # required [m] per axis of its own frame
//       rate: 100                          # required [Hz], 1 to 10000
//       orientation: false                 # optional: true for a 6-DoF tracker (then there may
//                                          #   be no IMU: a cell has one orientation source)
//       orientation_sigma: 1e-4            # [rad] per axis, required iff orientation: true
//   still_window:                          # optional, every key optional (defaults: CellSpec)
//     joint_rate_threshold: 1e-3           # [rad/s] still while every joint moves slower
//     gyro_threshold: 0.02                 # [rad/s] IMU still test (no joints)
//     accel_threshold: 0.3                 # [m/s²] IMU still test: ||f| − g|
//     min_duration: 0.5                    # [s] of stillness before a window opens
//     settle_time: 0.2                     # [s] skipped after that
//     min_window_samples: 20               # IMU samples a window needs
//     min_raw_samples: 10                  # raw samples for the scatter covariance
//     max_gap: 0.2                         # [s] largest IMU gap inside a window
//     rest_from_joints: true               # filters start at the first stop, whose window is
//                                          #   dropped (estimation::PosePipelineSettings)
//     warmup: 0                            # [s] windows beginning this soon after the first
//                                          #   sample are dropped (still_window --warmup)
//   identifier:                            # optional, every key optional
//     prior_sigma_length: 0.01             # [m] σ of each length error of the arm
//     prior_sigma_angle: 0.035             # [rad] σ of each angle error of the arm
//     drift_sigma_length: 0                # [m per pose] random walk (0: constant)
//     drift_sigma_angle: 0                 # [rad per pose]
//     gate_probability: 0.99999            # χ² gate on the innovation, 0.5 to 1 (1: no gate)
//     gate_after: 0                        # poses accepted before the gate arms
//     guess_poses: 6                       # poses held back for the set-up guess (≥ 3 with a
//                                          #   guessed frame)
//     base_set_seed: 1                     # seed of the joint sample choosing the base set
//     joint_margin: 0.1                    # [rad | m] joints beyond the limits by more: refused
//   channels:                              # optional: LCM channel names (defaults: CellChannels)
//     imu: IMU                             # and position, joints, orientation, tool_position,
//                                          # ins_orientation, ins_tool_position,
//                                          # pose_measurement, kinematic_params,
//                                          # calibration_status, ik_request, ik_command, health,
//                                          # supervisor_state, clock_offset, next_poses,
//                                          # model_discrepancy, arm_conditions;
//                                          # distinct, [A-Za-z0-9_./-], ≤ 63
//   ros2:                                  # optional: the cell's ROS 2 drivers, read by ros2_input
//                                          #   over DDS (ROS 2 wire types, no ROS installation)
//     domain: 0                            # DDS domain (ROS_DOMAIN_ID), 0 to 232
//     joint_states: /joint_states          # sensor_msgs/JointState topic (default /joint_states)
//     joint_names: [j1, j2, ...]           # optional: the arm's joints as the driver names them,
//                                          #   chain order (default: the robot file's names);
//                                          #   rows are mapped by name, never by order
//     imu: /imu/data                       # sensor_msgs/Imu, required iff sensors.imu
//     magnetic_field: /imu/mag             # optional sensor_msgs/MagneticField (same clock)
//     imu_frame: imu_link                  # optional: the header.frame_id IMU messages must carry
//     temperature: /arm/temperature        # optional sensor_msgs/Temperature of the arm [°C]
//                                          #   -> ARM_CONDITIONS (the poses' temperature)
//     payload: /arm/payload                # optional geometry_msgs/InertiaStamped of what the
//                                          #   arm carries (its m [kg]) -> ARM_CONDITIONS
//     positions:                           # required: one per sensors.position.markers id
//       - {marker: 0, topic: /tracker/point, type: PointStamped, frame: tracker}
//                                          # type PointStamped (laser tracker) | PoseStamped
//                                          #   (motion capture); frame optional, as imu_frame
//     clock_offsets: estimate              # estimate (each source's clock against the joints') |
//                                          #   none (the drivers share one clock)
//     max_clock_offset: 0.5                # [s] the largest offset searched, 0.01 to 10
//     frame_prefix: rcal_                  # optional: TF frame names (rcal_world, rcal_base, ...)
//   constraints:                           # optional: where `rcal plan-poses` and NEXT_POSES may
//                                          #   send the arm (identification::PoseConstraints);
//                                          #   positions in the robot's base frame [m]
//     tool_box: {min: [x, y, z], max: [x, y, z]}   # the marker stays inside; min < max
//     min_base_distance: 0.3               # [m] marker at least this far from the base origin
//     home: {joints: [0, -pi/2, ...], tolerance: 1.0}   # [rad | m] one per joint (checked by
//                                          #   BuildCell); tolerance: one or one per joint, > 0
//     task_region: {min: [...], max: [...]}   # where accuracy matters (plan-poses
//                                          #   --task-weighting, NEXT_POSES)
//
// Plausibility (the likely unit mistake is named): frame positions within 100 m, marker offsets
// within 2 m of the flange; angles within 2π ("degrees?"); σ of a length above 1 m (frames) or
// 1 cm (position sensor) ("millimetres?"), of an angle above 1 rad ("degrees?"); noise densities
// above 5e-3 rad/s/√Hz (gyro: °/s?), 0.05 m/s²/√Hz (accel: µg or mg?), 1e-5 T/√Hz (mag: µT?);
// ranges: gyro 0.5 to 100 rad/s, accel above gravity to 2000 m/s², mag 65 µT to 0.1 T.
//
// The robot file gives the arm only: its own set-up entries (base, marker(s), imu, earth), if
// any, are replaced by the cell's frames.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "rcal/estimation/fqa.hpp"
#include "rcal/estimation/pose_pipeline.hpp"
#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/identification/pose_planning.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::io {

/// How a set-up frame starts and whether it is identified.
enum class SetupMode {
  kFixed,  ///< known: its nominal value, not identified (no parameters in the model)
  kPrior,  ///< known to ± σ: starts at the nominal with that σ, identified
  kGuess,  ///< unknown: guessed from the first poses, then identified
};

/// One set-up frame of the cell. Translations [m], roll-pitch-yaw [rad] with
/// R = Rz(yaw)·Ry(pitch)·Rx(roll) (the model's segment ETs, kinematics::ModelBuilder).
struct SetupFrameSpec {
  SetupMode mode = SetupMode::kGuess;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();  ///< nominal position [m] (frames with one)
  Eigen::Vector3d rpy = Eigen::Vector3d::Zero();  ///< nominal rotation [rad] (frames with one)
  /// σ per axis [m] / per angle (roll, pitch, yaw) [rad]: required with kPrior; optional with
  /// kGuess (the identifier's prior_sigma_* when absent); never with kFixed.
  std::optional<Eigen::Vector3d> sigma_xyz, sigma_rpy;
};

/// A marker (measured point on the tool): its id and flange → marker offset p_FM (xyz only).
struct CellMarkerSpec {
  int id = 0;  ///< the pose datasets' `marker` id, 0 to 1e6
  SetupFrameSpec frame;
};

struct CellRobotSpec {
  /// The robot file (rcal.robot/1 YAML or URDF). LoadCellSpec makes a relative path absolute
  /// against the cell file's folder; ParseCellYaml keeps it as written.
  std::filesystem::path file;
  std::string base_link, tip_link;  ///< URDF chain ends (empty: robot_urdf.hpp defaults)
  std::string id;                   ///< the robot's own id or serial (informational)
};

/// The cell's set-up frames (`frames:`).
struct CellFramesSpec {
  SetupFrameSpec world_from_base;                  ///< T_WB: world (position sensor) ← base
  std::optional<SetupFrameSpec> earth_from_world;  ///< R_EW: earth (IMU's NED/ENU) ← world
  std::optional<SetupFrameSpec> flange_to_imu;     ///< R_FI: flange → IMU (or tracked body)
  std::vector<CellMarkerSpec> markers;             ///< p_FM per marker id, ≥ 1
};

struct ImuSensorSpec {
  std::string id;       ///< the sensor's id (informational)
  double rate = 100.0;  ///< sample rate [Hz]
  /// Mounting frame ← sensor axes (v_I = R_IS · v_S), a right-handed signed permutation, from
  /// `axes`: row i is the signed sensor axis named by axes[i].
  Eigen::Matrix3d R_IS = Eigen::Matrix3d::Identity();
  double gyro_noise_density = 0.0;   ///< [rad/s/√Hz]
  double accel_noise_density = 0.0;  ///< [m/s²/√Hz]
  double mag_noise_density = 0.0;    ///< [T/√Hz]
  /// Full-scale ranges; defaults: transport::SensorRanges (what every process refuses beyond).
  double gyro_range = 40.0;             ///< [rad/s]
  double accel_range = 320.0;           ///< [m/s²]
  double mag_range = 5e-3;              ///< [T]
  double accel_bias_sigma = 0.0;        ///< accelerometer bias σ per axis [m/s²]
  double accel_bias_random_walk = 0.0;  ///< accelerometer bias random walk [m/s²/√s]
  estimation::EarthFrame earth = estimation::EarthFrame::kNed;  ///< the earth frame of R_EW
  double gravity = 9.81;                                        ///< local gravity magnitude [m/s²]
  /// IMU → first marker r_IM_I in the mounting frame [m] (zero: the IMU taken at the marker).
  Eigen::Vector3d to_marker_I = Eigen::Vector3d::Zero();
  bool estimate_to_marker = false;  ///< `to_marker: estimate`: the position filter estimates it
  /// The accelerometer's lag behind its stamps [s] (estimation::PositionKfSettings::accel_delay).
  double accel_delay = 0.0;
};

struct PositionSensorSpec {
  std::string id;                                   ///< the sensor's id (informational)
  std::vector<int> markers;                         ///< the marker ids it measures
  Eigen::Vector3d sigma = Eigen::Vector3d::Zero();  ///< white noise per axis [m]
  double rate = 0.0;                                ///< output rate [Hz]
  bool orientation = false;                         ///< a 6-DoF tracker: measures orientation
  double orientation_sigma = 0.0;                   ///< [rad] per axis (orientation only)
};

/// The still-window settings a user tunes (`still_window:`). Defaults: today's
/// estimation::PosePipelineSettings / StillDetectorSettings and still_window's --warmup.
struct StillWindowSpec {
  double joint_rate_threshold = 1e-3;  ///< [rad/s]
  double gyro_threshold = 0.02;        ///< [rad/s]
  double accel_threshold = 0.3;        ///< [m/s²]
  double min_duration = 0.5;           ///< [s]
  double settle_time = 0.2;            ///< [s]
  int min_window_samples = 20;         ///< [-]
  int min_raw_samples = 10;            ///< [-]
  double max_gap = 0.2;                ///< [s]
  bool rest_from_joints = true;
  double warmup = 0.0;  ///< [s] (a process option today: still_window --warmup)
};

/// The identifier settings (`identifier:`). Defaults: today's identification::EkfSettings and
/// the ekf_identifier process's options.
struct IdentifierSpec {
  double prior_sigma_length = 0.01;   ///< [m]
  double prior_sigma_angle = 0.035;   ///< [rad]
  double drift_sigma_length = 0.0;    ///< [m per pose]
  double drift_sigma_angle = 0.0;     ///< [rad per pose]
  double gate_probability = 0.99999;  ///< [-]; 1: no gate
  int gate_after = 0;                 ///< [poses]
  int guess_poses = 6;                ///< [poses]
  unsigned base_set_seed = 1;         ///< ekf_identifier --ident-seed
  double joint_margin = 0.1;          ///< [rad | m]
};

/// LCM channel names (`channels:`). Defaults: services/transport's channels table.
struct CellChannels {
  std::string imu = "IMU", position = "POSITION", joints = "JOINTS";
  std::string orientation = "ORIENTATION", tool_position = "TOOL_POSITION";
  /// The tracker-aided INS's attitude and marker (aided_ins).
  std::string ins_orientation = "INS_ORIENTATION", ins_tool_position = "INS_TOOL_POSITION";
  std::string pose_measurement = "POSE_MEASUREMENT", kinematic_params = "KINEMATIC_PARAMS";
  std::string calibration_status = "CALIBRATION_STATUS";
  std::string ik_request = "IK_REQUEST", ik_command = "IK_COMMAND";
  std::string health = "HEALTH", supervisor_state = "SUPERVISOR_STATE";
  std::string clock_offset = "CLOCK_OFFSET";
  std::string next_poses = "NEXT_POSES";                ///< next_poses_t (issue 16)
  std::string model_discrepancy = "MODEL_DISCREPANCY";  ///< model_discrepancy_t (issue 15)
  std::string arm_conditions = "ARM_CONDITIONS";        ///< arm_conditions_t (issue 15)
};

/// One marker's ROS 2 topic (`ros2.positions[i]`).
struct Ros2PositionTopic {
  int marker = 0;        ///< the marker id it measures (sensors.position.markers)
  std::string topic;     ///< ROS 2 topic name, e.g. /tracker/point (DDS topic rt/tracker/point)
  bool pose = false;     ///< true: geometry_msgs/PoseStamped; false: geometry_msgs/PointStamped
  std::string frame_id;  ///< header.frame_id the messages must carry (empty: any)
};

/// The cell's ROS 2 drivers (`ros2:`): what ros2_input subscribes and how it reads it.
struct Ros2Spec {
  int domain = 0;  ///< DDS domain id (ROS_DOMAIN_ID)
  std::string joint_states = "/joint_states";
  std::vector<std::string> joint_names;  ///< chain order; empty: the robot file's names
  std::string imu, magnetic_field;       ///< topics (empty: none)
  std::string imu_frame;                 ///< required header.frame_id of IMU messages (empty: any)
  /// sensor_msgs/Temperature of the arm (its controller's, or a sensor on it) → ARM_CONDITIONS,
  /// the poses' temperature (empty: none).
  std::string temperature;
  /// geometry_msgs/InertiaStamped of what the arm carries (its mass m [kg]) → ARM_CONDITIONS, the
  /// poses' payload (empty: none).
  std::string payload;
  std::vector<Ros2PositionTopic> positions;  ///< one per measured marker
  bool estimate_clock_offsets = true;        ///< false: the drivers share the joints' clock
  double max_clock_offset = 0.5;             ///< [s] largest offset searched
  std::string frame_prefix = "rcal_";        ///< TF frame names: <prefix>world, <prefix>base, ...
};

/// Everything a cell file says.
struct CellSpec {
  std::string source;  ///< the file (or the `source` given to ParseCellYaml), for messages
  std::string name;
  CellRobotSpec robot;
  CellFramesSpec frames;
  std::optional<ImuSensorSpec> imu;  ///< absent: no IMU
  PositionSensorSpec position;
  StillWindowSpec still_window;
  IdentifierSpec identifier;
  CellChannels channels;
  std::optional<Ros2Spec> ros2;  ///< absent: no ROS 2 drivers
  /// `constraints:` (issue 16); default: none. home is checked against the arm by BuildCell.
  identification::PoseConstraints constraints;

  /// Where measured orientations come from: the IMU, the tracker (position.orientation), or
  /// nowhere (positions only).
  bool measures_orientation() const { return imu.has_value() || position.orientation; }
};

/// Parses YAML text of schema rcal.cell/1. `source` names the file in error messages; the robot
/// file path is kept as written. Throws std::runtime_error "SOURCE: KEY.PATH: what (line N)".
CellSpec ParseCellYaml(const std::string& text, const std::string& source = "<text>");
/// Reads and parses a cell file; a relative robot.file is resolved against the file's folder.
CellSpec LoadCellSpec(const std::filesystem::path& path);

/// Where a model parameter's prior comes from.
enum class PriorKind {
  kArm,    ///< the arm's own geometry: identifier.prior_sigma_length / _angle
  kSetup,  ///< a set-up frame of mode prior: its sigma_xyz / sigma_rpy
  kGuess,  ///< a set-up frame of mode guess: start from GuessSetup, this σ around it
};

struct ParameterPrior {
  PriorKind kind = PriorKind::kArm;
  double sigma = 0.0;  ///< prior σ around the start [m | rad]
  std::string key;     ///< the cell file's key that set it, e.g. "frames.markers[1].sigma_xyz"
};

/// What the pipeline needs of a cell.
struct BuiltCell {
  CellSpec spec;
  LoadedRobot robot;  ///< the robot file as loaded (its own set-up entries, if any, untouched)
  /// The arm (robot.spec) with the cell's set-up frames: base = world ← base, markers (one per
  /// id, in the order of frames.markers), imu = flange → IMU, earth = earth ← world; a fixed
  /// frame has identify: false.
  RobotSpec robot_spec;
  kinematics::KinematicModel model;  ///< BuildModel(robot_spec); its nominal is the start
  /// One per model parameter (model.parameters() order).
  std::vector<ParameterPrior> prior;
  /// The pose pipeline of still_window: PosePipelineSettings{} with still_window's values, the
  /// IMU's gyro noise density, earth frame, gravity and gyro/accel ranges, the position sensor's
  /// largest σ, and use_orientation = an IMU is present (the pipeline's orientation is the IMU's;
  /// a tracker's orientation does not enter it yet).
  estimation::PosePipelineSettings pipeline;
  /// EkfSettings{} with identifier's prior σ, drift, gate_probability and gate_after.
  identification::EkfSettings ekf;
  /// The arm's joint names as the ROS 2 driver publishes them, chain order: ros2.joint_names, else
  /// the model's joint names (one per model joint; BuildCell checks the count).
  std::vector<std::string> ros2_joint_names;

  /// prior[i].sigma for every parameter [m | rad].
  Eigen::VectorXd PriorSigma() const;
  /// Indices of the parameters started from the set-up guess (PriorKind::kGuess), ascending.
  std::vector<int> Guessed() const;
};

/// Loads the robot file (io::LoadRobot with the cell's base and tip links), adds the set-up
/// frames and builds the model, the priors and the settings. Throws std::runtime_error naming the
/// cell file and the key (a robot file's own errors name that file).
BuiltCell BuildCell(const CellSpec& spec);
/// BuildCell(LoadCellSpec(path)).
BuiltCell LoadCell(const std::filesystem::path& path);

}  // namespace rcal::io
