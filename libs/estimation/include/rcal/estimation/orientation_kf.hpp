// Orientation Kalman filter (the paper's Section 3.3, Eqs. 18–23, errata from
// ../shared/paper/NOTES.md applied), in error-state (multiplicative) form, with a gyro-bias
// state and rejection of disturbed accelerometer and magnetometer samples.
//
// Frames and conventions. q_EB = q̂ [w,x,y,z] (Hamilton) rotates body (IMU) vectors into the
// earth frame E (NED or ENU, z vertical): v_E = R_EB v_B. ω_B [rad/s] is the body angular rate,
// b_B [rad/s] the gyro bias.
//
// Paper's model (Eq. 18, 19):  q̇ = ½ q ⊗ [0, ω_B],  x = [q, ω_B],  ω̇_B = w (white, Eq. 21),
// gyro observes ω_B (Eq. 22, H = [0 I]), the FQA quaternion observes q, q renormalised (Eq. 23).
// Its linearised transition is Φ_ori (Eq. 20), returned by PaperPhiOri() with the row-2 sign
// corrected (NOTES.md: row 2 is q0Δt/2, −q3Δt/2, q2Δt/2).
//
// This filter keeps the same state and measurements but writes the quaternion part as a
// 3-vector error on the left, in the earth frame: R_EB = Exp(δθ_E) R̂_EB. This is the
// paper's filter with the normalisation (Eq. 23) built in: the 4×4 quaternion block of Eq. 20 is
// replaced by its 3×3 tangent-space equivalent, so P stays consistent with |q| = 1 and q, −q.
//   Each sample k: (1) rate prediction  ω̂_k⁻ = ω̂_{k−1}, b̂_k⁻ = b̂_{k−1},
//                     P_ωω += σ_α² Δt I, P_bb += σ_b² Δt I  (w white angular acceleration,
//                     PSD σ_α² [rad²/s³], Eq. 21; w_b bias random walk, PSD σ_b²);
//   (2) gyro update of ω̂_k, b̂_k; (3) attitude propagation with the rate over (t_{k−1}, t_k]:
//       q̂_k = q̂_{k−1} ⊗ Exp(ω̂_k Δt),
//       δθ_k = δθ_{k−1} + R̂_EB,k J_r(ω̂_k Δt) Δt δω_k     (the paper's Φ_ori columns 5–7),
//       P ← Φ P Φᵀ + σ_q² Δt I_θθ + k_ω² |ω̂|² Δt e_z e_zᵀ  (unmodelled attitude noise;
//       optional heading noise growing with the rate, off by default); (4) FQA update.
//   Ordering (2) before (3) makes ω_k the rate over the interval ending at t_k, as a sampled
//   gyro measures it; propagating with ω̂_{k−1} (Eq. 20 read literally) lags the gyro by one
//   sample, which costs several degrees on fast motion.
// Hard iron (beyond the paper, estimate_hard_iron): m_B ← m_B − b̂_B first, b̂_B learned from the
// field's norm alone (mag_hard_iron.hpp).
// Magnetometer delay (beyond the paper): m_B is first turned to the gyro's time with the rate,
// m_B ← Exp(ω̂_B mag_delay)ᵀ m_B (settings).
// FQA inputs (beyond the paper): f_B and the accepted m_B are first low-passed (time constants
// accel_lowpass_tau, mag_lowpass_tau) in a strapdown frame I integrated from the gyro alone,
// f̄_I ← f̄_I + α (R_IB f_B − f̄_I), and rotated back, f̄_B = R_IBᵀ f̄_I (the accelerometer's by
// a second-order Butterworth instead with accel_lowpass_order = 2). In I gravity and the
// earth field are nearly constant while linear accelerations average out; with τ = 0 the FQA
// sees the raw samples, as in the paper.
// Measurements (standard KF update, NOTES.md errata for Eqs. 15–17, Joseph form):
//   gyro:   z = ω_meas,  h = ω̂ + b̂,  H = [0 I I],  R = σ_g² / Δt I
//   rest:   z = 0,       h = ω̂,      H = [0 I 0]  (zero-rate update while still, optional)
//   FQA:    y = Log(R_FQA R̂_EBᵀ) (earth frame, sign-blind: q and −q give the same y),
//           H = [I 0 0]; rows x, y (tilt) come from the accelerometer, row z (heading) from the
//           magnetometer, with R = diag(σ_tilt², σ_tilt², σ_head²).
//   With `decoupled_fqa` (default) the tilt rows use FQA(accelerometer, predicted
//   magnetometer) and the heading row FQA(predicted gravity, magnetometer): each row is the FQA
//   with the other sensor replaced by its prediction, so a linear acceleration never reaches
//   heading and a magnetic disturbance never reaches tilt. Otherwise one FQA(acc, mag) is used.
// Rejection: the accelerometer when ||f| − g| > accel_norm_tolerance or its tilt innovation
// fails a χ² gate; the magnetometer when |m| or its dip angle departs from the reference or its
// heading innovation fails a χ² gate. Each rejection is counted (Counters).
// A step longer than max_step (an IMU silence) starts the attitude again from that sample's FQA,
// as the first sample does, keeping the gyro bias and the magnetic reference (settings).
// Bad input (non-finite values, values beyond the sensor's range, non-increasing time) is refused
// with a Status naming the field; the state is then unchanged. A state that still goes non-finite
// (an input within range but a degenerate step) is never kept: the filter resets, counts it
// (Counters::resets) and says so in the returned Status, and initialises again on the next sample.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>

