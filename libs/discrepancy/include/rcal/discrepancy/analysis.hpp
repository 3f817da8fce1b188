// Where the geometric model of an arm disagrees with measured poses, why, and what an extended
// model gains on data it did not fit (issue 6, pose data).
//
// 1. Base fit: identification::Calibrate on the calibration poses (set-up frames from the data,
//    identifiable geometric parameter set, noise σ estimated from the residuals).
// 2. Residual tests: χ² of the fit residuals against the stated noise and against the noise of
//    repeated poses (same joints, measured again), and the correlation of the residual along each
//    candidate's direction with its regressor (joint angle, sin/cos harmonics, gravity torque,
//    temperature, time, approach direction, payload through the torque).
// 3. Candidate extensions (kinematics::ExtendedModel effects) fitted on the calibration part and
//    judged on held-out poses by k-fold cross-validation. Around the base fit the problem is
//    linear to second order in the (sub-millimetre) corrections, so each fold solves the whitened
//    linearised least-squares problem [J_x J_e]·δ = r for the identified geometric parameters
//    and the candidate's effect parameters; held-out residuals are r − J·δ.
// 4. Greedy forward selection: each round adds the candidate with the lowest mean held-out
//    whitened squared residual, if its paired improvement over the current model on the held-out
//    poses is significant: one-sided z = mean(d)/(sd(d)/√n) > Φ⁻¹(1 − α/m), d the per-pose drop of
//    the whitened squared residual, m the candidates tried that round (Bonferroni), so an effect
//    that is not there is reported with probability ≲ α.
// 5. Judged on poses the selection did not fit: the `set` test poses when there are any, else
//    nested cross-validation (the whole greedy selection redone inside each outer fold, judged on
//    the outer held-out poses). The selected model is reported only if it gains there (held-out
//    position RMS below geometry's) and each of its effects only if leaving it out would lose
//    there (split: the selected model without it; nested: each outer fold's own selection
//    without it, so an effect no outer fold selects contributes nothing). Effects that fail are
//    listed as rejected with the figures, never as effects. The gain reported is that of the
//    selection as made (split: the selected model; nested: the outer folds' selections), never
//    recomputed after the rejections, which were decided on those same held-out poses.
// 6. The reported effects are refitted (nonlinear, batch: identification::FitExtended) on all
//    calibration poses: values with σ.
// Known geometry steps (PoseData::steps: the changes an online identifier released) make the
// geometry piecewise: after the base fit the steps' amplitudes are fitted with the identified
// parameters (FitExtended, noise re-estimated from that fit's residuals), every pose is
// linearised at its own segment's geometry, and the steps' columns join the geometry's in every
// fit above, so the tests judge what the piecewise geometry leaves. The base fit's x and noise
// are then the piecewise fit's (x: the first pose's geometry); its other figures are those of the
// single geometry.
// p-values and z beyond what a double holds: significance.hpp.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "rcal/identification/calibration.hpp"
#include "rcal/identification/extended_lm.hpp"
#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::discrepancy {

/// The measured poses with what each was taken under.
struct PoseData {
  std::vector<kinematics::PoseMeasurement> measurements;  ///< covariances: the starting noise
  std::vector<kinematics::EffectContext> contexts;        ///< one per measurement
  std::vector<bool> is_test;  ///< `set` = test; empty or all false: k-fold on everything
  /// Known changes of the geometry inside the data (first_pose: index into measurements, with
  /// fit poses before and after it): the geometric model is piecewise, one geometry up to each
  /// step, its amplitudes fitted with the geometry everywhere (the base fit, every fold, the
  /// final fit), so a step is not taken for an effect, nor hides one. What the online watch
  /// passes for the changes its identifier released inside the window.
  std::vector<identification::GeometryStep> steps;
};

struct AnalysisSettings {
  /// Noise the data claims (for the χ² test) [m], [rad]; 0: not stated.
  double stated_position_sigma_m = 0.0;
  double stated_orientation_sigma_rad = 0.0;
  bool estimate_noise = true;  ///< weights from the base fit's residuals (else the covariances)
  int folds = 5;               ///< k of the k-fold cross-validation (≥ poses: leave-one-out)
  int repeats = 2;             ///< k-fold repeated with different fold assignments, averaged
  unsigned seed = 1;           ///< fold assignment
  double alpha = 0.01;         ///< false-positive rate per selection round
  int max_effects = 4;
  bool second_harmonic = true;  ///< try joint_periodic h = 2 as well as h = 1
  kinematics::GravityModel gravity;
  double min_temperature_spread_c = 0.5;  ///< thermal by temperature needs at least this range
  double min_relative_novelty = 1e-3;     ///< candidate columns this close to geometry: skipped
};

/// χ² of the base fit's residuals against a noise level.
struct NoiseTest {
  std::string against;  ///< "stated noise" or "repeated poses"
  double position_sigma_m = 0;
  double orientation_sigma_rad = 0;
  double chi2 = 0;
  double dof = 0;
  double p_value = 1;  ///< P(χ² ≥ observed) if the model were right (0 after underflow)
  double log_p = 0;    ///< ln p_value, finite where p_value underflows
};

/// Correlation of a regressor with the residual along the direction its effect moves the pose.
struct RegressorCorrelation {
  std::string regressor;       ///< e.g. "gravity torque shoulder_lift", "sin(2 q3)", "temperature"
  std::string unit;            ///< of the regressor values: "N*m", "rad", "1", "degC", "s"
  kinematics::Effect effect;   ///< the candidate the regressor belongs to
  int column = 0;              ///< which of the effect's parameters (periodic: 0 sin, 1 cos)
  double correlation = 0;      ///< Pearson r, all calibration poses
  double p_value = 1;          ///< two-sided, Fisher z (0 after underflow)
  double log_p = 0;            ///< ln p_value, finite where p_value underflows
  std::vector<double> values;  ///< regressor per calibration pose [unit]
  std::vector<double> residual_before_m;  ///< projected residual per pose, geometric fit [m]
  std::vector<double> residual_after_m;   ///< the same after the selected model [m]
};

