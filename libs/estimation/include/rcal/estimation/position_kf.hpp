// Position Kalman filter (the paper's Section 3.4, Eqs. 24–31, errata from
// ../shared/paper/NOTES.md applied): position, velocity and acceleration per axis, observed by a
// position sensor and by the accelerometer rotated into the earth frame.
//
// Frame convention (one, used everywhere in this filter): all states and the position sensor
// are in the position sensor's frame W. The orientation estimate is in the earth frame E (NED or
// ENU, z vertical, as OrientationKf); the accelerometer's specific force f_B is rotated with it,
// gravity is removed in E, and the result is turned into W:
//   a_W = R_WE (R_EB f_B + g_E),   g_E = −g · up_E   (g_E = [0,0,+g] in NED, [0,0,−g] in ENU).
// This settles the NOTES.md erratum on Eqs. 25/29 (NED stated, gravity removed as if z were up).
// R_WE (world ← earth, SetWorldFromEarth) is the identity until told: the paper's W = E. A
// tracker turned against the earth frame (any real one) needs it, or every acceleration enters
// turned by that angle; gravity is removed before the turn, so an error δ in R_WE costs only
// δ × the tool's own acceleration, never δ × g.
//
// State (Eq. 27 order): x = [p_x, V_x, A_x, p_y, V_y, A_y, p_z, V_z, A_z], with p_WM_W [m] the
// marker position, V [m/s], A [m/s²] its acceleration, all in W. The paper's A is the
// body-frame acceleration with M_H2S in Φ (Eq. 28) and gravity as an input (Eq. 29); taking A in
// W instead moves the rotation and gravity into the accelerometer measurement, and Φ becomes
// the same constant-acceleration block per axis (PaperPhiPos() gives the paper's form, with
// the row-7 erratum: p_z does not depend on V_y):
//   Φ_axis = [1 Δt Δt²/2; 0 1 Δt; 0 0 1],   x⁻ = Φ x,   P⁻ = Φ P Φᵀ + Q,
//   Q_axis = q_j [Δt⁵/20 Δt⁴/8 Δt³/6; Δt⁴/8 Δt³/3 Δt²/2; Δt³/6 Δt²/2 Δt]  (white jerk, Eq. 30)
// Measurements (H′ of Eq. 31, missing in the text): the position sensor observes p
// (H = rows of p), the accelerometer observes A (H = rows of A).
// Lever arm (beyond the paper): the IMU is not at the marker. With r_B the IMU → marker
// vector in the body frame [m], p_M = p_I + R_WB r_B (R_WB = R_WE R_EB), so the marker's
// acceleration is
//   A = ä_I + R_WB ([α_B]× + [ω_B]×²) r_B,   ä_I = R_WE (R_EB f_B + g_E) (the accelerometer's),
// ω_B the body rate [rad/s] (UpdateAccel's omega_B) and α_B its derivative, differenced between
// accelerometer updates. The accelerometer's measurement is then z = R_WE (R_EB f_B + g_E) with
// h = A − R_WB M r_B, M = [α_B]× + [ω_B]×². With estimate_lever_arm r_B joins the state
// (constant; initial value lever_arm_B, σ lever_arm_sigma) and is observed whenever the body
// turns; otherwise lever_arm_B is taken as known (zero: the paper's filter).
// Acceleration bias (beyond the paper): an orientation error δθ leaves g × δθ in every
// gravity-compensated acceleration (0.07 m/s² at 7 mrad of tilt), and it is not white: it changes
// as slowly as the orientation error does. Counted as white accelerometer noise (accel_sigma) it
// forces a large σ, and the acceleration between position samples then rests on the jerk model
// alone. With accel_bias_walk > 0 a world-frame bias b_W [m/s²] joins the state as a random walk
// (σ accel_bias_walk √Δt), h gains + b_W, and the position sensor, which sees its double integral,
// makes it observable; accel_sigma can then be the accelerometer's own noise.
// Motion model (MotionModel): the paper's white jerk (Eq. 30) puts q_j² into p and V as well as
// A over each step (V gains q_j² Δt³/3), so between position samples the velocity wanders by the
// jerk model however well the accelerometer pins A: with q_j = 50 that is 3 cm/s per 10 ms step.
// kAccelerometerDriven lets A move between accelerometer samples along a ramp: its increment ΔA
// over a step is white (variance q_j² Δt), and p and V take the ramp's share of it (ΔA Δt²/6 and
// ΔA Δt/2), so Q_axis = q_j² Δt g gᵀ with g = (Δt²/6, Δt/2, 1), of rank one. A is free to follow
// each accelerometer sample, and p and V integrate it with no noise of their own: a strapdown
// integration of the accelerometer written in Eq. 27's state. The next sample's update of A
// moves p and V by the ramp's shares too, so the integration is the trapezoid's (a
// piecewise-linear acceleration), not the rectangle's (each sample held over its step, which
// lags the motion by half a step: with it, BROAD's fast trials 07 and 08 were 2.08 and 2.12 mm
// in the bank, against 1.87 and 2.00 mm with the trapezoid; every given trial is closer). It needs
// the accelerometer's stream (without it A's variance still grows, reaching p and V one step later)
// and, because the accelerometer's errors then reach the position unfiltered, the bias state.
// The two belong together: z = A + b_W separates A from b_W only through the position sensor
// and the rates at which each may change; under white jerk with a small q_j a change of the
// tool's acceleration is as well explained by the bias, which takes it and the position runs off
// (measured on the simulated cells: tens of mm at accel_bias_walk 0.2, q_j 0.1). With A driven
// by the accelerometer, b_W is learned from the position sensor alone. It trusts its
// accelerations, so real errors that grow with the motion (BROAD's fast and vibrating trials)
// make it run off where the paper's filter holds: the default stays the paper's (README).
// SetWorldFromEarth's covariance keeps it from trusting a frame it does not know.
// Motion-proportional accelerometer noise (beyond the paper; accel_relative_sigma): an orientation
// error δθ turns the measured acceleration, δa = δθ × a_W, a scale error scales it, a time offset
// δt adds ȧ δt: errors that grow with the motion, which the bias state (slow) and accel_sigma
// (constant) cannot take. Each acceleration's variance is accel_sigma² + (σ_rel |a_W|)² per axis
// (a_W the measured world acceleration, gravity removed): σ_rel is the relative error, e.g. 0.1
// for an orientation error of 0.1 rad or a 10 % scale error.
// Adaptive accelerometer noise (beyond the paper; accel_noise_adaptation_tau > 0): on real data
// the accelerometer's errors grow with the motion (the orientation's error turns the tool's own
// acceleration, a time offset meets the jerk, 100 Hz resampling aliases vibration and taps), by
// factors no constant σ fits: sized for the calm phases, a fast one makes the position
// innovations exceed the gate, the filter refuses the sensor that would correct it and runs off
// (BROAD: to 0.5 m); sized for the fast ones, the calm ones are no better than the tracker. So a
// factor λ ≥ 1 scales the accelerometer's variance accel_sigma² and the jerk PSD q_j² (both stand
// for what the motion model leaves out, which grows together), and follows the position
// innovations by covariance matching: at each position sample (gated or not), with a = Δt/τ (≤ 1),
//   log λ ← log λ + a (min(NIS, 30)/3 − 1),   λ clamped to [1, accel_noise_max_scale],
// a stochastic-approximation step toward E[NIS] = 3, the innovation's dimension: λ stays at 1
// while the innovations are as the model predicts, grows within a few samples when they are
// larger, and returns as fast when the motion calms. The cap 30 bounds what one glitch can do
// (λ × e^{9a} at most). Mehra's covariance matching (IEEE TAC 1972) in the form of a single
// scale, as fading-memory filters use it. Update as
// NOTES.md Eqs. 15–17, Joseph form. The position sensor is χ²-gated: NIS = yᵀS⁻¹y >
// position_gate_chi2 rejects it (counted), unless the adaptation is on and λ at its cap: having
// given up on the prediction, it has no reference by which to call a sample an outlier, so the
// sample re-initialises the position (Counters::reinitialised; in BROAD trial 16's shaking the
// accelerometer-driven model ran metres off while one sample in a few still passed the gate and
// kept max_consecutive_rejections from being reached). Its velocity then starts at the mean v̄
// over the interval from the position sample before, σ² = 2 σ_p² / Δt² + initial_velocity_sigma²
// + v̄² per axis: the motion that made the adaptation give up is seldom at rest (started at rest in
// trial 16's shaking, the marker at up to 7 m/s, the re-initialised filter was 20–40 mm off 10 ms
// later, every time), and v̄ is as uncertain as it is large (a jump of the marker, which is no
// motion, gives as large a mean: the next sample then outweighs it).
// So is the accelerometer gated when accel_gate_chi2 > 0 (its
// innovation against the predicted acceleration: a tap or shock the motion cannot have, which
// the adaptive noise would otherwise take in, is skipped). Bad input and out-of-order time are
// refused with a Status; the state is unchanged. A state that goes non-finite anyway is never kept:
// the filter resets (Counters::resets) and the update returns an Error saying so; the next position
// sample initialises it again.
// Taking back a bad stretch of the accelerometer (beyond the paper; accel_rollback_span): a tap or
// a shock rings the accelerometer at tens of m/s² for tens of milliseconds while the tool hardly
// moves (BROAD's tapping trial: 30–70 m/s² over 80 ms). Once λ has grown, the per-sample gate lets
// such samples in, and their integral puts metres per second into V: the position ran 210 mm off
// before a position sample could stop it. A position sample that comes in the middle of a tap may
// still pass, and V, which one position sample cannot fix, then carries the error on until the
// next sample is refused for it. So at each position sample the filter as it stands (every
// accelerometer sample right) is compared with the hypotheses that the accelerometer was wrong
// over the last j intervals (those that began within accel_rollback_span of now, at least the
// last one): the state after the position sample j back, run to now by the motion model alone
// with the position samples since re-applied (each behind the gate). The likeliest hypothesis for
// this sample is taken when 2 ln Λ = NIS₀ − NIS_j + ln(det S₀ / det S_j) in its favour exceeds
// position_gate_chi2 (the gate's χ² quantile, here as a likelihood-ratio test). Its intervals'
// accelerometer samples are counted as taken back (Counters), the states kept for later
// rollbacks are the re-run's, and the sample, its NIS, the adaptation and the bank's evidence are
// those of the state kept. The accelerometer-driven model's re-run holds A (no process noise on
// p, V and A over it): the knock was no motion, and the motion over the span is the one before
// it, continued. Left free to wander (its ramp noise, which stands for the motion between
// samples, not for no samples at all), A was set by the re-applied position samples and V with
// it through the ramp, confidently and wrongly, and the gates then kept that state (BROAD's
// tapping trial: that model alone 315 mm with the trapezoid, 6.2 mm with A held; the white-jerk
// model, whose jerk noise is its motion model, re-runs with it: held, 3.5 → 4.9 mm). A position
// outlier is no reason to roll back: without the accelerometer the prediction explains it no
// better.
// The mirror case: the onset of a real, violent motion (BROAD's fast translation B: a shaking
// from 20 to 94 m/s² within 40 ms) looks to the accelerometer's gate like a tap, and the refused
// samples' integral, metres per second the tool did have, is missing: both bank models ran
// 20–130 mm off for 0.15 s. So the hypotheses also include that the accelerometer was right over
// the last j intervals, its refused samples with the others: the state after the position sample
// j back, run to now with every accelerometer sample since applied, ungated (the position samples
// re-applied behind the gate). Such a stretch starts where the gate refused a sample, and takes
// every sample since, taken back or not (the onset, taken back as a tap at the first position
// sample, is shown a motion by the next). Taken on the same test, its samples not applied are
// counted as reinstated (Counters), and a later rollback may take them back as any other. Where
// the gate refused nothing none is tried, so a filter without the accelerometer's gate is as it
// was, cost included. A tap is not reinstated: its integral is a move the positions did not make.
// Cost: no hypothesis can make a sample likelier than N(0; 0, R) (NIS 0, S = R), so while
// the sample is within the test's margin of that bound, none is tried: every sample of a calm run.
// Otherwise up to 2 kMaxRollbackPoints re-runs of a few predictions, accelerometer updates and
// 3×3 solves.
// The accelerometer's lag (beyond the paper; accel_delay δ): a sample stamped t is the specific
// force of t − δ (the sensor's internal low-pass; the magnetometer's is OrientationKf's
// mag_delay). Taken as stamped, the filter's acceleration is δ behind the tool's, an error of the
// jerk times δ (BROAD's fast translation: jerks of 100 m/s³, and the accelerometer agrees with the
// optical truth's acceleration to 0.43 m/s² as stamped, 0.23 m/s² read 2.3 ms earlier). So each
// sample is first put in the earth frame with the attitude of its own time, R_EB(t − δ) =
// R_EB Exp(−ω_B δ), z(t − δ) = R_WE (R_EB Exp(−ω_B δ) f_B + g_E), and then extrapolated to t
// along the line through the previous sample's, z = z(t − δ) + δ (z(t − δ) − z(t′ − δ)) / (t − t′)
// (t′ the previous sample's stamp; exact for a ramp, and causal). Its noise, two white samples
// weighted 1 + κ and −κ with κ = δ / (t − t′), is the accelerometer's variance times
// (1 + κ)² + κ². After a gap of more than kMaxAccelExtrapolationStep, at the first sample and after
// one the accelerometer's gate refused (a tap: extrapolated along it, the next sample would ring
// by −κ times the tap), the sample is taken at z(t − δ) unextrapolated.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <vector>

