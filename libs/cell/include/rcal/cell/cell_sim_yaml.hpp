// The simulated counterpart of a cell file (config/cells/*.sim.yaml): the cell file it simulates
// plus the truth only the simulator knows (the seed, the arm's errors, the true set-up frames, the
// sensor switches). The production side (io/cell_yaml.hpp) never reads it.
//
// Schema `rcal.cell_sim/1`. SI units (m, rad, s); errors name the file and the key path as the
// cell file's do (io/cell_yaml.hpp, io/yaml_reader.hpp).
//
//   schema: rcal.cell_sim/1                # required, exactly this
//   cell: grb3016.yaml                     # required: the cell file simulated (relative to this
//                                          #   file)
//   seed: 1                                # required, 0 to 4294967295: seeds every draw (the
//                                          #   random arm errors, the trajectory, the sensors)
//   arm_errors: table3                     # required: none | table3 (the paper's Table 3, D–H
//                                          #   links 1–6: sim::Table3Errors) |
//                                          #   {sigma_length: 5e-4, sigma_angle: 1e-3} [m, rad]
//                                          #   (sim::RandomErrors, seeded by seed·1000 + 4)
//   truth:                                 # required: the true value of every set-up frame the
//                                          #   cell identifies (mode prior or guess); a fixed
//                                          #   frame is simulated at its nominal (no entry)
//     world_from_base: {xyz: [1.6, -0.35, 0.42], rpy: [-0.02, 0.012, 0.61]}   # T_WB [m, rad]
//     earth_from_world: {rpy: [-0.01, 0.017, 0.87]}                            # R_EW [rad]
//     flange_to_imu: {rpy: [-0.02, 0.035, 0.35]}                               # R_FI [rad]
//     markers: [{id: 0, xyz: [0.034, -0.003, 0.122]}]                          # p_FM [m]
//     imu_to_marker: [0.1, -0.05, 0.08]    # optional: r_IM_I, the IMU → first marker lever arm
//                                          #   in the IMU frame [m], |r| ≤ 1 m (default zero: the
//                                          #   IMU at the marker point); the live sources'
//                                          #   (MakeSimProgramme) IMU feels the rigid body's
//                                          #   acceleration at its own point
//   run:                                   # optional, every key optional (defaults: RunSettings)
//     calibration_poses: 50                # still stops used for calibration, 1 to 100000
//     test_poses: 50                       # then test stops, 0 to 100000
//     extra_poses: 0                       # then extra stops (peg-in-hole phase), 0 to 100000
//     still_time: 1.5                      # [s] at each stop, (0, 600]
//     noise_scale: 1                       # multiplies every simulated sensor noise, [0, 100]
//                                          #   (the offline experiment scales its filters' σ too)
//     gyro_bias: false                     # constant + random-walk gyro bias
//     mag_disturbance: false               # 15 µT at 20 % of the stops
//     dropout: 0                           # position samples lost, probability per sample [0, 1)
//
// The rpy of a frame follow the model's convention R = Rz(yaw)·Ry(pitch)·Rx(roll); the truth's
// parameter errors are truth − nominal per coordinate (each angle wrapped to (−π, π]).
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "rcal/cell/sim_cell.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/sim/effects.hpp"
#include "rcal/sim/sensor_sim.hpp"

