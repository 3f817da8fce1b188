// Clock offsets of the cell's sensors against the arm's joint clock (issue 14, item 2).
//
// The arm's controller, the IMU and the position tracker stamp their samples with clocks of their
// own. Before any calibration the frames between them are unknown (IMU mounting, tracker frame,
// marker offset), so the offsets are found from frame-invariant signals:
//   IMU     |ω_S(s)|  (gyro, sensor frame)       against |J_ω(q(t)) q̇(t)|   (nominal kinematics)
//   tracker |ṗ_WM_W(s)| (marker speed, any frame)  against |v_T(t) + ω_T(t) × r|
// where v_T, ω_T are the velocity of the model's marker point (the end of its chain at nominal
// parameters) and the angular velocity, both in the tool frame T, and r [m] is the marker's offset
// from that point in T. The marker's offset from the drawing is unknown; r is fitted with the
// time shift (Gauss–Newton, bounded by a prior of σ marker_offset_prior_m), so that a marker
// that is not where the drawing puts it does not bend the speed profile the shift is read from
// (settings.estimate_marker_offset; off: r = 0). Measured (test_clock_offset CriteriaOnSeveralArms,
// four arms × two seeds): with the reference at the drawing's marker (4 mm off) the offset holds
// within 0.9 ms with r fitted and 1.6 ms without; at the flange (12 cm off) within 4 ms with r
// fitted and not at all without (errors up to 42 ms).
//
// Offset convention: offset = t_source − t_joints for the same physical instant. A source sample
// stamped s therefore happened at joint time s − offset (ClockOffsetEstimator::ToJointTime). An
// IMU whose stamps run 37 ms late has offset +0.037 s. A gyro sample is the mean rate over the
// interval that ends at its stamp (the orientation filter integrates it so), so it is compared
// with the reference at the interval's midpoint, stamp − Δt/2 (Δt the median stamp spacing):
// read at the stamp instead, the offset would be Δt/2 early and the filter's attitude fed with
// it half a sample ahead of the arm.
//
// Method, per source and window (the overlap of the ring buffers, at most buffer_s):
//   1. signals: joint velocities q̇ from the stream, or, when absent, from a local quadratic
//      least-squares fit over ±joint_derivative_half_width samples on the real stamps (unbiased
//      for jittered stamps, smoothing encoder noise); the marker velocity from the same fit of
//      positions over ±marker_derivative_half_window_s.
//   2. coarse: Pearson correlation of the measured against the reference signal (r = 0) on a grid
//      of coarse_step_s over lags [−max_lag_s, +max_lag_s]; a parabola through the peak and its
//      neighbours. A peak below min_correlation gives no estimate.
//   3. refine: Gauss–Newton on  y_k = g·|ω_T + b_T|(s_k − offset) + c  (IMU: offset, gain g,
//      bias b_T, level c) or  y_k = g·|v_T + ω_T × r|(s_k − offset) + c  (tracker: offset, g, r,
//      c). The gain absorbs a gyro scale error and the scale the nominal kinematics get wrong
//      (gain_knot_s > 0 lets it vary piecewise linearly; measured worse, off by default); b_T is
//      the gyro bias seen in the tool frame (a constant vector in the sensor frame is constant in T
//      whatever the unknown mounting, so |ω_S| = |ω_T + b_T| holds without knowing it): left out, a
//      0.3 °/s bias bends the rate profile where the arm starts and stops, which is where the shift
//      is read, by several ms; c is the mean a noisy norm has at rest.
//   4. σ of the offset: the sandwich (JᵀJ)⁻¹ Ω (JᵀJ)⁻¹ with Ω the Newey–West (Bartlett)
//      estimate of the covariance of Jᵀe over lags up to residual_correlation_s, since the
//      residuals of differentiated, smoothed signals are correlated over the smoothing window
//      and JᵀJ (the slope energy of the reference) says how much the window pins the shift down.
//   A window whose reference moves too little (RMS of the reference about its mean below
//   min_rate_rms / min_speed_rms) gives no estimate (σ = ∞) rather than a wrong one.
//   The reference's time derivative is a central difference over ±slope_step_s: the q̇ fitted on
//   jittered stamps carries a multiplicative noise, and its sample-to-sample derivative in the
//   Jacobian biased the shift (errors-in-variables) by several ms at 0.5 ms of stamp jitter.
// What the windows do not see: the nominal kinematics' errors (the paper's Table 3: α up to
// 1.3°) bend |ω| and the speed by a few % slowly along a move, which moves one window's shift by
// up to ±10 ms on long moves with a σ of 0.2 ms. So the windows' estimates are combined
// (inverse-variance weights, the variance inflated by their overlap buffer_s / estimate_every_s)
// and σ is at least the scatter of the windows about the combined offset over the independent
// windows they span: over the test's seeds the error / σ has an RMS of 0.7–0.9.
//
// Online: samples are pushed one at a time with their own stamps; each stream keeps a ring buffer
// of buffer_s; a source is re-estimated every estimate_every_s of its own time. State per source:
//   kUnknown     no estimate since the last reset;
//   kEstimating  an estimate, σ ≥ max_sigma_s (not usable yet);
//   kLocked      σ < max_sigma_s and windows spanning lock_min_windows buffers: usable.
// A window without motion changes nothing (the offset does not change while the arm stands).
// The offset is assumed constant between resets (no drift model). Clock jumps: each stream's stamps
// go through a TimeGate; a re-synchronisation (a restarted driver: stamps back by more than
// jump_back_s, or forward by more than jump_forward_s, confirmed by resync_samples consistent
// samples) resets that source (the joint stream: every source) and is counted.
// Bad input (non-finite or absurd values, wrong joint count, stamps out of order) is refused
// with a Status naming the field, counted, and leaves the state unchanged.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <deque>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "rcal/estimation/result.hpp"
#include "rcal/estimation/time_gate.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::estimation {