#include "rcal/estimation/fqa.hpp"
#include "rcal/estimation/result.hpp"

namespace rcal::estimation {

/// The paper's Φ_pos (Eq. 28) for the state of Eq. 27 with body-frame acceleration A, the
/// rotation M_H2S = R_EB (tool → local frame) and sampling time t [s], with the NOTES.md
/// erratum (row 7: no t in the V_y column). The matching input is PaperGammaPos().
Eigen::Matrix<double, 9, 9> PaperPhiPos(const Eigen::Matrix3d& M, double t);
/// Γ_pos u (Eq. 29): gravity g [m/s²] removed along z as the paper writes it (z up).
Eigen::Matrix<double, 9, 1> PaperGammaPos(double g, double t);

/// Most intervals between position samples whose accelerometer one sample can take back (the
/// bound on accel_rollback_span's cost at high position rates).
inline constexpr int kMaxRollbackPoints = 8;

/// Most accelerometer samples kept after one position sample for the rollback's hypotheses (the
/// bound on their memory, about 0.5 MB a point, when the position sensor stops while the IMU
/// streams). Beyond it the samples are counted but not kept, and no stretch that holds them is
/// reinstated (at 100 Hz such a gap is 10 s, far beyond any span a rollback reaches).
inline constexpr int kMaxKeptAccelSamples = 1024;

/// The longest step between accelerometer samples over which accel_delay extrapolates [s].
inline constexpr double kMaxAccelExtrapolationStep = 0.1;

/// How the white-jerk noise enters the state (header comment).
enum class MotionModel {
  kWhiteJerk,            ///< the paper's Eq. 30: p, V and A, correlated
  kAccelerometerDriven,  ///< A's ramp between samples: p and V integrate the accelerometer
                         ///< (trapezoid)
};

struct PositionKfSettings {
  EarthFrame earth = EarthFrame::kNed;
  double gravity = 9.81;  ///< [m/s²]
  /// White-jerk PSD driving A (paper's w′, Eq. 30) [m/s³/√Hz].
  double jerk_noise = 50.0;
  /// Where the jerk noise enters (header comment): the paper's white jerk, or A's ramp.
  MotionModel motion_model = MotionModel::kWhiteJerk;
  /// Standard deviation of one earth-frame acceleration measurement [m/s²] (accelerometer
  /// noise plus g times the orientation error).
  double accel_sigma = 0.3;
  /// Standard deviation of one position-sensor sample, per axis [m].
  double position_sigma = 1e-3;
  /// χ² gate on the 3-dof position innovation (0 = off). 16.27: 0.999 quantile.
  double position_gate_chi2 = 16.27;
  /// After this many consecutive gated position samples the filter re-initialises its position
  /// on the next one (a real jump, not a glitch) [-]. 0 = never.
  int max_consecutive_rejections = 20;
  double initial_velocity_sigma = 0.5;  ///< [m/s]
  double initial_accel_sigma = 5.0;     ///< [m/s²]
  /// IMU → marker vector r_B in the body frame [m] (the initial value when estimated).
  Eigen::Vector3d lever_arm_B = Eigen::Vector3d::Zero();
  /// Estimate r_B as three constant states (see the header comment).
  bool estimate_lever_arm = false;
  /// Initial σ of each component of r_B when estimated [m].
  double lever_arm_sigma = 0.2;
  /// Random walk of the world-frame acceleration bias b_W [m/s²/√s] (see the header comment).
  /// 0 = no bias state (the paper's filter).
  double accel_bias_walk = 0.0;
  /// Initial σ of each component of b_W when it is estimated [m/s²].
  double initial_accel_bias_sigma = 0.2;
  /// The part of the accelerometer's error that grows with the tool's own acceleration [-]:
  /// σ_rel |a_W| per axis joins accel_sigma in quadrature (see the header comment). 0 = none.
  double accel_relative_sigma = 0.0;
  /// Time constant [s] of the accelerometer noise's adaptation to the position innovations (see
  /// the header comment); 0 = off (the paper's constant σ).
  double accel_noise_adaptation_tau = 0.0;
  /// Largest factor λ on accel_sigma² and q_j² [-] (1e4: σ × 100).
  double accel_noise_max_scale = 1e4;
  /// χ² gate on the 3-dof accelerometer innovation (the measured world acceleration against the
  /// predicted one, under its predicted covariance); 0 = off. A sample beyond it (a tap, a
  /// shock the 100 Hz samples alias) is skipped and counted in accel_rejected.
  double accel_gate_chi2 = 0.0;
  /// How far back the accelerometer may be taken back when a position sample shows it wrong
  /// (see the header comment: a shock or tap the per-sample gate let in) [s]: the intervals
  /// between position samples that began within this span (always the last one; at most
  /// kMaxRollbackPoints). 0 = off. Needs the position gate (its χ² quantile is the test's).
  double accel_rollback_span = 0.3;
  /// The accelerometer's lag behind its stamps [s] (see the header comment): a sample stamped t
  /// is the specific force of t − accel_delay (a MEMS accelerometer low-passes internally; BROAD's
  /// reads ≈ 2.3 ms behind its optical truth). Each sample is turned back to the body's attitude
  /// of then and extrapolated to t along the last two samples. 0 = taken as stamped; at most
  /// kMaxAccelDelay (the constructor refuses more, a negative or a non-finite value).
  double accel_delay = 0.0;
};

/// The largest accel_delay the filter takes [s]: beyond it the extrapolation is no estimate.
inline constexpr double kMaxAccelDelay = 0.05;

/// The accelerometer-driven filter's settings (position_kf --motion-model accelerometer-driven;
/// the defaults above are the paper's filter): MotionModel::kAccelerometerDriven,
/// accel_bias_walk 0.1 m/s²/√s, accel_sigma 0.1 m/s². Chosen as the minimax over simulated
/// cells, tracker rates, lever arms, a navigation-grade and a consumer-grade IMU (rcal
/// position-kf-sweep reruns it). Too small a bias walk or σ is a cliff (the bias cannot follow
/// the orientation's error), too large a gentle slope, hence the larger side. On BROAD's real
/// fast-motion and vibration trials no σ or walk of this filter holds (README): the paper's
/// filter stays the default.
PositionKfSettings AccelerometerDrivenSettings();

class PositionKf {
 public:
  struct Counters {
    std::int64_t accel_samples = 0;         ///< accelerometer updates applied
    std::int64_t position_samples = 0;      ///< position samples accepted
    std::int64_t position_rejected = 0;     ///< position samples rejected by the χ² gate
    std::int64_t accel_rejected = 0;        ///< accelerometer samples rejected by its χ² gate
    std::int64_t input_rejected = 0;        ///< refused calls (bad input, time order)
    std::int64_t reinitialised = 0;         ///< re-initialisations (rejections, or λ at its cap)
    std::int64_t accel_rollbacks = 0;       ///< intervals whose accelerometer was taken back
    std::int64_t accel_rolled_back = 0;     ///< accelerometer samples taken back in them
    std::int64_t accel_reinstatements = 0;  ///< times refused accelerometer samples were
                                            ///< reinstated (header comment)
    std::int64_t accel_reinstated = 0;      ///< refused accelerometer samples reinstated
    std::int64_t resets = 0;                ///< state went non-finite: reset (kept by Reset)
  };

