// Sensor-level simulation: the truth motion of the tool along a JointTrajectory, and the sensor
// streams a cell records while the arm moves (joints, IMU, position sensor), sampled on one clock.
//
// Truth (model at errors x_true, set-up frames included in x_true):
//   p_WM_W(t) = model.Forward(q(t), x_true).p_WM_W        marker position, world [m]
//   R_EI(t)   = model.Forward(q(t), x_true).R_EI          IMU orientation, imu → earth
//   v_WM_W, a_WM_W: central differences of p_WM_W along the analytic q(t) (step h):
//     v ≈ (p(t+h) − p(t−h)) / 2h,   a ≈ (p(t+h) − 2p(t) + p(t−h)) / h²       [m/s, m/s²]
//   ω_I ≈ Log(R_EI(t−h)ᵀ R_EI(t+h)) / 2h    angular rate in the IMU frame [rad/s]
// Both are O(h²) accurate; q(t) is a quintic, so h = 1 ms gives errors far below sensor noise.
// The IMU sits at p_WI_W = p_WM_W − R_WI r_IM_I, r_IM_I the IMU → marker lever arm in the IMU
// frame (set_imu_to_marker_I; default zero: the IMU at the marker point), R_WI = R_EWᵀ R_EI; its
// acceleration a_WI_W is the central second difference of p_WI_W like the marker's (for r = 0
// exactly a_WM_W), and in the earth frame a_E = R_EW a_WI_W (gravity not included; ImuModel adds
// it). ImuModel's W is this earth frame E (NED).
//
// Streams, all at the clock rate (default 100 Hz), sample k at t_k = k / rate:
//   joints  q(t_k) as read (optionally quantised to the encoder resolution)
//   IMU     ImuModel(ImuTruth{t_k, R_EI, ω_I, a_E, p_E}) (+ optional magnetic disturbance)
//   position PositionSensorModel(t_k, p_WM_W) (its frame M = world W by default)
// Magnetic disturbance (optional): at a seeded random fraction of the still stops, a constant
// field d_E [µT] (random direction, fixed magnitude) is added in the earth frame for the whole
// stop, as a ferrous object near that pose would: m_S += R_SI R_EIᵀ d_E.
// Every draw is seeded: the same settings and seed give the same streams.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <random>
#include <vector>

#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/model.hpp"
#include "rcal/sim/imu_model.hpp"
#include "rcal/sim/position_sensor_model.hpp"
#include "rcal/sim/trajectory.hpp"