#include "rcal/estimation/fqa.hpp"
#include "rcal/estimation/mag_hard_iron.hpp"
#include "rcal/estimation/result.hpp"

namespace rcal::estimation {

/// The paper's Φ_ori (Eq. 20) for the state [q0..q3, ωx, ωy, ωz] and sampling time dt [s],
/// with the NOTES.md erratum: row 2 is [0 1 0 0 | q0 dt/2, −q3 dt/2, q2 dt/2].
Eigen::Matrix<double, 7, 7> PaperPhiOri(const Eigen::Vector4d& q_wxyz, double dt);

/// Defaults: the one set used for all BROAD trials (`rcal fuse`), tuned on those trials;
/// the IMU noise densities are the paper's Xsens MTi-100.
struct OrientationKfSettings {
  EarthFrame earth = EarthFrame::kNed;
  /// Local gravity magnitude [m/s²].
  double gravity = 9.81;

  // --- Process model ---
  /// PSD of the white angular acceleration driving ω (paper's w, Eq. 21) [rad/s²/√Hz].
  double angular_accel_noise = 30.0;
  /// Gyro-bias random walk [rad/s/√s]. Used when estimate_gyro_bias.
  double gyro_bias_random_walk = 2e-5;
  /// Extra attitude random walk for unmodelled effects (scale, misalignment) [rad/√s].
  double attitude_process_noise = 1e-3;
  /// Heading random walk proportional to the rate, for gyro scale-factor and integration
  /// errors that grow with fast motion: σ = rate_proportional_noise · |ω̂| [rad/√s], applied to
  /// the earth-z (heading) error only [√s].
  double rate_proportional_noise = 0.0;
  /// Estimate the gyro bias (beyond the paper; on by default).
  bool estimate_gyro_bias = true;
  /// Learn in motion: the gyro bias before the filter's first rest (still()), and the magnetic
  /// reference from moving samples. Off by default: in motion linear accelerations bend the
  /// accelerometer's gravity, so a filter started in a move mislearned its bias (by 0.05 rad/s,
  /// with its wide initial bias covariance absorbing the bent FQA updates) and its dip (by 6°,
  /// then rejecting the field): a pose pipeline restarted in a move gave still windows 2–340 σ
  /// off in heading for the next ~20 s. Off, the bias is a consider state (Schmidt) until the
  /// first rest: its covariance enters every gain, it is not corrected; and the reference is
  /// learned from samples at rest only. On for data without rests and without linear
  /// acceleration.
  bool learn_in_motion = false;