namespace rcal::cell {

enum class ArmErrorsKind {
  kNone,    ///< the arm is its drawing
  kTable3,  ///< the paper's Table 3 (GRB3016 D–H links 1–6)
  kRandom,  ///< independent Gaussian errors of σ sigma_length [m], sigma_angle [rad]
};

/// A true set-up frame: position [m] (frames with one) and roll-pitch-yaw [rad].
struct TrueFrame {
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  Eigen::Vector3d rpy = Eigen::Vector3d::Zero();
};

struct CellSimSpec {
  std::string source;  ///< the file, for messages
  /// The cell file; LoadCellSimSpec makes a relative path absolute against the sim file's folder.
  std::filesystem::path cell;
  unsigned seed = 1;
  ArmErrorsKind arm_errors = ArmErrorsKind::kNone;
  double sigma_length = 0.0;  ///< [m] (kRandom)
  double sigma_angle = 0.0;   ///< [rad] (kRandom)
  std::optional<TrueFrame> world_from_base, earth_from_world, flange_to_imu;
  std::vector<std::pair<int, Eigen::Vector3d>> markers;       ///< marker id, true p_FM [m]
  Eigen::Vector3d imu_to_marker_I = Eigen::Vector3d::Zero();  ///< true r_IM_I [m]
  // The run; defaults: RunSettings{}.
  int num_cal = 50, num_test = 50, num_extra = 0;
  double still_time = 1.5;   ///< [s]
  double noise_scale = 1.0;  ///< [-]
  bool gyro_bias = false, mag_disturbance = false;
  double dropout = 0.0;  ///< [-]
};

/// Parses YAML text of schema rcal.cell_sim/1 (the cell path kept as written). Throws
/// std::runtime_error "SOURCE: KEY.PATH: what (line N)".
CellSimSpec ParseCellSimYaml(const std::string& text, const std::string& source = "<text>");
/// Reads and parses a sim file; a relative `cell` is resolved against the file's folder.
CellSimSpec LoadCellSimSpec(const std::filesystem::path& path);

/// The true parameter errors of `cell.model` [m | rad]: the arm's errors and, for every set-up
/// parameter, truth − nominal. Throws std::runtime_error naming the sim file and the key when the
/// truth does not fit the cell (a frame the cell identifies without a truth, a truth for a frame
/// the cell fixes or lacks, table3 on an arm without the GRB3016's D–H links).
Eigen::VectorXd TrueErrors(const io::BuiltCell& cell, const CellSimSpec& sim);

/// The simulated cell sim_cell works on (SimulateWindows, RunOnline): cell.model at
/// TrueErrors(cell, sim), its base set for the cell's measurements (full poses with an
/// orientation source, else positions), seeded by sim.seed (MakeCell).
Cell MakeSimCell(const io::BuiltCell& cell, const CellSimSpec& sim);

/// The run's settings: sim's seed, poses, still time and switches; orientation = the cell has an
/// IMU (the pose pipeline's orientation source).
RunSettings SimRunSettings(const io::BuiltCell& cell, const CellSimSpec& sim);

/// The simulated sensors the cell declares (what SimulateWindows builds from SensorSimSettings{}
/// today, for the demo's cell exactly that): the clock at the IMU's rate (the position sensor's
/// without an IMU), the IMU's noise densities (magnetometer in µT, the simulator's unit) and
/// mounting (R_SI = R_ISᵀ), gravity and the earth field in the cell's earth frame (NED:
/// (20, 0, 44) µT, ENU: (0, 20, −44) µT), the position sensor's rate and largest σ (the simulator
/// draws one σ for all axes), each noise × noise_scale, and the run's bias, disturbance and
/// dropout switches (RunSettings' values).
sim::SensorSimSettings SimSensorSettings(const io::BuiltCell& cell, const CellSimSpec& sim);

/// The sensor-level programme of a simulated cell (sensor_acquisition --source sim --level
/// sensors and ros2_sim_drivers play the same one): the cell at its truth (MakeSimCell), a home
/// pose then `num_cal` calibration stops drawn with `num_test` test stops from
/// mt19937_64(seed·1000 + 3), driven to the calibration stops and the first test stop (the last
/// calibration window closes as offline), the sim file's still time at each.
struct SimProgramme {
  Cell cell;
  std::vector<Eigen::VectorXd> stops;  ///< the calibration stops, then the test stops [rad | m]
  sim::ToolMotionTruth truth;          ///< the truth motion along the programme
};
SimProgramme MakeSimProgramme(const io::BuiltCell& cell, const CellSimSpec& sim, unsigned seed,
                              int num_cal, int num_test);

/// The offset step `spec` in the programme's sensor time: the joint reads off from the moment the
/// arm leaves the stop before calibration stop `spec.stop` (the home pose for stop 1), so every
/// window at that stop and after it sees the step and none before. Throws std::invalid_argument
/// when the programme has no such calibration stop.
sim::JointOffsetStep OffsetStepInProgramme(const SimProgramme& programme,
                                           const sim::JointOffsetStepSpec& spec);

/// The arm's conditions in a sensor-level programme, as its simulated controller reports them
/// (sensor_acquisition's ARM_CONDITIONS, ros2_sim_drivers' sensor_msgs/Temperature and
/// geometry_msgs/InertiaStamped): the arm warms as sim::SessionSettings says (+12 K from 20 °C)
/// with time constant `warmup_s`, carries no payload unless SetPayloads gives it one per stop, and
/// the controller reports once per second of sensor time with its sensor's 0.3 K noise.
class SimArmConditions {
 public:
  /// `start_utime` [µs]: the sensor clock at sim time 0; `seed`: the run's (each report's noise is
  /// drawn from its own generator, so a resumed run reports the same and the other streams are
  /// unchanged). Throws std::invalid_argument when warmup_s is not positive.
  SimArmConditions(double warmup_s, int64_t start_utime, unsigned seed);
  /// Where a pick-and-place arm takes on a new payload (SetPayloads).
  enum class PayloadChangeAt {
    /// Halfway through the move to the stop: a pick or place between the measurement stops, where
    /// no still window reaches (a window's end is detected up to about a second into the next
    /// move).
    kMidMove,
    /// At the middle of the stop's still interval: a grasp made at the measurement stop, so that
    /// stop's window was measured under two loads (still_window refuses it).
    kAtStop,
  };
  /// A pick-and-place arm: at each waypoint k ≥ 1 of `trajectory` (the programme's calibration
  /// stops) it holds a payload drawn uniformly from `payloads_kg` [kg] (mt19937_64(seed·1000 + 13);
  /// the home pose too), taken on where `at` says: the true payload blends from the old to the new
  /// over half a second (at most a quarter of the move, or of the still interval) by a quintic
  /// smoothstep, so the tool's motion, and what the IMU feels, stays twice differentiable; the
  /// controller reports the new payload from the blend's start. Call before ApplyEffects (the
  /// effects take the conditions as they are then). Throws std::invalid_argument on an empty list
  /// or a payload that is not finite or outside [0, 1000] kg.
  void SetPayloads(const sim::JointTrajectory& trajectory, const std::vector<double>& payloads_kg,
                   PayloadChangeAt at = PayloadChangeAt::kMidMove);
  /// The true conditions at sim time `t_sim` [s]: time_s on the sensor clock, the temperature
  /// [°C], the payload [kg] (SetPayloads; 0 without).
  kinematics::EffectContext At(double t_sim) const;
  /// The temperature [°C] the controller reports at `t_sim`; `tick`: the report's key (the sample
  /// index at the sensors' rate: its noise's seed).
  double Reported(double t_sim, int64_t tick) const;
  /// The payload [kg] the controller reports at `t_sim`: the one it was told to carry (a step
  /// where the true payload starts to blend; At).
  double ReportedPayload(double t_sim) const;
  /// The sim times [s] at which ReportedPayload steps (a pick or place reported as it is made),
  /// ascending; none without SetPayloads.
  std::vector<double> PayloadReportTimes() const;
  /// The payload [kg] held at waypoint k of SetPayloads' trajectory (0 without); with kAtStop,
  /// the one taken on at k (held from the middle of its still interval on).
  double PayloadAt(int waypoint) const;
  /// `--sim-effect` texts (sim::ParseEffectSpec) on the programme's truth: the arm grows with its
  /// true temperature (or time), its joints give way under gravity and the payload
  /// (joint_compliance), turn off their readings periodically (joint_periodic: a gear error) or by
  /// a scale (joint_scale), or stand off them by their backlash in the direction they came in
  /// (sim::ToolMotionTruth::set_backlash). Throws std::invalid_argument for a text ParseEffectSpec
  /// refuses. Returns one line per effect for the log.
  std::vector<std::string> ApplyEffects(const std::vector<std::string>& texts,
                                        SimProgramme& programme) const;
  /// The same effects on each of `truths` (non-null), each the motion of its own marker (a
  /// tracker per marker: ros2_sim_drivers), all of one arm: every marker grows with it.
  std::vector<std::string> ApplyEffects(const std::vector<std::string>& texts,
                                        const std::vector<sim::ToolMotionTruth*>& truths) const;
  const sim::SessionSettings& session() const { return session_; }

 private:
  // One payload change: from `from` to `to` [kg], blending over [t_start, t_end] [s of sim time].
  struct PayloadChange {
    double t_start, t_end, from, to;
  };
  sim::SessionSettings session_;
  double t0_s_;
  unsigned seed_;
  std::vector<double> waypoint_payloads_kg_;    // SetPayloads: per waypoint
  std::vector<PayloadChange> payload_changes_;  // ascending in time
};

}  // namespace rcal::cell