namespace rcal::sim {

/// The truth state of the tool at one time.
struct ToolState {
  double t = 0.0;                                      ///< [s]
  Eigen::VectorXd q;                                   ///< joints [rad | m]
  Eigen::Vector3d p_WM_W = Eigen::Vector3d::Zero();    ///< marker position, world [m]
  Eigen::Vector3d v_WM_W = Eigen::Vector3d::Zero();    ///< marker velocity, world [m/s]
  Eigen::Vector3d a_WM_W = Eigen::Vector3d::Zero();    ///< marker acceleration, world [m/s²]
  Eigen::Matrix3d R_EI = Eigen::Matrix3d::Identity();  ///< IMU → earth
  Eigen::Vector3d omega_I = Eigen::Vector3d::Zero();   ///< IMU angular rate, IMU frame [rad/s]
  Eigen::Vector3d p_WI_W = Eigen::Vector3d::Zero();    ///< IMU position, world [m]
  Eigen::Vector3d a_WI_W = Eigen::Vector3d::Zero();    ///< IMU acceleration, world [m/s²]
};

/// Truth motion of the marker/IMU for a truth model (model, x_true) along a trajectory.
class ToolMotionTruth {
 public:
  /// `fd_step` h [s] of the central differences. Keeps copies of model, x_true and trajectory.
  ToolMotionTruth(const kinematics::KinematicModel& model, const Eigen::VectorXd& x_true,
                  JointTrajectory trajectory, double fd_step = 1e-3);
  /// The truth state at t [s] (clamped to the trajectory's span, where the arm stands still).
  ToolState At(double t) const;
  /// The IMU truth (ImuModel's W = earth E): R_WI = R_EI, a_W = R_EW a_WI_W, p_W = R_EW p_WI_W,
  /// ω_I the rate at the instant s.t (ToolState::omega_I).
  ImuTruth Imu(const ToolState& s) const;
  /// The same with ω_I the mean rate over the sample interval (s.t − interval_s, s.t]:
  /// Log(R_EI(s.t − interval_s)ᵀ R_EI(s.t)) / interval_s, what a gyro sampled every interval_s
  /// [s] reports (ImuTruth::omega_I). SensorSim samples its IMU this way.
  ImuTruth Imu(const ToolState& s, double interval_s) const;
  /// The IMU → marker lever arm r_IM_I in the IMU frame [m] (the first marker; zero: the IMU at
  /// the marker point).
  void set_imu_to_marker_I(const Eigen::Vector3d& r_IM_I) { r_IM_I_ = r_IM_I; }
  const Eigen::Vector3d& imu_to_marker_I() const { return r_IM_I_; }
  /// Non-geometric effects of the truth arm (issue 15: a sensor-level cell whose arm grows with
  /// its temperature): from now on the tool moves as `model.Forward(q, context(t), x_true, e)`
  /// (kinematics::ExtendedModel) instead of the geometry alone, `context(t)` the conditions at
  /// sensor time t [s]. The context must be smooth in t (a warming temperature, the time): the
  /// IMU's truth is its second difference. `model` must extend this truth's model (same
  /// parameters); throws std::invalid_argument otherwise or without a context.
  using ContextAt = std::function<kinematics::EffectContext(double t_s)>;
  void set_effects(kinematics::ExtendedModel model, Eigen::VectorXd e, ContextAt context);
  /// Backlash of the truth arm's joints (b [rad | m] per joint, 0: none; empty: no backlash), as
  /// kinematics::ExtendedModel defines it: at a stop each joint stands b_j·s_j off its reading,
  /// s_j the sign of its net move from the stop before (what still_window publishes as the pose's
  /// approach direction; 0 at the first stop and for a joint that did not move). Where a move
  /// reverses a joint's direction, its gear crosses the dead band while the motor turns the first
  /// 2|b_j| of the move: the offset blends from b_j·s_old to b_j·s_new over that travel by a
  /// quintic smoothstep (the output nearly stands while the motor takes up the play), so the
  /// tool's motion, and what the IMU feels, stays twice differentiable; the jolt is the
  /// smoothstep's. Read from the trajectory as it is when evaluated (a retargeted stop too).
  /// Throws std::invalid_argument for a size other than the joints' or a value not finite.
  void set_backlash(Eigen::VectorXd b);
  /// The backlash offset of the joints [rad | m] at sensor time t when they read q (zero without).
  Eigen::VectorXd BacklashOffset(const Eigen::VectorXd& q, double t) const;
  /// Earth ← world rotation of the truth set-up (the model's earth segment at x_true).
  const Eigen::Matrix3d& R_EW() const { return R_EW_; }
  const JointTrajectory& trajectory() const { return trajectory_; }
  /// JointTrajectory::Retarget on the truth's programme: the arm goes to q [rad | m] at stop k
  /// instead (a cell that picks its next stop while it works). A SensorSim reading this truth
  /// follows it from its next tick.
  void Retarget(int k, const Eigen::VectorXd& q) { trajectory_.Retarget(k, q); }
  const kinematics::KinematicModel& model() const { return model_; }
  const Eigen::VectorXd& x_true() const { return x_true_; }