/// One selection round.
struct SelectionRound {
  std::vector<kinematics::Effect> tried;
  std::vector<double> z;  ///< paired z of each tried candidate against the current model (±∞:
                          ///< zero spread of the paired differences)
  int best = -1;          ///< index into tried
  double z_critical = 0;  ///< Φ⁻¹(1 − α/m)
  bool accepted = false;
  double heldout_rms_current_m = 0;  ///< position RMS, current model, k-fold
  double heldout_rms_best_m = 0;     ///< with the best candidate added
};

/// An effect the data supports.
struct FoundEffect {
  kinematics::Effect effect;
  std::string cause;                ///< vocabulary name
  std::vector<std::string> joints;  ///< joint names (empty for thermal)
  std::vector<kinematics::EffectParameter> parameters;
  Eigen::VectorXd values;  ///< [SI, parameters' units]
  Eigen::VectorXd sigma;   ///< 1σ
  double z = 0;            ///< selection statistic when it was added
  /// Held-out position RMS of the judged model without this effect (Gain's poses and scheme) [m]
  double heldout_rms_without_m = 0;
  int outer_folds_selecting = -1;  ///< nested: outer folds whose selection chose it; split: −1
};

/// An effect the greedy selection chose on the fit poses that does not gain on held-out poses
/// (step 5 of the file comment): not reported as an effect, not in Analysis::x/e.
struct RejectedEffect {
  kinematics::Effect effect;
  std::string reason;
  double z = 0;                      ///< selection statistic when it was added
  double heldout_rms_with_m = 0;     ///< held-out position RMS of the judged model [m]
  double heldout_rms_without_m = 0;  ///< the same without this effect [m]
  int outer_folds_selecting = -1;    ///< nested: outer folds whose selection chose it; split: −1
};

struct Gain {
  std::string scheme;               ///< "cal/test split", "nested 5-fold (...)" or "5-fold ×2"
  bool nested = false;              ///< the selection was redone in each outer fold
  double heldout_rms_before_m = 0;  ///< geometric model, held-out position RMS
  double heldout_rms_after_m = 0;   ///< selected model
  double relative_gain = 0;         ///< (before − after) / before
  double z = 0;                     ///< paired z of the improvement (whitened squared residual)
  std::vector<double> position_before_m, position_after_m;  ///< per held-out pose [m]
  /// Nested: the effects each outer fold's selection chose.
  std::vector<std::vector<kinematics::Effect>> outer_selections;
  /// Nested, with effects reported: held-out RMS of the reported effects' structure fitted in
  /// each outer fold but chosen on all fit poses: not nested, so flattered by the choice. This
  /// is what `rcal calibrate --effects` measures on the same folds (it fits a fixed list) [m].
  double heldout_rms_after_not_nested_m = 0;
};

struct Analysis {
  identification::CalibrationFit base_fit;
  std::vector<NoiseTest> noise_tests;
  std::vector<RegressorCorrelation> correlations;  ///< strongest first
  std::vector<kinematics::Effect> candidates;      ///< tried (eligible and identifiable)
  std::vector<std::string> skipped;                ///< candidates not tried, with the reason
  std::vector<SelectionRound> rounds;
  std::vector<FoundEffect> effects;      ///< empty: geometry suffices
  std::vector<RejectedEffect> rejected;  ///< selected on the fit poses, lost on held-out poses
  Eigen::VectorXd x;                     ///< geometric errors of the final fit [m|rad] (with
                                         ///< steps: the geometry of the first pose)
  Eigen::VectorXd e;                     ///< effect parameters of the final fit [SI]
  /// Per PoseData::steps entry: its amplitudes in the final fit [per unit direction] and 1σ.
  std::vector<Eigen::VectorXd> step_amplitudes, step_sigma;
  double position_sigma_after_m = 0;  ///< noise re-estimated with the effects
  Gain gain;
  int num_fit_poses = 0, num_test_poses = 0;
};

/// Runs steps 1–5 of the file comment. Throws std::invalid_argument on inconsistent input.
Analysis Analyze(const kinematics::KinematicModel& model, const PoseData& data,
                 const AnalysisSettings& settings = {});

/// Held-out position RMS [m] of the geometric model extended by `effects` (fitted, not given),
/// on the `set` test poses when there are any, else by repeated k-fold (settings.folds ×
/// settings.repeats), linearised around the base fit. For tests: the gain the true model
/// structure would get.
double HeldOutRms(const kinematics::KinematicModel& model, const PoseData& data,
                  const std::vector<kinematics::Effect>& effects,
                  const AnalysisSettings& settings = {});
/// The per-pose held-out position errors [m] behind HeldOutRms (fit poses in order, or the test
/// poses with a split). With settings.repeats = 1 the folds are the outer folds of Analyze's
/// nested cross-validation, so they pair pose by pose with Gain::position_after_m.
std::vector<double> HeldOutPositionErrors(const kinematics::KinematicModel& model,
                                          const PoseData& data,
                                          const std::vector<kinematics::Effect>& effects,
                                          const AnalysisSettings& settings = {});

/// Human-readable name of an effect: "joint_compliance shoulder_lift", "thermal (temperature)".
std::string Describe(const kinematics::KinematicModel& model, const kinematics::Effect& effect);

}  // namespace rcal::discrepancy
