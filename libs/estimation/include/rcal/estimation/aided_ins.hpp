// Tracker-aided inertial navigation (beyond the paper): the tool's attitude, velocity and position
// integrated from the IMU (strapdown) and corrected by the position sensor that tracks the tool's
// marker, in one error-state Kalman filter.
//
// Why. The orientation KF (orientation_kf.hpp) learns its tilt from the accelerometer low-passed
// in a strapdown frame, so it lets through part of every linear acceleration, and in fast rotation
// the gyro's scale and cross-axis errors bend its strapdown frame faster than the low-pass
// corrects it (README, BROAD: 0.7–1.2° RMS over 0.5 s windows). The position sensor measures what
// the accelerometer needs to become a gravity sensor at every sample: the marker's motion. A tilt
// error δθ leaves g·δθ in the gravity-compensated acceleration, which the positions see as a drift
// ½ g δθ t² (2 mm in 0.5 s at 0.1°): tilt becomes observable in any motion, and with it the gyro's
// bias, while the heading still needs another source.
//
// Frames and conventions (as OrientationKf and PositionKf): E the earth frame (NED or ENU, z
// vertical), B the IMU's body frame, M the marker, W the position sensor's frame (a tracker's own
// axes and origin). R_WE turns earth axes into the tracker's (SetWorldFromEarth; the identity until
// told, the position KF's default); the positions p_EB_E are in earth axes about W's origin, so
// the marker the tracker sees is p_WM_W = R_WE (p_EB_E + R_EB r_BM_B).
// q_EB [w,x,y,z] (Hamilton) body → earth; p_EB_E the IMU's position and v_EB_E its velocity [m,
// m/s], b_g,B [rad/s] and b_a,B [m/s²] the gyro and accelerometer biases, r_BM_B [m] the lever arm
// IMU → marker in the body frame. Gravity g_E = −g·up_E.
// Nominal state x = (R_EB, v, p, b_g, b_a, r, R_WE); error state δx (21) = [δθ_E, δv, δp, δb_g,
// δb_a, δr, δφ_W], the attitude error on the left in the earth frame, R_EB = Exp(δθ_E) R̂_EB
// (OrientationKf's convention), the tracker frame's on the left in W, R_WE = Exp(δφ_W) R̂_WE, the
// others additive: x = x̂ ⊞ δx (Boxplus). The frame is constant; its covariance is what
// SetWorldFromEarth is told (zero: known). A frame known only roughly is learned: its tilt from
// gravity, which the positions see in the tracker's axes, its heading from the magnetometer's
// heading against the heading the positions give (the tool accelerating sideways).
// IMU step over (t_{k−1}, t_k] with the sample at t_k (a sampled gyro's rate over the interval
// ending at its stamp, as OrientationKf):
//   ω = ω_m − b_g,   R_k = R_{k−1} Exp(ω Δt),
//   a_E = ½ (R_{k−1} (f_{k−1} − b_a) + R_k (f_k − b_a)) + g_E  (the specific force is a sample of
//   its instant, so its integral over the step is the trapezoid's; with f_k alone it lags half a
//   step, and gravity turning at |ω| in the body frame then leaves ½ g |ω| Δt: 0.1 m/s² at 2
//   rad/s), p_k = p + v Δt + ½ a_E Δt²,   v_k = v + a_E Δt.
// Its error transition Φ = ∂(x_k ⊟ x̂_k)/∂δx_{k−1} (TransitionJacobian, checked against finite
// differences in the tests), first order in Δt for the attitude:
//   δθ_k = δθ − R_k Δt δb_g,
//   δv_k = δv − [f_E]× Δt δθ − R̄ Δt δb_a + ½ [R_k f̃_k]× R_k J_r Δt² δb_g,
//          f_E = ½ (R_{k−1} f̃_{k−1} + R_k f̃_k), f̃ = f − b_a, R̄ = ½ (R_{k−1} + R_k),
//   δp_k = δp + Δt δv + ½ Δt (δv_k − δv),
// and P ← Φ P Φᵀ + Q, Q = diag((σ_g² + σ_θ²) Δt I, (λ σ_a² Δt + (c |Δf_E| Δt)²) I, 0, σ_bg² Δt I,
// σ_ba² Δt I, 0, 0), λ the accelerometer noise's adaptive factor and c |Δf_E| its weighting by
// motion (settings).
// Measurements (P ← P − K S Kᵀ with the optimal gain, symmetrised; M ≤ 3 rows each):
//   marker position  z = p_WM_W,  h = R_WE (p + R_EB r),
//                    H = [−R̂_WE [R̂ r̂]×, 0, R̂_WE, 0, 0, R̂_WE R̂, −[ĥ]×]  (behind a χ² gate on its
//                    3 dof; a gated sample is tried again under the accelerometer-shock
//                    hypothesis, P + Σ_s ⊗ I₃ on (δp, δv) with Σ_s the covariance of one axis's
//                    [δp, δv] that the force's changes since the last position taken may have made,
//                    Σ_s ← F Σ_s Fᵀ + diag(0, (κ |Δf_E| Δt)²), F = [1 Δt; 0 1], and taken if it
//                    then passes; after max_consecutive_rejections gated samples the next is taken
//                    with the position's and velocity's covariance grown, settings);
//                    a sample stamped within the last IMU step, τ = t_k − t ∈ [0, Δt_k], is the
//                    marker then: the step's constant acceleration a_E and rate ω taken back,
//                    h = R_WE (p − v τ + ½ a_E τ² + R_EB Exp(−ω τ) r), the same H with
//                    R_EB Exp(−ω τ) for R_EB and −τ R_WE on δv (a_E and ω as given: their own
//                    errors enter at O(τ²) and O(τ |r|));
//   tracker frame    another estimator's cumulative estimate of R_WE (the identifier's): only the
//                    information it gained since its previous one, H = I on δφ_W
//                    (UpdateWorldFromEarth);
//   heading          from another attitude source (the orientation KF, whose heading comes from
//                    the magnetometer): y = the angle about up_E of R_ref R̂_EBᵀ, H = e_zᵀ on δθ,
//                    σ heading_sigma. Only its heading is used: the tilt is this filter's own.
//   magnetometer     a field sample judged undisturbed elsewhere, levelled with this filter's
//                    attitude: y = the angle about E's z axis from the horizontal part of R̂ m_B to
//                    magnetic north, H = e_zᵀ on δθ, σ mag_heading_sigma. Levelled with this
//                    filter's tilt, not the orientation KF's, whose tilt error about north turns
//                    into tan(dip) times as much heading error.
// Initialisation: the first heading source's attitude and the first marker position (v = 0, its
// σ initial_velocity_sigma; p = R_WEᵀ z − R r, its covariance from the sensor's, the lever arm's
// and the frame's): until both have come the filter only keeps the time.
// Bad input (non-finite values, values beyond the sensor's range, time not increasing, a
// measurement not at the IMU's last time, a position not within the last IMU step) is refused with
// a Status naming the field and counted; the state is then unchanged. A state that still goes
// non-finite is never kept: the filter resets, counts it and initialises again.
#pragma once