 private:
  kinematics::KinematicModel model_;
  Eigen::VectorXd x_true_;
  JointTrajectory trajectory_;
  double h_;
  Eigen::Matrix3d R_EW_;
  Eigen::Vector3d r_IM_I_ = Eigen::Vector3d::Zero();
  struct Effects {
    kinematics::ExtendedModel model;
    Eigen::VectorXd e;
    ContextAt context;
  };
  std::shared_ptr<const Effects> effects_;  // null: the geometry alone
  Eigen::VectorXd backlash_;                // per joint [rad | m]; empty: none
  kinematics::ToolPose Pose(const Eigen::VectorXd& q, double t) const;
};

/// An encoder swapped and re-mastered (or slipped in a collision) while the arm works: from sensor
/// time t_s on, joint `joint` reads `delta` less than where it stands, so the model's offset of
/// that joint (θ_j of a D–H arm) grows by `delta`. The arm's motion is unchanged; only its
/// readings move, as on a real arm.
struct JointOffsetStep {
  double t_s = 0.0;    ///< [s] sensor time from which the reading is off
  int joint = 0;       ///< 0-based
  double delta = 0.0;  ///< [rad | m] the offset's step (the reading is this much less)
};
/// The joints as read at sensor time t [s] of an arm standing at q_true [rad | m].
Eigen::VectorXd JointsAsRead(const Eigen::VectorXd& q_true, double t,
                             const std::vector<JointOffsetStep>& steps);
/// Where the arm stands at sensor time t [s] when its joints read q_read (the inverse of
/// JointsAsRead): the truth a commanded (read) configuration reaches.
Eigen::VectorXd TrueJoints(const Eigen::VectorXd& q_read, double t,
                           const std::vector<JointOffsetStep>& steps);

struct SensorSimSettings {
  double rate_hz = 100.0;  ///< common clock of the joint, IMU and position streams [Hz]
  ImuModelSettings imu;    ///< rate_hz is overwritten with the clock rate
  /// Position sensor; rate_hz should be ≤ the clock rate. Default: 100 Hz, 0.5 mm per axis.
  PositionSensorSettings position = [] {
    PositionSensorSettings p;
    p.rate_hz = 100.0;
    p.sigma = 5e-4;
    return p;
  }();
  double joint_resolution = 0.0;              ///< encoder quantum [rad]; 0: exact readings
  std::vector<JointOffsetStep> offset_steps;  ///< readings that step while the arm works
  bool mag_disturbance = false;
  double mag_disturbance_uT = 15.0;       ///< |d_E| [µT]
  double mag_disturbance_fraction = 0.2;  ///< fraction of the still stops disturbed [-]
};

/// Everything the sensors deliver at one clock tick.
struct SensorFrame {
  double t = 0.0;                          ///< [s]
  Eigen::VectorXd q;                       ///< joints as read [rad | m]
  ImuSample imu;                           ///< gyro [rad/s], specific force [m/s²], field [µT]
  std::optional<PositionSample> position;  ///< when the position sensor fired (not dropped)
  ToolState truth;                         ///< the truth at t (for tests and reports)
};

/// Steps the clock along the trajectory and samples every sensor.
class SensorSim {
 public:
  SensorSim(const ToolMotionTruth& truth, const SensorSimSettings& settings, std::uint64_t seed);
  /// The next tick, or nullopt after the end of the trajectory.
  std::optional<SensorFrame> Next();
  /// Number of ticks in the whole trajectory (as it stands now: a retargeted truth changes it).
  std::int64_t num_ticks() const;
  /// Still stops given a magnetic disturbance (indices of waypoints).
  const std::vector<int>& disturbed_stops() const { return disturbed_; }
  const ImuModel& imu() const { return imu_; }
  const PositionSensorModel& position() const { return position_; }

 private:
  const ToolMotionTruth& truth_;
  SensorSimSettings settings_;
  ImuModel imu_;
  PositionSensorModel position_;
  std::int64_t k_ = 0;
  std::vector<int> disturbed_;
  std::vector<Eigen::Vector3d> disturbance_E_;  // per waypoint [µT]
};

}  // namespace rcal::sim