  // --- Measurement noise ---
  /// Gyro white-noise density [rad/s/√Hz] (Xsens MTi-100: 0.01 °/s/√Hz).
  double gyro_noise_density = 0.01 * 3.14159265358979 / 180.0;
  /// Standard deviation of one FQA tilt measurement [rad] (accelerometer noise plus the
  /// unmodelled linear acceleration the filter should average out).
  double tilt_sigma = 0.015;
  /// Standard deviation of one FQA heading measurement [rad].
  double heading_sigma = 0.2;
  /// Time constants of the first-order low-pass applied to the accelerometer and to the
  /// accepted magnetometer samples in the strapdown frame before the FQA [s]; 0 = raw samples
  /// (the paper). Linear accelerations average out; gravity does not.
  double accel_lowpass_tau = 3.0;
  double mag_lowpass_tau = 3.0;
  /// Order of the accelerometer's low-pass [-]: 1 the first-order filter above; 2 a second-order
  /// Butterworth with the same delay at low frequencies (VQF's accelerometer filter). Above the
  /// cutoff it falls as f⁻² instead of f⁻¹:
  /// a 0.5 Hz linear acceleration is kept at 2 % instead of 11 % with τ = 3 s (low_pass.hpp).
  int accel_lowpass_order = 1;
  /// How far the magnetometer lags the gyro [s]: a sample stamped t measured the field the body
  /// saw at t − mag_delay (a magnetometer low-passes internally). The sample is turned to time t
  /// with the rate before anything uses it: m_B(t) = Exp(ω̂_B mag_delay)ᵀ m_meas (the body turned
  /// by ω̂ mag_delay since). Uncompensated, a lag δ puts the field δ|ω| rad off in fast rotation:
  /// its dip then fails the gate and its heading is wrong. 0 = as stamped.
  double mag_delay = 0.0;
  /// Learn a hard-iron offset (a magnet fixed to the sensor) from the field's norm and take it
  /// off every magnetometer sample before anything else uses it (mag_hard_iron.hpp: applied only
  /// once it is known and beyond a floor the magnetometer's own errors do not reach).
  bool estimate_hard_iron = true;
  MagHardIronSettings hard_iron;
  /// See the header comment. false: one FQA(acc, mag) quaternion as in the paper.
  bool decoupled_fqa = true;
  /// Accelerometer weighted by motion: the tilt rows' standard deviation grows with the motion
  /// the accelerometer sees, σ_tilt,k = tilt_sigma · √(1 + (a_k / tilt_motion_accel)² +
  /// (|ω̂_k| / tilt_motion_rate)²), a_k = |f_B − f̄_B| the raw specific force's departure from
  /// the low-passed one [m/s²] (linear and centripetal acceleration the low-pass has not yet
  /// averaged out), |ω̂_k| the rate [rad/s] (the low-pass's strapdown frame drifts with gyro
  /// scale errors in proportion to it). 0 = that term off.
  double tilt_motion_accel = 0.0;  ///< [m/s²]
  double tilt_motion_rate = 0.0;   ///< [rad/s]

  // --- Rejection (beyond the paper; on by default) ---
  bool reject_accel = true;
  /// Reject the accelerometer when ||f| − g| exceeds this [m/s²].
  double accel_norm_tolerance = 0.5;
  /// χ² gate on the 2-dof tilt innovation (0 = off) [-].
  double tilt_gate_chi2 = 0.0;
  bool reject_mag = true;
  /// Reject the magnetometer when ||m| − m_ref| > mag_norm_tolerance · m_ref [-].
  double mag_norm_tolerance = 0.1;
  /// Reject the magnetometer when its dip angle departs from the reference by more [rad].
  double mag_dip_tolerance = 0.08;
  /// χ² gate on the 1-dof heading innovation (0 = off) [-].
  double heading_gate_chi2 = 0.0;
  /// Disturbance evidence of an accepted magnetometer sample, e = max(|Δnorm| /
  /// (mag_norm_tolerance · m_ref), |Δdip| / mag_dip_tolerance) ∈ [0, 1], inflates its heading
  /// variance: σ_head,k² = heading_sigma² · (1 + mag_evidence_inflation · e²) [-]; 0 = off. A
  /// field half-way to rejection is already suspect: it is weighted down, not trusted fully.
  double mag_evidence_inflation = 0.0;