#include <Eigen/Core>
#include <cstdint>

#include "rcal/estimation/fqa.hpp"
#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/estimation/position_kf.hpp"
#include "rcal/estimation/result.hpp"

namespace rcal::estimation {

/// Settings with defaults for a MEMS IMU and a 1 mm tracker; units in each comment.
struct AidedInsSettings {
  EarthFrame earth = EarthFrame::kNed;
  double gravity = 9.81;  ///< [m/s²]
  /// Gyro white noise density [rad/s/√Hz] and an extra attitude random walk for what the model
  /// leaves out (the gyro's scale and cross-axis errors, coning) [rad/√s].
  double gyro_noise_density = 3e-3;
  double attitude_process_noise = 1e-3;
  /// Accelerometer white noise density, with what the model leaves out (its lag, vibration the
  /// samples alias, scale errors) [m/s²/√Hz].
  double accel_noise_density = 0.05;
  /// The accelerometer's lag behind its stamps [s] (PositionKfSettings::accel_delay): a sample
  /// stamped t is the specific force of t − accel_delay, turned to the body of then. It is turned
  /// to the body at t with the rate and extrapolated to t along the previous sample. 0 = as
  /// stamped; at most kMaxAccelDelay.
  double accel_delay = 0.0;
  /// Time constant [s] of the accelerometer noise's adaptation to the position innovations
  /// (PositionKf's covariance matching): at each position sample, with a = Δt/τ ≤ 1,
  /// log λ ← log λ + a (min(NIS, 30)/3 − 1), λ in [1, accel_noise_max_scale], and the velocity's
  /// process noise is λ accel_noise_density² Δt. Real accelerometer errors grow with the motion
  /// (vibration the samples alias, taps, scale errors) by factors no constant density fits.
  /// 0 = off. 3 s is `rcal fuse-loo --ins`'s choice on BROAD, which the aided_ins process ships
  /// (README: it holds trial 27's vibration, whose aliased samples are otherwise taken for tilt).
  double accel_noise_adaptation_tau = 0.0;
  double accel_noise_max_scale = 1e4;  ///< [-]
  /// The accelerometer-shock hypothesis [-] (0 = off): σ of a step's specific-force integral as a
  /// fraction κ of the force's change across the step. A position the χ² gate refuses is tried
  /// again under the hypothesis that the integral went wrong since the last position taken: each
  /// step a velocity error of variance (κ |R_k f̃_k − R_{k−1} f̃_{k−1}| Δt)² per axis, carried into
  /// the position to now; the sample is taken when its NIS then passes the gate. The trapezoid
  /// takes the force as linear between samples; what it did in between is unknown by about that
  /// change. Where the samples are a smooth motion's the hypothesis explains little; where they
  /// alias a shock (a tap: 30–150 m/s² from one 10 ms sample to the next, while the tool's
  /// velocity changed by a fifth of what the samples integrate to) it explains the tracker, and
  /// the velocity takes the correction. A tracker's own outlier after smooth samples stays
  /// refused. 2 was `rcal fuse-loo --ins`'s choice on BROAD (README; 2–5 are alike there, 1 too
  /// little for its taps); with accel_change_sigma it changes nothing on the untapped trials, so
  /// its grid keeps it at 2 rather than let the fold without the tapped trial turn it off.
  double accel_shock_sigma = 2.0;
  /// The accelerometer weighted by motion [-] (0 = off): each step's velocity noise gains
  /// (c |R_k f̃_k − R_{k−1} f̃_{k−1}| Δt)² per axis, the step's specific-force integral uncertain by
  /// a fraction c of the force's change across it. The shock hypothesis's model (accel_shock_sigma)
  /// at every step and a fraction of its size: the trapezoid is exact for a force linear between
  /// samples, and what the force did in between (vibration the samples alias, a shock's ringing)
  /// goes with how much it changed. A constant density that covers a vibrating tool distrusts the
  /// calm one; this covers each step by its own motion. 0.1 is `rcal fuse-loo --ins`'s choice on
  /// BROAD, which the aided_ins process ships (README: with it every held-out fold keeps trial 27's
  /// phone vibration at or below VQF, where the adaptation above needs 27 among the trials it is
  /// chosen on).
  double accel_change_sigma = 0.0;
  /// Bias random walks: gyro [rad/s/√s], accelerometer [m/s²/√s].
  double gyro_bias_random_walk = 1e-4;
  double accel_bias_random_walk = 1e-3;
  /// Position sensor σ per axis [m] and the χ² gate on its 3-dof innovation (0 = off; 16.27 is
  /// the 0.999 quantile).
  double position_sigma = 1e-3;
  double position_gate_chi2 = 16.27;
  /// After this many consecutive gated position samples the next one is taken, ungated: the
  /// tracker agrees with itself and not with the integral, so the integral is what went wrong (a
  /// shock the accelerometer aliased, a tap). The velocity's covariance is first grown by
  /// initial_velocity_sigma² and the position's by the innovation's square, so the sample moves
  /// the position and velocity, not the attitude. (Starting the position and velocity again from
  /// the tracker instead, their cross-covariances dropped, turned the attitude by degrees on
  /// BROAD's trials 24, 27 and 33.) 0 = never (a tracker that jumps is then refused for good).
  int max_consecutive_rejections = 3;
  /// σ of one heading taken from the other attitude source [rad].
  double heading_sigma = 0.05;
  /// σ of one magnetometer heading [rad] (the orientation KF's heading_sigma on BROAD).
  double mag_heading_sigma = 0.15;
  /// Initial lever arm IMU → marker in the body frame [m] and its σ per axis [m] (0: known).
  Eigen::Vector3d lever_arm_B = Eigen::Vector3d::Zero();
  double lever_arm_sigma = 0.05;
  /// Initial σ: attitude [rad], velocity [m/s], gyro bias [rad/s], accelerometer bias [m/s²].
  double initial_attitude_sigma = 0.1;
  double initial_velocity_sigma = 0.3;
  double initial_gyro_bias_sigma = 0.01;
  double initial_accel_bias_sigma = 0.1;
  /// Plausibility: |gyro| per axis [rad/s], |specific force| per axis [m/s²] (OrientationKf's).
  double gyro_range = 40.0;
  double accel_range = 320.0;
  /// The longest IMU step integrated [s]: a longer gap re-initialises (the strapdown integral
  /// over it is no estimate).
  double max_step = 0.1;
};

/// The nominal state (header comment).
struct AidedInsState {
  Eigen::Matrix3d R_EB = Eigen::Matrix3d::Identity();
  Eigen::Vector3d v_EB_E = Eigen::Vector3d::Zero();    ///< [m/s]
  Eigen::Vector3d p_EB_E = Eigen::Vector3d::Zero();    ///< [m]
  Eigen::Vector3d b_g_B = Eigen::Vector3d::Zero();     ///< [rad/s]
  Eigen::Vector3d b_a_B = Eigen::Vector3d::Zero();     ///< [m/s²]
  Eigen::Vector3d r_BM_B = Eigen::Vector3d::Zero();    ///< [m]
  Eigen::Matrix3d R_WE = Eigen::Matrix3d::Identity();  ///< earth axes → the tracker's
};

/// The error state's dimension and its blocks' first rows (header comment's order).
inline constexpr int kAidedInsStates = 21;
using AidedInsVector = Eigen::Matrix<double, kAidedInsStates, 1>;
using AidedInsMatrix = Eigen::Matrix<double, kAidedInsStates, kAidedInsStates>;
using AidedInsRow3 = Eigen::Matrix<double, 3, kAidedInsStates>;

/// x ⊞ δx and its inverse y ⊟ x (header comment: attitude on the left, earth frame).
AidedInsState Boxplus(const AidedInsState& x, const AidedInsVector& dx);
AidedInsVector Boxminus(const AidedInsState& y, const AidedInsState& x);
/// One IMU step of Δt [s] with gyro ω_m [rad/s], the specific force at the step's start f_prev and
/// end f [m/s²] (body frame) and gravity g_E [m/s²]; its error transition Φ.
AidedInsState PropagateAidedIns(const AidedInsState& x, const Eigen::Vector3d& gyro_B,
                                const Eigen::Vector3d& f_prev_B, const Eigen::Vector3d& f_B,
                                const Eigen::Vector3d& g_E, double dt);
AidedInsMatrix AidedInsTransition(const AidedInsState& x, const Eigen::Vector3d& gyro_B,
                                  const Eigen::Vector3d& f_prev_B, const Eigen::Vector3d& f_B,
                                  double dt);
/// The marker in earth axes about W's origin, p_EM_E = p + R_EB r [m].
Eigen::Vector3d MarkerPosition(const AidedInsState& x);
/// The marker as the tracker sees it, p_WM_W = R_WE (p + R_EB r) [m], and its Jacobian on δx.
Eigen::Vector3d TrackerPosition(const AidedInsState& x);
AidedInsRow3 TrackerPositionJacobian(const AidedInsState& x);
/// The marker's velocity as the tracker sees it, v_WM_W = R_WE (v + R_EB (ω_B × r)) [m/s], with
/// ω_B the body's rate less the gyro bias [rad/s], and its Jacobian on δx (ω_B = ω_m − b_g: δb_g
/// turns it by −δb_g).
Eigen::Vector3d TrackerVelocity(const AidedInsState& x, const Eigen::Vector3d& omega_B);
AidedInsRow3 TrackerVelocityJacobian(const AidedInsState& x, const Eigen::Vector3d& omega_B);
/// The marker as the tracker saw it τ [s] before x's time, within an IMU step of rate ω_B [rad/s]
/// (bias removed) and constant acceleration a_E [m/s²] (gravity included): R_WE (p − v τ + ½ a_E
/// τ² + R_EB Exp(−ω_B τ) r), and its Jacobian on δx (ω_B and a_E as given). τ = 0: the above.
Eigen::Vector3d TrackerPositionBefore(const AidedInsState& x, double tau,
                                      const Eigen::Vector3d& omega_B, const Eigen::Vector3d& a_E);
AidedInsRow3 TrackerPositionBeforeJacobian(const AidedInsState& x, double tau,
                                           const Eigen::Vector3d& omega_B,
                                           const Eigen::Vector3d& a_E);

class AidedIns {
 public:
  struct Counters {
    std::int64_t imu_samples = 0;          ///< IMU steps integrated
    std::int64_t positions = 0;            ///< marker positions applied
    std::int64_t position_rejected = 0;    ///< refused by the χ² gate
    std::int64_t reanchored = 0;           ///< taken after max_consecutive_rejections
    std::int64_t shocks_taken = 0;         ///< gated, then taken as an accelerometer shock
    std::int64_t headings = 0;             ///< headings applied (UpdateHeading)
    std::int64_t frame_updates = 0;        ///< frame estimates applied (UpdateWorldFromEarth)
    std::int64_t frame_uninformative = 0;  ///< frame estimates without new information
    std::int64_t mag_headings = 0;         ///< magnetometer headings applied
    std::int64_t input_rejected = 0;       ///< refused calls (bad input, time)
    std::int64_t reinitialised = 0;        ///< IMU gaps beyond max_step
    std::int64_t resets = 0;               ///< state went non-finite: reset
  };