/// The sources whose clocks are aligned to the joint clock.
enum class ClockSource { kImu = 0, kMarker = 1 };
inline constexpr int kNumClockSources = 2;
/// "imu" or "marker" (field names in messages).
const char* ClockSourceName(ClockSource s);

enum class ClockState { kUnknown, kEstimating, kLocked };
/// "unknown", "estimating", "locked".
const char* ClockStateName(ClockState s);

struct ClockOffsetSettings {
  double max_lag_s = 0.5;         ///< coarse search over offsets in [−max_lag_s, max_lag_s] [s]
  double coarse_step_s = 0.004;   ///< grid step of the coarse search [s]
  double buffer_s = 20.0;         ///< ring buffer per stream [s]
  double estimate_every_s = 2.0;  ///< re-estimation period, in the source's own time [s]
  double min_window_s = 4.0;      ///< shortest overlap of source and joints to estimate from [s]
  double max_sigma_s = 0.002;     ///< an offset is usable (locked) when σ is below this [s]
  /// Locked also needs the windows combined to span this many buffer lengths of source data [-]
  /// (the scatter between windows, which bounds σ, needs more than one).
  double lock_min_windows = 2.0;
  double min_correlation = 0.6;  ///< coarse correlation peak below this: no estimate [-]
  double min_rate_rms = 0.05;    ///< IMU: reference |ω| RMS about its mean below: still [rad/s]
  double min_speed_rms = 0.02;   ///< tracker: reference speed RMS below this: still [m/s]
  int joint_derivative_half_width = 6;  ///< samples each side of the q̇ fit when q̇ is absent [-]
  double marker_derivative_half_window_s = 0.05;  ///< half width of the marker velocity fit [s]
  bool estimate_marker_offset = true;             ///< fit r (see the header) with the offset
  bool estimate_gyro_bias = true;      ///< fit the gyro bias b_T (see the header) with the offset
  double gyro_bias_prior = 0.05;       ///< σ of the prior bounding b_T [rad/s]
  double marker_offset_prior_m = 0.2;  ///< σ of the prior bounding r [m]
  double slope_step_s = 0.04;          ///< half step of the reference's central time derivative [s]
  double gain_knot_s = 0.0;  ///< knot spacing of the reference's gain g(t); ≤ 0: one gain [s]
  double gain_prior = 0.2;   ///< σ of each gain knot about 1 [-]
  double residual_correlation_s = 0.25;  ///< Newey–West lag window of the σ [s]
  int gauss_newton_iterations = 10;      ///< [-]
  // Clock jumps (the TimeGate of each stream).
  double jump_forward_s = 1.0;  ///< a stamp this far past the last one is a jump, not a gap [s]
  double jump_back_s = 0.1;     ///< a stamp back by more than this may be a new clock [s]
  int resync_samples = 5;       ///< consistent samples that confirm a jump [-]
  // Bounds of sane input.
  double max_abs_time_s = 1e11;      ///< |stamp| above this is corrupt [s] (≈ 3000 years)
  double max_gyro = 35.0;            ///< |ω| above this is absurd [rad/s] (2000 °/s)
  double max_position_m = 100.0;     ///< |p_WM_W| above this is absurd [m]
  double max_joint_value = 100.0;    ///< |qᵢ| above this is absurd [rad | m]
  double max_joint_speed = 50.0;     ///< |q̇ᵢ| above this is absurd [rad/s | m/s]
  int max_buffer_samples = 100'000;  ///< hard bound per stream whatever the rate [-]
  /// MayFormStillWindow: a still window of T seconds is refused while σ > fraction × T [-].
  double still_window_sigma_fraction = 0.02;
};