  // --- Magnetic reference ---
  /// Reference field norm [magnetometer unit] and dip angle [rad, positive down]. When the
  /// norm is ≤ 0 both are learned as the mean over the first mag_reference_samples samples at
  /// rest (any samples with learn_in_motion), away from disturbances; until then the
  /// magnetometer is used ungated.
  double mag_ref_norm = 0.0;
  double mag_ref_dip = 0.0;
  int mag_reference_samples = 100;
  /// After learning, the reference norm and dip follow accepted samples at rest with this time
  /// constant [s] (slow changes across a room; at rest only, where the dip's gravity is not
  /// bent by motion); 0 = fixed.
  double mag_reference_tau = 0.0;
  /// After this long [s] of continuous rejection with a steady field, the field seen is taken
  /// as the new reference (the sensor moved to a place with another field); 0 = never.
  double mag_new_reference_time = 0.0;

  // --- Zero-rate update while still (beyond the paper) ---
  bool zero_rate_update = true;
  /// Still when |ω_meas − b̂| < still_gyro [rad/s] and ||f| − g| < still_accel [m/s²] for
  /// still_samples consecutive samples.
  double still_gyro = 0.02;
  double still_accel = 0.3;
  int still_samples = 20;
  /// Standard deviation of the zero-rate pseudo-measurement [rad/s].
  double zero_rate_sigma = 0.002;

  // --- Initial uncertainty (the first sample initialises q̂ with the FQA) ---
  double initial_attitude_sigma = 0.1;  ///< [rad]
  double initial_rate_sigma = 0.1;      ///< [rad/s]
  double initial_bias_sigma = 0.01;     ///< [rad/s]

  // --- IMU silences ---
  /// The longest step between samples the filter propagates across [s] (0 = any). A longer one
  /// (an IMU that fell silent: a dropped USB frame, a driver restart) re-initialises the attitude
  /// from that sample's FQA, keeping the gyro bias, its covariance and the magnetic reference:
  /// across a silence the rate is extrapolated as constant, and a tool that turned otherwise
  /// meanwhile leaves an attitude error the covariance's linearisation cannot take back (15–30°
  /// RMS over the next 20 s after 1 s of motion, against 0.3–2.6° from the FQA:
  /// OrientationKf.StartsAgainFromTheSensorsAfterAnImuSilence, AidedIns.*ImuSilence*).
  double max_step = 0.1;

  // --- Plausibility: the sensor cannot report beyond its range, so such a sample is corrupt ---
  /// Largest |gyro| per axis [rad/s]: 40 rad/s ≈ 2300 °/s, above the widest MEMS range (2000 °/s).
  double gyro_range = 40.0;
  /// Largest |specific force| per axis [m/s²]: 320 m/s² ≈ 32 g (MEMS IMUs: 16–20 g).
  double accel_range = 320.0;
};

/// max_step [s] for an IMU sampling at rate_hz [Hz]: max_step, or three sample periods of an IMU
/// too slow for it (every step of a 10 Hz IMU would otherwise be a silence). A rate that is not
/// finite and positive leaves max_step.
double MaxStepForRate(double rate_hz, double max_step = OrientationKfSettings{}.max_step);

class OrientationKf {
 public:
  struct Counters {
    std::int64_t samples = 0;                ///< accepted Update calls
    std::int64_t input_rejected = 0;         ///< refused Update calls (bad input)
    std::int64_t accel_rejected = 0;         ///< accelerometer not used (norm test or tilt gate)
    std::int64_t accel_gated = 0;            ///< of which by the χ² tilt gate
    std::int64_t mag_rejected = 0;           ///< magnetometer not used (norm, dip or heading gate)
    std::int64_t mag_gated = 0;              ///< of which by the χ² heading gate
    std::int64_t zero_rate_updates = 0;      ///< samples with a zero-rate update
    std::int64_t mag_reference_changes = 0;  ///< new magnetic references adopted
    std::int64_t reinitialised = 0;          ///< steps beyond max_step: attitude from the FQA
    std::int64_t resets = 0;                 ///< state went non-finite: reset (kept by Reset)
  };

