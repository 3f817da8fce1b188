// Where an IMU stream disagrees with the sensor model the simulator assumes, the cause, the
// extended model and its gain on data the fit did not use (issue 6, IMU streams).
//
// Data: the BROAD layout (../shared/data/broad/README.md): t [s], gyro [rad/s], specific force
// [m/s²], field [µT] in the IMU frame, optional truth q_WI (IMU → ENU, [w,x,y,z]) and movement,
// optional positions p_W of the tool (a tracker's or the optical truth's, in a frame aligned with
// ENU [m]).
//
// Base model (sim/imu_model.hpp, sim/imu_stream.hpp with every effect off):
//   gyro  ω_m = ω + b + n_g,   b constant,                  n_g white, density N_g [rad/s/√Hz]
//   acc   f   = R_WIᵀ(−g_W) + n_a   (gravity only),          n_a white, density N_a [m/s²/√Hz]
//   mag   m   = R_WIᵀ m_W + n_m,  |m_W| and dip δ constant,   n_m white, density N_m [µT/√Hz]
// and the filter that trusts it: the orientation KF (estimation/orientation_kf.hpp) with
// reject_mag = reject_accel = false and gyro_bias_random_walk = base_bias_random_walk.
// Fit: rest segments (movement = 0, or detected still when there is no movement column; each run
// trimmed by rest_trim_s at both ends) of at least min_rest_s; the reference field (norm m₀, dip
// δ₀ = asin(−m·f / |m||f|)) and the noise levels σ_|m|, σ_δ, σ_|f| (never below the stated
// densities · √rate) on the first rest segment.
// Short rests (a still-and-move programme such as the demo's 1.5 s stops): when no rest reaches
// min_rest_s, the rests of at least min_short_rest_s are used instead (ImuAnalysis::short_rests):
// the reference is pooled over the first rests until they hold min_rest_s (norm, dip and |f| do
// not depend on the orientation, so rests at different poses measure the same quantities); the
// Allan curve only reaches half the longest rest, so the long-τ Allan test (τ ≥
// allan_test_tau_min_s, rests of at least twice that) cannot run and gyro_bias rests on the drift
// between the first and the last rest alone. ImuAnalysis::rest_note says so in words.
//
// Candidates (cause vocabulary), each tested at α / 4 (Bonferroni over the four; α / 5 when the
// stream has positions and accel_lag is tested too):
//  gyro_bias   overlapping Allan variance per axis over the rest segments (pooled), relative
//              confidence s(τ) = 1/√(2 Σ_seg (N_seg/m − 1)); fitted AVAR = N²/τ + (2 ln2/π) B² +
//              K² τ/3 (white density N, bias instability B, rate random walk K, weighted LS).
//              Test: z(τ) = (σ_A(τ) / (N_w/√τ) − 1) / s(τ) for τ ≥ allan_test_tau_min_s, N_w the
//              white level read at short τ (max of the stated density and the data's); and the
//              drift z = (mean_last − mean_first) / √(N_w²/T₁ + N_w²/T₂ + Ω_E²) per axis (Ω_E the
//              earth rate: the rests may differ in orientation). Bonferroni over axes × tests.
//              Extension: gyro_bias_random_walk = max(K, B/√bias_time_constant_s).
//  magnetic_disturbance  deviations from the reference: |m| − m₀ on every sample, δ − δ₀ with
//              δ from the base filter's attitude. Gate = band_z · σ_r per quantity, σ_r the
//              robust spread about the reference (1.4826 · median |dev|, never below the
//              reference rest's noise): the field the stream shows most of the time. Test:
//              one-sided binomial test of the samples outside the gate (norm anywhere; dip at
//              rests, from the accelerometer, since in motion the filter's tilt carries the
//              accelerometer's own error) against p₀ = max(4 P(Z > band_z), outlier_rate).
//              The fraction outside the strict noise band of the reference rest is reported too.
//              Extension: reject_mag with mag_ref_norm = m₀, mag_ref_dip = δ₀,
//              mag_norm_tolerance = gate/m₀, mag_dip_tolerance = dip gate.
//  accel_motion  |f| − g₀ during motion (g₀ = mean |f| at the reference rest): binomial test of
//              the samples outside band_z σ_|f|, and the RMS angle between f and the base
//              filter's gravity direction. Extension: reject_accel.
//  time_offset  (truth present) lag L minimising Σ|ω_m(t) − b̄ − ω_truth(t − L)|² over motion
//              samples (ω_truth the truth quaternion's rate over the interval ending at each
//              sample, the gyro convention the filters integrate: such a gyro reads τ = 0),
//              integer grid to ±max_lag_s then a parabola through the minimum; σ from
//              offset_blocks contiguous blocks (sd/√B), so τ/σ is Student's t with B − 1 degrees
//              of freedom, written as the z of the same p. Effect when beyond Φ⁻¹(1 − α_c/2) and
//              it matters: the offset alone turns the attitude by |τ| |ω|, RMS e_τ = |τ| ω_rms
//              over the motion samples; in quadrature with the rest of the base filter's total
//              RMSE e, re-timing is expected to lower e by 1 − √(1 − (e_τ/e)²), which must reach
//              min_offset_gain (a criterion in the error the offset causes, not in sample
//              periods: 1 ms matters to a filter good to 0.1° at 2 rad/s, not to one of 1.5° at
//              1.7 rad/s). Extension: the estimate stamped t is
//              compared with truth at t − τ, τ fitted on the other half of the movement samples
//              (2-fold).
//  accel_lag   (positions present) the accelerometer reads δ late against the position sensor
//              (and the gyro): estimation::EstimateAccelLag (accel_lag.hpp) on the accelerometer
//              turned by the truth's attitude (the base filter's without truth: its tilt errors
//              under linear acceleration scatter δ tenfold) and the positions taken one every
//              accel_lag_position_period_s (a tracker's rate: the second differences of 10 ms
//              steps drown in the positions' noise). Test: t = δ/σ_δ, σ_δ the estimator's
//              jackknife over B blocks, so t has B − 1 degrees of freedom
//              (significance.hpp, LogStudentTUpper), written as the z of the same p; effect when
//              beyond Φ⁻¹(1 − α_c/2) and |δ| ≥ min_accel_lag_periods sample periods. A time
//              offset of the whole IMU is also a lag of its accelerometer behind the positions and
//              the truth's attitude, so both are named then. Extension: the position KF as
//              position_kf runs it (the bank of DefaultBankModels, position_kf_bank.hpp, with the
//              lever arm estimated; ENU, gravity the reference rest's |f|, the base filter's
//              attitude) with accel_delay = δ, cross-fitted: δ of the first half of the stream
//              (split at the middle movement sample) applied to the second half and the reverse;
//              a negative δ (the accelerometer leads: more likely the position sensor is late)
//              cannot be taken out causally and is applied as 0. Its gain is the position RMSE
//              [m] over the movement samples the filter did not fuse (between the tracker's
//              samples), base (accel_delay = 0) vs extended; it changes no orientation, so it is
//              not part of the orientation gain below.
// Gain: the truth is never used by a fit except the time offset's and the accelerometer lag's
// (both cross-fitted), so the gain of an extension is the BROAD RMSE (discrepancy/imu_scoring.hpp)
// over movement samples of the base filter vs the same filter with the extension; `gain` is base
// vs all selected extensions together, metric heading RMSE when magnetic_disturbance is selected
// (the gate acts on heading only), else total RMSE. Without truth the gain is not measured
// (has_truth = false, NaN figures).
#pragma once