/// The current offset of one source.
struct ClockOffset {
  ClockState state = ClockState::kUnknown;
  double offset_s = 0.0;  ///< t_source − t_joints [s] (0 while unknown)
  double sigma_s = std::numeric_limits<double>::infinity();  ///< 1σ of offset_s [s]
  bool usable = false;                                       ///< state == kLocked
  double correlation = 0.0;     ///< latest window: coarse correlation peak [-]
  double residual_rms = 0.0;    ///< latest window: RMS residual [rad/s | m/s]
  double window_s = 0.0;        ///< latest window: its length [s]
  double estimated_at_s = 0.0;  ///< source time of the window's last sample [s]
  double gain = 1.0;            ///< latest window: measured / reference scale [-]
  Eigen::Vector3d marker_r_T = Eigen::Vector3d::Zero();   ///< tracker: fitted r, tool frame [m]
  Eigen::Vector3d gyro_bias_T = Eigen::Vector3d::Zero();  ///< IMU: fitted bias, tool frame [rad/s]
};

/// One window's estimate: the offset with its σ, or σ = ∞ and the reason there is none.
struct OffsetWindowEstimate {
  double offset_s = 0.0;                                     ///< [s]
  double sigma_s = std::numeric_limits<double>::infinity();  ///< [s]; ∞: no estimate
  double correlation = 0.0;                                  ///< [-]
  double residual_rms = 0.0;                                 ///< [signal units]
  double gain = 1.0;  ///< measured / reference scale (mean of the knots) [-]
  Eigen::Vector3d marker_r_T = Eigen::Vector3d::Zero();   ///< tracker only [m]
  Eigen::Vector3d gyro_bias_T = Eigen::Vector3d::Zero();  ///< IMU only [rad/s]
  int samples = 0;                                        ///< source samples used [-]
  std::string reason;  ///< why there is no estimate ("" when σ is finite)
  bool ok() const { return sigma_s < std::numeric_limits<double>::infinity(); }
};

/// The reference motion at one joint sample, from the nominal kinematics.
struct ReferenceSample {
  double t = 0.0;                                     ///< joint time [s]
  Eigen::Vector3d v_T = Eigen::Vector3d::Zero();      ///< marker-point velocity, tool frame [m/s]
  Eigen::Vector3d omega_T = Eigen::Vector3d::Zero();  ///< angular velocity, tool frame [rad/s]
};

/// One source sample: its stamp [s] and its value (IMU: the gyro [rad/s]; tracker: the speed
/// [m/s] from the velocity fit).
struct SourceSample {
  double t = 0.0;
  double y = 0.0;
};

/// The batch core, for one window: the offset of `measured` (source clock) against `reference`
/// (joint clock, increasing t). Pure; ClockOffsetEstimator calls it on its buffers.
OffsetWindowEstimate EstimateOffsetWindow(const std::vector<ReferenceSample>& reference,
                                          const std::vector<SourceSample>& measured,
                                          ClockSource source, const ClockOffsetSettings& settings);

/// Marker speeds from positions by a local quadratic fit over ±half_window_s on the real stamps
/// (samples whose window is not covered on both sides are left out). t [s] increasing, p [m].
std::vector<SourceSample> MarkerSpeeds(const std::vector<double>& t,
                                       const std::vector<Eigen::Vector3d>& p, double half_window_s);

/// Whether a still window of `window_s` seconds may be formed on a source's corrected time: refused
/// (naming the source) while its offset is unknown or σ > fraction × window_s.
Status MayFormStillWindow(const ClockOffset& offset, ClockSource source, double window_s,
                          double fraction);

class ClockOffsetEstimator {
 public:
  struct StreamCounters {
    int64_t accepted = 0;     ///< samples accepted
    int64_t bad_value = 0;    ///< refused: non-finite or absurd value, wrong size
    int64_t bad_time = 0;     ///< refused by the stamp checks (duplicate, out of order, jump)
    int64_t clock_jumps = 0;  ///< confirmed clock jumps (each reset the source)
  };
  struct SourceCounters {
    int64_t windows = 0;        ///< estimation attempts
    int64_t estimates = 0;      ///< windows that gave a finite σ
    int64_t no_estimate = 0;    ///< windows without (too little motion, low correlation, …)
    int64_t disagreements = 0;  ///< window estimates more than 5σ from the combined one
    std::string last_reason;    ///< why the last window gave no estimate
  };