  explicit OrientationKf(const OrientationKfSettings& settings = {});

  /// Forgets the state, the learned magnetic reference and the counters (but `resets`).
  void Reset();

  /// One IMU sample at time t [s] (strictly increasing): gyro ω_meas [rad/s], specific force
  /// f_B [m/s²] and magnetic field m_B [any fixed unit], all in the body frame. `at_rest`: the
  /// caller's own knowledge that the sensor stands still (a robot's joints standing still);
  /// given, it replaces the IMU's rest test (still_gyro, still_accel) for still(), the zero-rate
  /// update, the bias's consider phase and the magnetic reference. (The IMU's test takes a slow
  /// rotation below still_gyro for rest: at the start of a smooth move that is ~0.2 s of
  /// zero-rate updates on a turning sensor.)
  Status Update(double t, const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B,
                const Eigen::Vector3d& m_B, std::optional<bool> at_rest = std::nullopt);

  bool initialized() const { return initialized_; }
  /// q_EB [w,x,y,z], body → earth; sign kept continuous from sample to sample.
  const Eigen::Vector4d& q_EB() const { return q_EB_; }
  Eigen::Matrix3d R_EB() const;
  /// Angular rate estimate ω̂_B [rad/s] (body) and gyro bias b̂_B [rad/s] (body).
  const Eigen::Vector3d& omega_B() const { return omega_B_; }
  const Eigen::Vector3d& bias_B() const { return bias_B_; }
  /// Error-state covariance P (9×9) of [δθ_E [rad], δω_B [rad/s], δb_B [rad/s]].
  const Eigen::Matrix<double, 9, 9>& P() const { return P_; }
  /// Attitude covariance [rad²] of the earth-frame rotation error δθ_E: R_EB = Exp(δθ_E) R̂_EB.
  Eigen::Matrix3d attitude_covariance() const { return P_.topLeftCorner<3, 3>(); }
  /// Last normalised innovation squared of the tilt rows (2 dof) and the heading row (1 dof);
  /// NaN when that row was not used in the last update.
  double last_tilt_nis() const { return last_tilt_nis_; }
  double last_heading_nis() const { return last_heading_nis_; }
  /// Whether the last sample's accelerometer / magnetometer were used.
  bool last_accel_used() const { return last_accel_used_; }
  bool last_mag_used() const { return last_mag_used_; }
  /// The field the last sample's heading row used, m_B [the magnetometer's unit]: the accepted
  /// samples low-passed in the strapdown frame, turned to the body now; NaN when the last sample's
  /// magnetometer was not used. Another filter can level it with its own tilt (aided_ins.hpp).
  const Eigen::Vector3d& last_mag_B() const { return last_mag_B_; }
  bool still() const { return still_count_ >= settings_.still_samples; }
  const Counters& counters() const { return counters_; }
  const OrientationKfSettings& settings() const { return settings_; }
  /// The hard-iron fit (estimate_hard_iron; untouched when off).
  const MagHardIron& hard_iron() const { return hard_iron_; }
  /// Reference field norm and dip [rad] in use (0 until learned).
  double mag_ref_norm() const { return mag_ref_norm_; }
  double mag_ref_dip() const { return mag_ref_dip_; }

