// The pose pipeline: raw sensor streams in, one still-pose measurement per still window out —
// the measurement the EKF identifier consumes (the paper's Sections 3.3–3.4 feeding Section 4).
//
// Inputs, in sensor-time order (non-decreasing t across all three streams; ties allowed):
//   joints   q [rad | m]                          → still detection (StillDetector, joints)
//   IMU      gyro ω_B [rad/s], specific force f_B [m/s²], field m_B [any fixed unit], body B = I
//            → OrientationKf (FQA inside) → q_EI; the accelerometer also drives the position KF
//   position p_WM_W [m], marker in the world (position sensor) frame W → PositionKf
// Frames. The orientation KF works in the earth frame E (NED by default). The position KF works
// in W: the accelerometer is brought into W with the current estimate R_WE (SetWorldFromEarth,
// identity until told) as a_W = R_WE (R_EI f_B + g_E); the position KF is given that
// acceleration through its own interface (R = I, f' = a_W − g_E), so any R_WE is exact. While the
// arm stands still a_W ≈ 0 whatever R_WE is, so R_WE only matters while moving.
//
// Window. It opens when the joints have been still for StillDetectorSettings::min_duration, then
// `settle_time` more seconds are skipped (the filters forget the move), and it closes at the
// first moving joint sample (or Flush()). Over the window, at each IMU sample:
//   pose       p̄_WM_W, q̄_EI: mean of the filters' outputs (StillWindow: arithmetic mean of
//              positions, Markley mean of quaternions); q̄ = mean of the joint readings.
//   covariance of the window mean, from the scatter of the raw measurements the filters accepted:
//              Σ_p = S_p / N_p, S_p the sample covariance of the position-sensor samples;
//              Σ_θ = S_θ / N_θ, S_θ that of δθ_i = Log(R_FQA,i R̄_EIᵀ) (earth frame), R_FQA,i the
//              FQA of sample i (accelerometer and magnetometer both accepted);
//              each inflated by `covariance_scale` and floored by the `*_floor_sigma`s; Σ_θ
//              also carries the accelerometer bias, which no averaging removes (accel_bias_*),
//              and, when the window's heading disagrees with the previous window's carried by
//              the gyro (heading_consistency_chi2), that disagreement squared. With
//              fewer than `min_raw_samples` raw samples the filters' mean covariance is used
//              (StillWindow, conservative). The 6×6 covariance is block diagonal [m², rad²].
// Rest (rest_from_joints, default): the filters take their first IMU sample once the joints have
// stood still for still.min_duration, the window of that first stop is dropped, as a warm-up,
// and the orientation KF's rest (zero-rate update, gyro bias, magnetic reference) is the joints'.
// A window is dropped (counted, with the reason) when it has fewer than min_window_samples IMU
// samples, no accepted position sample, or an IMU gap longer than max_gap, or is the warm-up.
// Bad input (non-finite values, wrong joint count, time going backwards) is refused with a
// Status naming the field and counted; the state is unchanged. A filter whose state goes
// non-finite resets (Counters::filter_resets): both filters start again at the next rest, the
// open window is dropped, and no pose is ever built from a non-finite state.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/estimation/position_kf.hpp"
#include "rcal/estimation/result.hpp"
#include "rcal/estimation/still_window.hpp"
#include "rcal/kinematics/measurement.hpp"