  explicit PositionKf(const PositionKfSettings& settings = {});
  /// Forgets the state and the counters (but `resets`); R_WE is kept.
  void Reset();

  /// Accelerometer sample at t [s] (not before the last update): specific force f_B [m/s²] in
  /// the body frame, the orientation estimate R_EB (body → earth) at t and the body rate
  /// omega_B [rad/s] (for the lever arm; zero: no rotation). Before the first position sample
  /// the filter is not initialised and the sample is ignored (Ok).
  Status UpdateAccel(double t, const Eigen::Vector3d& f_B, const Eigen::Matrix3d& R_EB,
                     const Eigen::Vector3d& omega_B = Eigen::Vector3d::Zero());

  /// Position-sensor sample p_WM_W [m] at t [s] (not before the last update). The first one
  /// initialises the filter. Returns Ok also when gated (see last_position_accepted()).
  Status UpdatePosition(double t, const Eigen::Vector3d& p_WM_W);

  /// The position sensor's frame W against the orientation's earth frame E: R_WE (earth →
  /// world), a rotation, and the covariance [rad²] of its error as a rotation vector on the left
  /// in W (R_WE,true = Exp(δφ_W) R_WE; zero: known). Takes effect from the next accelerometer
  /// sample; the state (already in W) is kept. An uncertain frame adds [a]× Σ [a]×ᵀ to each
  /// acceleration's noise (a = the measured a_W; first order in δφ): an acceleration turned by an
  /// unknown angle says only its size. Refused (counted in input_rejected, nothing changed) when
  /// R_WE is not finite or not a rotation (|R Rᵀ − I| > 1e-6 or det < 0), or the covariance is
  /// not finite, not symmetric or has a negative diagonal.
  Status SetWorldFromEarth(const Eigen::Matrix3d& R_WE,
                           const Eigen::Matrix3d& covariance = Eigen::Matrix3d::Zero());
  const Eigen::Matrix3d& R_WE() const { return R_WE_; }
  const Eigen::Matrix3d& R_WE_covariance() const { return R_WE_covariance_; }