  /// Throws std::invalid_argument naming a setting outside its domain (a NaN, a negative σ, a
  /// zero time step, accel_delay beyond kMaxAccelDelay).
  explicit AidedIns(const AidedInsSettings& settings = {});
  /// Forgets the state and the counters (but `resets`); the tracker's frame as told (or as
  /// UpdateWorldFromEarth last gave it) stays.
  void Reset();

  /// One IMU sample at t [s] (strictly increasing): gyro ω_m [rad/s] and specific force f_B
  /// [m/s²], body frame.
  Status UpdateImu(double t, const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B);
  /// The tracker's frame: R_WE turns earth axes into its axes, with the covariance [rad²] of the
  /// rotation error δφ_W (R_WE = Exp(δφ_W) R̂_WE): zero, the frame is known; else it is learned
  /// (header comment). Before the first position only; refused (naming why) when R_WE is not a
  /// rotation or the covariance not a finite symmetric one with a non-negative diagonal.
  Status SetWorldFromEarth(const Eigen::Matrix3d& R_WE,
                           const Eigen::Matrix3d& covariance = Eigen::Matrix3d::Zero());
  /// A cumulative estimate of the tracker's frame from another estimator (the identifier, whose
  /// every estimate holds all its earlier ones' information): R_WE and its covariance [rad²].
  /// Only the information gained since the previous estimate (or since SetWorldFromEarth's frame)
  /// is applied, as a measurement of δφ_W, so the same data count once (the channel filter's
  /// decorrelation): with x the estimates about R̂_WE (x = Log(R R̂_WEᵀ)) and I = C⁻¹,
  ///   ΔI = I_k − I_{k−1},  z = ΔI⁻¹ (I_k x_k − I_{k−1} x_{k−1}),  R_z = ΔI⁻¹,  H = I on δφ_W.
  /// An estimate that carries no new information (ΔI not positive definite: the other estimator
  /// forgot some, or said the same) is applied as nothing and becomes the reference for the next.
  /// Refused (naming why) before initialisation (SetWorldFromEarth is the frame then), for a frame
  /// told as known exactly (zero covariance), and for a non-rotation or a covariance that is not
  /// finite, symmetric and positive definite.
  Status UpdateWorldFromEarth(const Eigen::Matrix3d& R_WE, const Eigen::Matrix3d& covariance);
  /// The marker's position p_WM_W [m] in the tracker's frame, measured at t [s]: the IMU's last
  /// sample time, or within the step that ended there (t_{k−1} ≤ t ≤ t_k; a tracker's stamps
  /// need not fall on the IMU's). Apply each position after the first IMU sample at or after
  /// its time (AidedInsNode orders the streams so); an older one is refused, naming the step.
  Status UpdatePosition(double t, const Eigen::Vector3d& p_WM_W);
  /// Another source's attitude q_EB [w,x,y,z] at t (the IMU's last sample time): its heading
  /// about up_E is applied; before initialisation its whole attitude is the initial one.
  Status UpdateHeading(double t, const Eigen::Vector4d& q_EB_ref);
  /// The magnetic field m_B [any unit] at t (the IMU's last sample time), a sample already judged
  /// undisturbed (OrientationKf::last_mag_B): levelled with this filter's attitude, its heading
  /// against magnetic north (MagneticNorth) is applied, σ mag_heading_sigma. Refused before
  /// initialisation and where the field is nearly vertical (less than 10 % of it horizontal).
  Status UpdateMagnetometer(double t, const Eigen::Vector3d& m_B);