 private:
  using Mat9 = Eigen::Matrix<double, 9, 9>;
  // Whether this sample's accelerometer and magnetometer are used.
  struct SensorUse {
    bool accel = false, mag = false;
  };
  // The steps of Update, in order (see the header comment).
  Status Refuse(const std::string& why);
  Status CheckInput(double t, const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B,
                    const Eigen::Vector3d& m_B);
  Status Initialize(double t, const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B,
                    const Eigen::Vector3d& m_B, const FqaSettings& fqa);
  void PredictRate(double dt);
  void UpdateGyro(const Eigen::Vector3d& gyro_B, double dt);
  void PropagateAttitude(double dt);
  void DetectRest(const Eigen::Vector3d& gyro_B, double f_norm, std::optional<bool> at_rest);
  void ZeroRateUpdate();
  // Integrates the strapdown attitude q_IB; returns R_IB.
  Eigen::Matrix3d PropagateStrapdown(double dt);
  // One step of the accelerometer's low-pass in I (accel_lowpass_order) on f_I = R_IB f_B.
  void LowPassAccel(const Eigen::Vector3d& f_I, double dt);
  bool AccelAccepted(const Eigen::Vector3d& f_meas_B) const;
  // σ of this sample's tilt rows given the motion f_B − f̄_B [m/s²] (tilt_motion_accel).
  double TiltSigma(const Eigen::Vector3d& f_motion_B) const;
  // Learns, gates and follows the magnetic reference; whether m_B is used.
  bool MagAccepted(const Eigen::Vector3d& m_B, const Eigen::Vector3d& f_B,
                   const Eigen::Vector3d& down_B, double dt);
  void LearnMagReference(const Eigen::Vector3d& m_B, const Eigen::Vector3d& f_B,
                         const Eigen::Vector3d& down_B);
  void FollowAcceptedField(double m_norm, double dip, double dt);
  void FollowRejectedField(double m_norm, double dip, double dt);
  // FQA rows row0 .. row0 + rows − 1 of y_full behind a χ² gate (0 = off); false when gated.
  bool GatedFqaUpdate(int row0, int rows, const Eigen::Vector3d& y_full, double sigma, double gate);
  SensorUse DecoupledFqaUpdate(const Eigen::Vector3d& f_meas_B, const Eigen::Vector3d& m_meas_B,
                               const FqaSettings& fqa, SensorUse use);
  SensorUse PaperFqaUpdate(const Eigen::Vector3d& f_meas_B, const Eigen::Vector3d& m_meas_B,
                           const FqaSettings& fqa, SensorUse use);
  // Generic KF update on the error state; returns the NIS. Applies the correction.
  double Correct(const Eigen::MatrixXd& H, const Eigen::VectorXd& y, const Eigen::MatrixXd& R);
  void ApplyCorrection(const Eigen::Matrix<double, 9, 1>& dx);

  OrientationKfSettings settings_;
  bool initialized_ = false;
  double t_ = 0.0;
  Eigen::Vector4d q_EB_ = Eigen::Vector4d(1, 0, 0, 0);
  Eigen::Vector3d omega_B_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d bias_B_ = Eigen::Vector3d::Zero();
  Eigen::Vector4d q_IB_ = Eigen::Vector4d(1, 0, 0, 0);  // strapdown (gyro-only) attitude
  Eigen::Vector3d f_I_lp_ = Eigen::Vector3d::Zero();    // low-passed f in I [m/s²]
  // The second-order low-pass's past (direct form I): inputs R_IB f_B one and two steps back,
  // output two steps back (f_I_lp_ is the last output) [m/s²].
  Eigen::Vector3d f_I_in1_ = Eigen::Vector3d::Zero(), f_I_in2_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d f_I_out2_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d m_I_lp_ = Eigen::Vector3d::Zero();  // low-passed m in I
  Mat9 P_ = Mat9::Identity();
  MagHardIron hard_iron_;
  Counters counters_;
  double tilt_sigma_k_ = 0.0;  // this sample's tilt and heading σ [rad] (motion, evidence)
  double heading_sigma_k_ = 0.0;
  double last_tilt_nis_ = 0.0;
  double last_heading_nis_ = 0.0;
  bool last_accel_used_ = false;
  bool last_mag_used_ = false;
  Eigen::Vector3d last_mag_B_ = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  int still_count_ = 0;
  bool been_still_ = false;  // still() once since the start (the bias is then learned)
  double mag_ref_norm_ = 0.0;
  double mag_ref_dip_ = 0.0;
  int mag_ref_count_ = 0;
  double mag_rejected_time_ = 0.0;  // continuous rejection so far [s]
  double mag_cand_norm_ = 0.0;      // low-passed norm and dip of the rejected samples
  double mag_cand_dip_ = 0.0;
  double mag_norm_sum_ = 0.0;
  double mag_dip_sum_ = 0.0;
};

}  // namespace rcal::estimation