  bool initialized() const { return initialized_; }
  double t() const { return t_; }
  /// Position p_WM_W [m], velocity [m/s] and acceleration [m/s²], all in the position sensor's
  /// frame W.
  Eigen::Vector3d p_WM_W() const;
  Eigen::Vector3d v_W() const;
  Eigen::Vector3d a_W() const;
  /// State x in Eq. 27 order and its covariance (without the lever arm and the bias).
  Eigen::Matrix<double, 9, 1> x() const { return x_.head<9>(); }
  Eigen::Matrix<double, 9, 9> P() const { return P_.topLeftCorner<9, 9>(); }
  /// IMU → marker lever arm r_B [m] (body frame) and its covariance [m²] (zero when known).
  Eigen::Vector3d lever_arm_B() const { return x_.segment<3>(kLever); }
  Eigen::Matrix3d lever_arm_covariance() const { return P_.block<3, 3>(kLever, kLever); }
  /// World-frame acceleration bias b_W [m/s²] and its covariance [m²/s⁴] (zero when
  /// accel_bias_walk is 0).
  Eigen::Vector3d accel_bias_W() const { return x_.segment<3>(kBias); }
  Eigen::Matrix3d accel_bias_covariance() const { return P_.block<3, 3>(kBias, kBias); }
  /// Covariance of p_WM_W [m²].
  Eigen::Matrix3d position_covariance() const;
  /// Covariance of [p_WM_W; v_W], 6×6 [m², m²/s, m²/s²] (TOOL_POSITION's).
  Eigen::Matrix<double, 6, 6> position_velocity_covariance() const;
  double last_position_nis() const { return last_position_nis_; }
  /// ln N(y; 0, S) of the last position sample's innovation y under its predicted covariance S,
  /// gated or not (0 for the sample that initialised the filter): how well this filter predicted
  /// it (PositionKfBank weighs its filters by it).
  double last_position_log_likelihood() const { return last_position_log_likelihood_; }
  /// The adaptive factor λ on the accelerometer's variance and the jerk PSD [-] (1 when the
  /// adaptation is off or the innovations are as predicted).
  double accel_noise_scale() const { return accel_noise_scale_; }
  bool last_position_accepted() const { return last_position_accepted_; }
  /// Accelerometer samples kept for the rollback's hypotheses [-]: those since the oldest position
  /// sample a rollback may reach, at most kMaxKeptAccelSamples after each.
  int kept_accel_samples() const;
  const Counters& counters() const { return counters_; }
  const PositionKfSettings& settings() const { return settings_; }