  /// `model`: the arm at nominal parameters (x = 0) gives the reference; its position output
  /// (the chain's end: the drawing's marker, or the flange) is the marker point.
  explicit ClockOffsetEstimator(kinematics::KinematicModel model,
                                const ClockOffsetSettings& settings = {});

  /// A joint sample at controller time t [s], q [rad | m]; q̇ is differentiated from q.
  Status PushJoints(double t, const Eigen::VectorXd& q);
  /// A joint sample with its velocities q̇ [rad/s | m/s].
  Status PushJoints(double t, const Eigen::VectorXd& q, const Eigen::VectorXd& qd);
  /// A gyro sample at IMU time t [s], ω in the sensor frame [rad/s].
  Status PushGyro(double t, const Eigen::Vector3d& omega_S);
  /// A marker position at tracker time t [s], p_WM_W in the tracker's frame [m].
  Status PushMarker(double t, const Eigen::Vector3d& p_WM_W);

  /// Re-estimates `source` from the buffers now (the pushes do it every estimate_every_s).
  /// Returns the window's estimate (σ = ∞ and a reason when it gave none).
  OffsetWindowEstimate Estimate(ClockSource source);

  const ClockOffset& offset(ClockSource s) const { return offsets_[Index(s)]; }
  /// The joint time of a source stamp: t_source − offset [s] (the estimate as it stands).
  double ToJointTime(ClockSource s, double t_source) const {
    return t_source - offsets_[Index(s)].offset_s;
  }
  /// MayFormStillWindow for every source that has delivered samples since its last reset (the
  /// first refusal, naming the source), with settings.still_window_sigma_fraction.
  Status MayFormStillWindow(double window_s) const;

  /// Joint stream counters; source counters (stream and estimation).
  const StreamCounters& joint_counters() const { return joint_counters_; }
  const StreamCounters& stream_counters(ClockSource s) const { return stream_counters_[Index(s)]; }
  const SourceCounters& source_counters(ClockSource s) const { return source_counters_[Index(s)]; }
  /// Reason of the last refused sample (any stream), "" before the first.
  const std::string& last_error() const { return last_error_; }
  const ClockOffsetSettings& settings() const { return settings_; }

  /// Forgets every buffer and estimate (counters are kept).
  void Reset();

 private:
  static int Index(ClockSource s) { return static_cast<int>(s); }
  struct JointSample {
    double t;
    Eigen::VectorXd q;
    std::optional<Eigen::VectorXd> qd;
  };
  Status Refuse(int64_t& counter, std::string reason);
  Status CheckStamp(TimeGate& gate, StreamCounters& c, double t, const char* stream, bool& jumped);
  void ProcessJoints();  // turns joint samples into reference samples once q̇ is known
  ReferenceSample Reference(double t, const Eigen::VectorXd& q, const Eigen::VectorXd& qd) const;
  void ResetSource(ClockSource s);
  void MaybeEstimate(ClockSource s, double t);

  kinematics::KinematicModel model_;
  Eigen::VectorXd x0_;
  ClockOffsetSettings settings_;
  TimeGate joint_gate_;
  std::array<TimeGate, kNumClockSources> gates_;
  std::deque<JointSample> joints_;  // the last samples: the fit's left side, those awaiting q̇
  size_t next_joint_ = 0;           // first sample of joints_ not yet a reference sample
  std::deque<ReferenceSample> reference_;
  std::deque<SourceSample> gyro_;  // t, |ω_S|
  std::deque<double> marker_t_;
  std::deque<Eigen::Vector3d> marker_p_;
  std::array<ClockOffset, kNumClockSources> offsets_;
  struct Combined {  // inverse-variance sums of the window estimates since the reset
    int n = 0;
    double sw = 0, swx = 0, swxx = 0, first_t = 0, last_t = 0;
  };
  std::array<Combined, kNumClockSources> combined_{};
  std::array<double, kNumClockSources> next_estimate_{};
  std::array<bool, kNumClockSources> has_samples_{};
  StreamCounters joint_counters_;
  std::array<StreamCounters, kNumClockSources> stream_counters_;
  std::array<SourceCounters, kNumClockSources> source_counters_;
  std::string last_error_;
};

}  // namespace rcal::estimation