namespace rcal::estimation {

struct PosePipelineSettings {
  /// Orientation KF; defaults suited to a still-and-move program with an Xsens MTi-100 class
  /// IMU (raw FQA, no low-pass, so the estimate settles within a still stop).
  OrientationKfSettings orientation = [] {
    OrientationKfSettings s;
    s.accel_lowpass_tau = 0.0;
    s.mag_lowpass_tau = 0.0;
    // The FQA's own noise at rest (accelerometer 60 µg/√Hz, magnetometer 0.02 µT/√Hz against
    // a 20 µT horizontal field, 100 Hz), and an attitude process noise that lets the estimate
    // forget a move within ~0.1 s: the window mean is then the mean of the still samples.
    s.tilt_sigma = 0.002;             // [rad]
    s.heading_sigma = 0.01;           // [rad]
    s.attitude_process_noise = 0.01;  // [rad/√s]
    return s;
  }();
  /// Position KF; position_sigma should be the position sensor's σ per axis [m].
  PositionKfSettings position = [] {
    PositionKfSettings s;
    s.position_sigma = 5e-4;
    return s;
  }();
  StillDetectorSettings still;
  double settle_time = 0.2;              ///< [s] skipped after the detector declares still
  int min_window_samples = 20;           ///< IMU samples a window needs [-]
  int min_raw_samples = 10;              ///< raw samples needed for the scatter covariance [-]
  double max_gap = 0.2;                  ///< [s] largest IMU gap tolerated inside a window
  bool use_orientation = true;           ///< false: position-only measurements
  double covariance_scale = 1.0;         ///< multiplies the window covariance [-]
  double position_floor_sigma = 0.0;     ///< [m] per axis, added in quadrature
  double orientation_floor_sigma = 0.0;  ///< [rad] per axis, added in quadrature
  /// Rest from the joints (the encoders see a stop exactly; the IMU's own test takes a slow
  /// rotation below its still_gyro for rest): the filters start once the joints have stood
  /// still for still.min_duration (the detector's still()), the window of that first stop is
  /// dropped (the filters converge in it), and the orientation KF's zero-rate update, bias and
  /// magnetic reference follow the joints' rest. A pipeline restarted in a move, or at the very
  /// start of one, otherwise took the move's first 0.2 s for rest, learned a gyro bias of
  /// 0.03 rad/s, and gave windows 3–6 σ off in heading for the next ~20 s. Off: the filters
  /// start on the first IMU sample and judge rest from the IMU.
  bool rest_from_joints = true;
  /// The accelerometer's bias b [m/s²], which no window averages out: it tilts the window's
  /// orientation by (b_E × u)/g and, through the magnetometer's levelling, turns its heading by
  /// tan(dip) (ê·b_E)/g (AccelBiasOrientationCovariance). The window covariance adds that, with
  /// the bias's variance per axis σ_ba² = accel_bias_sigma² + accel_bias_random_walk² · (t − t₀),
  /// t the window's end and t₀ the first IMU sample. Measured why: with a random walk of
  /// 1e-4 m/s²/√s (an MTi-100 class accelerometer over minutes, as the sensor experiment's
  /// "gyro bias" configuration simulates) the windows' tilt was 5e-4 rad off against a 6e-5 rad
  /// scatter and the window NEES read 41 for 6.3; with the walk off, 6.0–6.6. 0 and 0: the bias
  /// is taken as calibrated away (the paper).
  double accel_bias_sigma = 0.0;        ///< [m/s²] per axis (datasheet: bias stability)
  double accel_bias_random_walk = 0.0;  ///< [m/s²/√s] per axis
  /// A window whose heading disagrees with the previous window's carried by the gyro alone
  /// (less the filter's bias estimate) beyond this χ²(1) value, against the sum of the
  /// variances (both windows', the gyro's white noise and the bias's over the time between),
  /// follows a disturbed field: its heading variance gains the disagreement squared, Δψ².
  /// Measured why: the disturbed stops the magnetometer's norm and dip tests let through are
  /// those whose disturbance turns the horizontal field without changing its norm or dip, the
  /// most harmful (0.7 rad); their own evidence is nil, the gyro's is not. (The filter's heading
  /// at the stop's start is no reference: in motion the accelerometer's linear acceleration
  /// tilts it, and the dip turns that into heading, 0.06 rad against a σ of 0.003.) 10.83: a
  /// false alarm in 1000 windows; 0 = off.
  double heading_consistency_chi2 = 10.83;
};

/// Covariance [rad²] of a window's orientation error δθ_E (earth frame, R̂_EI = Exp(δθ_E) R_EI)
/// caused by an accelerometer bias of variance sigma_ba² [m²/s⁴] per axis, isotropic: the FQA
/// takes f + b for the specific force, so δθ_E = A b_E with A = (−[u]× + tan(dip) u êᵀ)/g,
/// u the earth frame's up, ê = n̂ × u magnetic east, g [m/s²] gravity, dip [rad] the field's dip
/// (positive down; 0 when the heading does not use a magnetometer). Returns sigma_ba² A Aᵀ.
Eigen::Matrix3d AccelBiasOrientationCovariance(EarthFrame earth, double gravity, double dip,
                                               double sigma_ba);

/// One still-window pose measurement (the fields of kinematics::PoseMeasurement, plus where it
/// came from).
struct StillPose {
  Eigen::VectorXd q;                                 ///< mean joint reading [rad | m]
  Eigen::Vector3d p_WM_W = Eigen::Vector3d::Zero();  ///< marker position, world [m]
  bool has_orientation = true;
  Eigen::Matrix3d R_EI = Eigen::Matrix3d::Identity();  ///< IMU → earth
  /// Covariance of [δp_W; δθ_E] (6×6) [m², rad²], or 3×3 [m²] when position only.
  Eigen::MatrixXd covariance;
  double t_begin = 0.0, t_end = 0.0;  ///< [s]
  int imu_samples = 0;                ///< filter outputs averaged
  int position_samples = 0;           ///< raw position samples accepted in the window
  int orientation_samples = 0;        ///< raw FQA samples in the orientation scatter