  /// World-frame acceleration a_W = R_WE (R_EB f_B − g·up_E) [m/s²] (what the accelerometer
  /// update uses).
  Eigen::Vector3d WorldAcceleration(const Eigen::Vector3d& f_B, const Eigen::Matrix3d& R_EB) const;

 private:
  // State: the 9 of Eq. 27, then r_B (3; constant, uncertain only when estimated), then b_W (3;
  // a random walk, zero and certain when accel_bias_walk is 0).
  static constexpr int kLever = 9;
  static constexpr int kBias = 12;
  static constexpr int kN = 15;
  using MatN = Eigen::Matrix<double, kN, kN>;
  using VecN = Eigen::Matrix<double, kN, 1>;
  void PredictTo(double t);
  // The motion model's prediction of (x, P) over dt [s] (λ included); hold_acceleration: no
  // process noise on p, V and A (the accelerometer-driven model's rollback hypotheses).
  void Predict(VecN& x, MatN& P, double dt, bool hold_acceleration = false) const;
  // ln N(y; 0, S) and the NIS of a position sample p against the prediction (x, P).
  struct PositionInnovation {
    Eigen::Vector3d y;
    Eigen::Matrix3d S_inv;
    double nis = 0.0, log_likelihood = 0.0;
  };
  PositionInnovation Innovation(const VecN& x, const MatN& P, const Eigen::Vector3d& p) const;
  // accel_rollback_span, with room for the rounding of time stamps [s].
  double RollbackReach() const;
  // The position sample's update of (x, P), Joseph form.
  void ApplyPosition(VecN& x, MatN& P, const PositionInnovation& in) const;
  // After a position sample p at t_: the state the next ones may roll back to.
  void KeepRollbackPoint(const Eigen::Vector3d& p);
  // The accelerometer's measurement as UpdateAccel built it, kept for the rollback's hypotheses.
  struct AccelSample {
    double t = 0.0;
    Eigen::Vector3d z = Eigen::Vector3d::Zero();
    Eigen::Matrix<double, 3, kN> H = Eigen::Matrix<double, 3, kN>::Zero();
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    bool applied = false;  // false: refused by the gate, or taken back
    bool gated = false;    // refused by the gate when it came
  };
  // The accelerometer update of (x, P) with one sample, its innovation y and S⁻¹, Joseph form.
  void ApplyAccel(VecN& x, MatN& P, const AccelSample& a, const Eigen::Vector3d& y,
                  const Eigen::Matrix3d& S_inv) const;
  // The accelerometer of the last intervals taken back, or its refused samples reinstated, when
  // the position sample p at t shows it wrong (header comment); `in` is the sample's innovation,
  // replaced when a hypothesis is taken.
  void RollBackAccelerometer(double t, const Eigen::Vector3d& p, PositionInnovation& in);
  Status Check(double t, const Eigen::Vector3d& v, const char* name);
  // After an update: Ok, or the state went non-finite and the filter was reset (an Error).
  Status GuardState(double t);
  void Initialise(double t, const Eigen::Vector3d& p);
  // Initialise on a position sample, which counts as taken (no rollback reaches before it).
  // With `previous` (the position sample before, re-initialising in motion), the velocity starts
  // at the mean over that interval (header comment).
  struct PositionSample {
    double t = 0.0;
    Eigen::Vector3d p_WM_W = Eigen::Vector3d::Zero();
  };
  void InitialiseOn(double t, const Eigen::Vector3d& p_WM_W,
                    const std::optional<PositionSample>& previous = std::nullopt);
  // The adaptive accelerometer noise's step at a position sample (header comment).
  void AdaptAccelNoise(double t);