  bool initialized() const { return initialized_; }
  const AidedInsState& state() const { return x_; }
  /// q_EB [w,x,y,z], sign continuous from sample to sample.
  const Eigen::Vector4d& q_EB() const { return q_EB_; }
  /// The marker's position in the tracker's frame, p_WM_W [m].
  Eigen::Vector3d p_WM_W() const { return TrackerPosition(x_); }
  /// The marker's velocity in the tracker's frame, v_WM_W [m/s] (TrackerVelocity with the last
  /// step's rate).
  Eigen::Vector3d v_WM_W() const { return TrackerVelocity(x_, step_omega_B_); }
  /// The covariance of [p_WM_W; v_WM_W] [m², m²/s, m²/s²], J P Jᵀ with J their Jacobians (the
  /// gyro's noise on the last step's rate left out).
  Eigen::Matrix<double, 6, 6> marker_covariance() const;
  /// The tracker's frame R_WE as estimated (as told when its covariance is zero).
  const Eigen::Matrix3d& R_WE() const { return x_.R_WE; }
  /// Error-state covariance (21×21, header comment's order and units).
  const AidedInsMatrix& P() const { return P_; }
  /// The accelerometer noise's adaptive factor λ [-] (1 when the adaptation is off).
  double accel_noise_scale() const { return accel_noise_scale_; }
  /// Normalised innovation squared of the last position sample (3 dof).
  double last_position_nis() const { return last_position_nis_; }
  const Counters& counters() const { return counters_; }
  const AidedInsSettings& settings() const { return settings_; }