#include <Eigen/Core>
#include <array>
#include <limits>
#include <string>
#include <vector>

#include "rcal/discrepancy/imu_scoring.hpp"
#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/sim/imu_model.hpp"
#include "rcal/sim/imu_stream.hpp"

namespace rcal::discrepancy {

/// An IMU stream in SI units (µT for the field, as BROAD). Vectors of equal length.
struct ImuStreamData {
  std::vector<double> t;                 ///< [s], strictly increasing, uniform rate
  std::vector<Eigen::Vector3d> gyro;     ///< [rad/s]
  std::vector<Eigen::Vector3d> accel;    ///< specific force [m/s²]
  std::vector<Eigen::Vector3d> mag_uT;   ///< [µT]
  std::vector<Eigen::Vector4d> q_truth;  ///< IMU → ENU [w,x,y,z]; empty: none; NaN: occluded
  std::vector<int> movement;             ///< 1 moving, 0 rest; empty: rest detected
  /// The tool's position, ENU-aligned [m] (the IMU's point: a lever arm is estimated); empty:
  /// none; NaN: occluded.
  std::vector<Eigen::Vector3d> p_W;
};

/// The base model's stated noise and the tests' settings.
struct ImuAnalysisSettings {
  double gyro_noise_density = sim::ImuModelSettings{}.gyro_noise_density;    ///< [rad/s/√Hz]
  double accel_noise_density = sim::ImuModelSettings{}.accel_noise_density;  ///< [m/s²/√Hz]
  double mag_noise_density_uT = sim::ImuModelSettings{}.mag_noise_density;   ///< [µT/√Hz]
  double alpha = 0.01;  ///< false-positive rate of the whole selection [-]
  // Rest segments.
  double min_rest_s = 3.0;  ///< shorter rests are not used while a rest this long exists [s]
  /// With no rest of min_rest_s: the shortest rest used, the tests adapted (header comment) [s].
  double min_short_rest_s = 0.4;
  double rest_trim_s = 0.5;       ///< cut from both ends of each still run (transitions) [s]
  double still_gyro = 0.05;       ///< detected still: |ω_m − median| below [rad/s]
  double still_accel = 0.3;       ///< and ||f| − g| below [m/s²]
  double gravity = 9.81;          ///< [m/s²], for still detection only
  double reference_max_s = 30.0;  ///< the reference uses at most this much of the first rest [s]
  // Allan deviation.
  double allan_white_tau_min_s = 0.05;  ///< white level read over [min, max] [s]
  double allan_white_tau_max_s = 0.5;
  double allan_test_tau_min_s = 1.0;    ///< long-τ test from here [s]
  double allan_max_rel_sigma = 0.4;     ///< τ with a larger relative confidence are not used [-]
  double earth_rate = 7.292e-5;         ///< [rad/s]
  double bias_time_constant_s = 100.0;  ///< turns B into a random walk for the extension [s]
  double base_bias_random_walk = 1e-7;  ///< the base filter's "constant" bias [rad/s/√s]
  // Field and accelerometer bands.
  double band_z = 4.0;  ///< noise band half-width in σ [-]
  /// Window around each sample outside the magnetic gate reported separately [s].
  double disturbed_window_s = 2.0;
  /// Outlier fraction the base model tolerates: the binomial tests' p₀ never goes below it [-].
  double outlier_rate = 1e-3;
  // Time offset.
  double max_lag_s = 0.2;  ///< lag grid ± [s]
  int offset_blocks = 8;   ///< blocks for the offset's σ [-]
  /// Smallest expected gain of re-timing for an offset to be named [-] (header comment): the
  /// 10 % within which two filters on the same samples differ by noise alone, as an extension
  /// that loses by less is no loss (ImuCandidate::loses_to_truth). BROAD's gyro leads its truth
  /// by 0.7–0.9 ms, an expected 0.03–5 % there (07: measured 4.9 %).
  double min_offset_gain = 0.1;
  // Accelerometer lag (positions present).
  /// The positions are taken one per this period [s]: the tracker the position KF fuses and the
  /// lag estimator's triplets (their second differences over shorter steps are mostly noise).
  double accel_lag_position_period_s = 0.05;
  double accel_lag_position_sigma = 1e-3;  ///< the position KF's position noise σ [m]
  int accel_lag_blocks = 8;                ///< jackknife blocks of the lag's σ [-]
  /// Smallest lag named [sample periods]: the estimator's trapezoid and central differences are
  /// exact to O(Δt²), and a clean simulated stream read with exact positions shows 0.0015 periods
  /// at z 3.4; the lags that cost (BROAD: 0.2–0.3 periods) are far above.
  double min_accel_lag_periods = 0.05;
  /// The filter (base and extensions differ only in the fields named above). ENU.
  estimation::OrientationKfSettings filter = [] {
    estimation::OrientationKfSettings s;
    s.earth = estimation::EarthFrame::kEnu;
    return s;
  }();
};

struct ImuValue {
  std::string name;  ///< with its unit, e.g. "white_noise_density_rad_s_sqrt_hz"
  double value = 0.0;
  double sigma = 0.0;
};

/// One candidate: its test, and (with truth) its gain.
struct ImuCandidate {
  /// gyro_bias | magnetic_disturbance | accel_motion | time_offset | accel_lag
  std::string cause;
  std::vector<std::string> axes;  ///< axes found ("x","y","z") or the sensor
  std::vector<ImuValue> values;   ///< fitted figures with σ (SI, unit in the name)
  double statistic = 0.0;  ///< z (or Φ̄⁻¹(p) for a binomial test; ±∞: significance.hpp)
  /// ln p of a binomial test, finite where p underflows a double (z is derived from it); NaN
  /// when the statistic is a z itself (gyro_bias, time_offset).
  double log_p = std::numeric_limits<double>::quiet_NaN();
  double critical = 0.0;  ///< its critical value after Bonferroni
  bool significant = false;
  /// With truth: its extension raised the error it acts on (heading for magnetic_disturbance,
  /// total otherwise) over the movement samples by more than 10 %. A significant candidate whose
  /// extension loses against the truth is not named as an effect (the test saw something; the
  /// extension is not what it is).
  bool loses_to_truth = false;
  bool tested = false;  ///< false: not testable on this stream (reason in note)
  std::string note;
  OrientationScore before, after;  ///< base filter vs base + this extension (movement samples)
  /// accel_lag: the position KF's RMSE [m] over the movement samples it did not fuse, base vs
  /// extended (NaN for the other candidates, or when not measured).
  double position_before_m = std::numeric_limits<double>::quiet_NaN();
  double position_after_m = std::numeric_limits<double>::quiet_NaN();
  /// Named as an effect: significant and not losing against the truth.
  bool named() const { return significant && !loses_to_truth; }
  /// "heading" for magnetic_disturbance (its gate acts on heading only), "position" for
  /// accel_lag (it changes no orientation), "total" otherwise.
  std::string gain_metric() const;
};

/// Sets loses_to_truth on each tested candidate whose `after` is more than 10 % worse than its
/// `before` in its gain_metric() (both finite; within 10 % it gains nothing, which is no loss),
/// and says so in its note.
void MarkLosingExtensions(std::vector<ImuCandidate>& candidates);

struct AllanCurve {
  std::vector<double> tau_s;
  std::array<std::vector<double>, 3> adev_rad_s;  ///< per axis
  std::vector<double> rel_sigma;                  ///< s(τ)
  std::array<double, 3> white_level{};            ///< N_w per axis [rad/s/√Hz]
};

struct ImuAnalysis {
  int samples = 0;
  double rate_hz = 0.0;
  bool has_truth = false, has_movement = false;
  std::vector<std::pair<int, int>> rests;  ///< [begin, end) sample ranges
  /// No rest of min_rest_s: rests of min_short_rest_s and longer used (header comment).
  bool short_rests = false;
  int reference_rests = 0;   ///< rests pooled into the reference
  double reference_s = 0.0;  ///< their total length [s]
  /// What the rests allow, in words, when short_rests ("" otherwise).
  std::string rest_note;
  // Reference fitted on the first rest (short_rests: on the first reference_rests).
  double mag_ref_norm_uT = 0.0, mag_ref_dip_rad = 0.0, gravity_ref = 0.0;
  double sigma_mag_norm_uT = 0.0, sigma_dip_rad = 0.0, sigma_accel_norm = 0.0;
  double mag_gate_norm_uT = 0.0, mag_gate_dip_rad = 0.0;  ///< the fitted gate half-widths
  AllanCurve allan;
  bool has_positions = false;
  /// gyro_bias, magnetic_disturbance, accel_motion, time_offset, accel_lag; tested or not.
  std::vector<ImuCandidate> candidates;
  /// The named candidates (ImuCandidate::named).
  std::vector<const ImuCandidate*> effects() const;
  // Gain of all selected extensions together.
  std::string gain_metric;  ///< "total" | "heading"
  OrientationScore base_score, extended_score;
  double time_offset_s = 0.0;  ///< applied in extended_score (0 when not selected)
  // Per-sample series for plots (full length; NaN where undefined).
  std::vector<double> mag_norm_uT, mag_dip_rad;
  std::vector<char> mag_disturbed;  ///< within disturbed_window_s of a sample outside the gate
  std::vector<double> heading_err_base_rad, heading_err_ext_rad;
  std::vector<double> total_err_base_rad, total_err_ext_rad;
  /// accel_lag's position KF without and with the lag (cross-fitted), |p̂ − p| at the movement
  /// samples it did not fuse [m] (empty when not measured).
  std::vector<double> position_err_base_m, position_err_ext_m;
};

/// Checks the stream (equal lengths, finite IMU values, increasing time) and throws
/// std::invalid_argument naming the field and the row otherwise.
void ValidateImuStream(const ImuStreamData& data);

/// A simulated stream (sim/imu_stream.hpp) as the analysis takes it, truth and movement flag
/// included.
ImuStreamData FromSimulatedStream(const std::vector<sim::ImuStreamSample>& stream);

/// The analysis described in the header comment. Progress lines go to spdlog.
ImuAnalysis AnalyzeImuStream(const ImuStreamData& data, const ImuAnalysisSettings& settings = {});

/// Runs the orientation KF over the stream; q_WI estimate per sample (NaN before the first
/// accepted sample).
std::vector<Eigen::Vector4d> RunOrientationFilter(const ImuStreamData& data,
                                                  const estimation::OrientationKfSettings& s);

/// BROAD score of estimates against the truth at t − offset (truth nlerp-interpolated) over the
/// movement samples [begin, end) with finite truth.
OrientationScore ScoreAgainstTruth(const ImuStreamData& data,
                                   const std::vector<Eigen::Vector4d>& q_est, double offset_s = 0.0,
                                   int begin = 0, int end = -1);

}  // namespace rcal::discrepancy