  /// The identifier's measurement of this window (kinematics::PoseMeasurement: q, p_WM_W, R_EI,
  /// covariance), what the still_window process publishes as POSE_MEASUREMENT.
  kinematics::PoseMeasurement ToMeasurement() const {
    kinematics::PoseMeasurement m;
    m.q = q;
    m.p_WM_W = p_WM_W;
    m.has_orientation = has_orientation;
    m.R_EI = R_EI;
    m.covariance = covariance;
    return m;
  }
};

class PosePipeline {
 public:
  struct Counters {
    std::int64_t joint_samples = 0, imu_samples = 0, position_samples = 0;
    std::int64_t input_rejected = 0;   ///< refused calls (bad input, time order)
    std::int64_t windows_emitted = 0;  ///< poses produced
    std::int64_t windows_dropped = 0;  ///< windows without a usable pose (or the warm-up)
    std::int64_t imu_before_rest = 0;  ///< IMU samples before the filters started (at rest)
    std::int64_t filter_resets = 0;    ///< a filter's state went non-finite: both restarted
    /// windows whose heading disagreed with the previous window carried by the gyro, their
    /// heading variance widened (heading_consistency_chi2)
    std::int64_t heading_disagreements = 0;
    std::string last_error;  ///< last refusal or drop reason
  };

  explicit PosePipeline(const PosePipelineSettings& settings = {});
  /// Forgets filters, window, pending poses and counters (R_WE is kept).
  void Reset();
  /// World ← earth rotation used to bring accelerations into the position frame.
  void SetWorldFromEarth(const Eigen::Matrix3d& R_WE) { R_WE_ = R_WE; }

  /// Joint reading q [rad | m] at t [s].
  Status AddJoints(double t, const Eigen::VectorXd& q);
  /// IMU sample at t [s]: gyro [rad/s], specific force [m/s²], magnetic field (body frame).
  Status AddImu(double t, const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B,
                const Eigen::Vector3d& m_B);
  /// Position-sensor sample p_WM_W [m] at t [s] (the time the position refers to).
  Status AddPosition(double t, const Eigen::Vector3d& p_WM_W);
  /// Closes an open window (end of a recording).
  void Flush();
  /// Poses completed since the last call (oldest first).
  std::vector<StillPose> TakePoses();

  const Counters& counters() const { return counters_; }
  const OrientationKf& orientation_kf() const { return ori_; }
  const PositionKf& position_kf() const { return pos_; }
  bool in_window() const { return open_; }
  const PosePipelineSettings& settings() const { return settings_; }

 private:
  Status CheckTime(double t, const char* stream);
  Status Refuse(const std::string& reason);
  void CloseWindow();
  void Drop(const std::string& reason);
  void FilterReset(double t);

  PosePipelineSettings settings_;
  OrientationKf ori_;
  PositionKf pos_;
  StillDetector detector_;
  StillWindow window_;
  Eigen::Matrix3d R_WE_ = Eigen::Matrix3d::Identity();
  Counters counters_;
  std::vector<StillPose> ready_;
  bool has_t_ = false;
  double t_last_ = 0.0;
  int num_joints_ = -1;
  bool still_ = false;  // detector state after the last joint sample
  bool open_ = false;   // accumulating a window
  double t_open_ = 0.0, t_first_ = 0.0, t_last_imu_ = 0.0;
  bool gap_ = false;
  // Start at rest: when the filters started [s], and whether the open window is in the stop
  // they started in.
  bool filters_started_ = false;
  double t_filters_started_ = 0.0;
  // The last window's orientation carried since by the gyro alone (less the filter's bias):
  // R_EI of that window, the rotation R_I0I (IMU then ← IMU now), the heading variance of the
  // window [rad²], the gyro's white-noise part since [rad²], the time carried [s], the last
  // sample's time [s].
  struct Carried {
    Eigen::Matrix3d R_EI = Eigen::Matrix3d::Identity();
    Eigen::Matrix3d R_I0I = Eigen::Matrix3d::Identity();
    double var_window = 0.0, var_gyro = 0.0, duration = 0.0, t = 0.0;
  };
  std::optional<Carried> carried_;
  // The first IMU sample [s], the start of the accelerometer bias's random walk.
  std::optional<double> t_imu0_;
  bool window_in_start_stop_ = false;
  Eigen::VectorXd q_sum_;
  int q_count_ = 0;
  std::vector<Eigen::Vector3d> raw_p_;
  std::vector<Eigen::Matrix3d> raw_R_;
};

}  // namespace rcal::estimation