 private:
  Status Refuse(const std::string& why);
  // Reset, the last IMU time kept (the next sample then steps from it).
  void ResetKeepingTime();
  Status CheckMeasurementTime(double t, const char* what);
  void TryInitialise();
  // A heading innovation y [rad] about E's z axis with σ [rad].
  void CorrectHeading(double y_rad, double sigma_rad);
  // KF update on δx; returns the NIS (NaN: not applied, the state went non-finite).
  template <int M>
  double Correct(const Eigen::Matrix<double, M, kAidedInsStates>& H,
                 const Eigen::Matrix<double, M, 1>& y, const Eigen::Matrix<double, M, M>& R,
                 double gate_chi2, bool* gated);
  void Commit();

  AidedInsSettings settings_;
  Eigen::Vector3d g_E_;
  bool initialized_ = false;
  bool has_time_ = false;
  double t_ = 0.0;
  bool has_attitude_ = false, has_position_ = false;
  Eigen::Matrix3d R_init_ = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p_init_ = Eigen::Vector3d::Zero();  // the first marker position, W [m]
  // The frame as told, or the other estimator's latest, and its covariance: what a
  // re-initialisation starts from.
  Eigen::Matrix3d R_WE_ = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R_WE_covariance_ = Eigen::Matrix3d::Zero();
  // The other estimator's last frame estimate and its covariance (UpdateWorldFromEarth).
  Eigen::Matrix3d R_WE_reference_ = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R_WE_reference_covariance_ = Eigen::Matrix3d::Zero();
  Eigen::Vector3d f_prev_B_ = Eigen::Vector3d::Zero();  // the last specific force, lag removed
  Eigen::Vector3d f_then_B_ = Eigen::Vector3d::Zero();  // the last sample turned to its time t − δ
  double accel_noise_scale_ = 1.0;
  // The last integrated step: its length [s], rate ω_B less the bias [rad/s] and constant
  // acceleration in E, gravity included [m/s²] (a position within it is taken back along it).
  double step_dt_ = 0.0;
  Eigen::Vector3d step_omega_B_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d step_a_E_ = Eigen::Vector3d::Zero();
  double last_position_t_ = 0.0;
  bool has_last_position_t_ = false;
  AidedInsState x_;
  Eigen::Vector4d q_EB_ = Eigen::Vector4d(1, 0, 0, 0);
  AidedInsMatrix P_ = AidedInsMatrix::Identity();
  double last_position_nis_ = 0.0;
  int consecutive_rejections_ = 0;
  // The accelerometer-shock hypothesis since the last position taken (settings): the covariance
  // of one axis's [δp, δv] its force changes may have made [m², m²/s, m²/s²].
  Eigen::Matrix2d shock_covariance_ = Eigen::Matrix2d::Zero();
  Counters counters_;
};

/// One IMU sample into the INS after the orientation KF has taken it (its Update at the same t,
/// accepted): the IMU step, then a heading: the KF's attitude until the INS has started, and
/// always with heading_from_kf; else the field the KF's heading row accepted
/// (OrientationKf::last_mag_B), levelled with the INS's own tilt (none while it has accepted
/// none). What `rcal fuse` and the aided_ins process run, so that both give the same estimates.
/// Returns the IMU step's status; a refused heading is counted in the INS and not an error here.
Status StepAfterOrientationKf(AidedIns& ins, const OrientationKf& okf, double t,
                              const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B,
                              bool heading_from_kf);

}  // namespace rcal::estimation