  PositionKfSettings settings_;
  bool initialized_ = false;
  double t_ = 0.0;
  VecN x_ = VecN::Zero();
  MatN P_ = MatN::Identity();
  Counters counters_;
  Eigen::Matrix3d R_WE_ = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R_WE_covariance_ = Eigen::Matrix3d::Zero();
  double last_position_nis_ = 0.0;
  double last_position_log_likelihood_ = 0.0;
  bool last_position_accepted_ = false;
  int consecutive_rejections_ = 0;
  double accel_noise_scale_ = 1.0;  // λ (header comment)
  double last_position_t_ = 0.0;    // for the adaptation's step a = Δt/τ
  bool has_last_omega_ = false;     // for α_B by differencing
  double last_omega_t_ = 0.0;
  // The previous accelerometer sample's earth-frame acceleration z(t′ − δ), for accel_delay.
  bool has_last_z_ = false;
  Eigen::Vector3d last_z_ = Eigen::Vector3d::Zero();
  double last_z_t_ = 0.0;
  Eigen::Vector3d last_omega_B_ = Eigen::Vector3d::Zero();
  // The states right after the last position samples, newest last, with the sample each took
  // and the accelerometer samples that came after it, applied or not (accel_rollback_span).
  struct RollbackPoint {
    double t = 0.0;
    Eigen::Vector3d p_WM_W = Eigen::Vector3d::Zero();
    VecN x = VecN::Zero();
    MatN P = MatN::Identity();
    std::vector<AccelSample> accel;  // at most kMaxKeptAccelSamples
    int applied_not_kept = 0;        // applied samples beyond them
    bool complete = true;            // every sample after it kept
  };
  std::vector<RollbackPoint> rollback_;
};

}  // namespace rcal::estimation
