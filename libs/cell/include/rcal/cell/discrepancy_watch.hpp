// The discrepancy watch of the online identification (issue 15 item 5): what `rcal analyze` would
// say about the poses the identifier is fitting now, asked while it runs.
//
// Every `every_poses` poses the EKF takes (accepted or refused by its gate: a large unmodelled
// effect shows first as refused poses) the watch takes the identifier's window (the poses the EKF
// still holds, at most EkfSettings::window_poses, and those its gate refused between them: what
// the model cannot explain is the evidence; each with its context) and runs
// discrepancy::Analyze on it, as `rcal analyze` runs on a file:
//   - the geometric fit's whitened residuals against the noise the poses claim (χ²: the RMS
//     per-axis σ of their covariances; a model that fits reads χ²/dof ≈ 1),
//   - the correlation of the residual with each candidate effect's regressor (gravity torque,
//     sin/cos of a joint, the joint, the approach direction, temperature, time),
//   - greedy forward selection of the candidates by cross-validated held-out gain, judged by
//     nested cross-validation (an effect is suspected only if it gains on poses its selection
//     did not fit, so an arm that has no such effect raises nothing with probability ≳ 1 − α).
// The changes the identifier released inside the window (OnlineIdentification::WindowSteps) go to
// the analysis as known geometry steps (discrepancy::PoseData::steps): it fits a piecewise
// geometry, so a real step (an encoder swapped) inside the window is neither taken for an effect
// nor hides one, and a change an effect raised costs the analysis only the columns it adds.
// The suspects are the effects Analyze reports, each with its selection z; the expected gain is
// the held-out position RMS of the geometric model against the selected one. An effect the
// identifier already identifies (its --effects) is reported too, marked in the model: the watch
// analyses the window against the geometry alone, so it also says whether those effects still
// earn their place.
//
// SwitchIn: the identification is rebuilt with the suspected effects added (the geometric state
// and its covariance kept, the new effect parameters from 0 with their weak prior) and
// relinearised over its window, so the effects are identified from the poses it already holds.
// The information of poses folded out of the window carries no knowledge of the new effects
// (they were linearised without them): the effects are identified from the window's poses on.
//
// Pure: no transport, no files. Analyze costs about a second per 100 full poses on one core:
// the caller decides where it runs (ekf_identifier: a worker thread, so poses keep flowing).
#pragma once

#include <string>
#include <vector>

#include "rcal/cell/online_identification.hpp"
#include "rcal/discrepancy/analysis.hpp"

namespace rcal::cell {

struct DiscrepancyWatchSettings {
  int every_poses = 50;  ///< run after every this many poses taken by the EKF (0: never)
  int min_poses = 40;    ///< poses in the window (accepted or refused) before the first run
  /// rcal analyze's settings (noise, folds, α, candidates). The stated noise and the gravity
  /// model are filled from the window's poses and the identifier's model when left at 0 / default.
  discrepancy::AnalysisSettings analysis;
};

/// An effect the watch suspects.
struct SuspectedEffect {
  kinematics::Effect effect;
  std::string description;          ///< discrepancy::Describe: "joint_compliance j2"
  std::string cause;                ///< vocabulary: joint_compliance, joint_periodic, ...
  std::vector<std::string> joints;  ///< joint names (empty for thermal)
  double z = 0;                     ///< selection z against the model without it
  std::vector<kinematics::EffectParameter> parameters;
  Eigen::VectorXd values, sigma;  ///< the window's batch fit [SI, parameters' units], 1σ
  bool in_model = false;          ///< the identifier already identifies it
};

/// The residual's correlation with one candidate's regressor.
struct WatchedCorrelation {
  std::string regressor;  ///< with its unit: "gravity torque j2 [N*m]", "temperature [degC]"
  double r = 0;           ///< Pearson r
  double log_p = 0;       ///< ln p, two-sided
};

/// One run of the watch.
struct DiscrepancyReport {
  int window_poses = 0;
  int window_steps = 0;       ///< released changes inside the window, fitted as geometry steps
  std::string noise_against;  ///< "stated noise" (the poses' covariances)
  double chi2 = 0, chi2_dof = 0;
  double chi2_log_p = 0;                  ///< ln P(χ² ≥ chi2) if the geometric model were right
  std::vector<SuspectedEffect> suspects;  ///< strongest first; empty: the geometry suffices
  double heldout_rms_before_m = 0;        ///< geometric model, held-out position RMS [m]
  double heldout_rms_after_m = 0;         ///< with the suspects [m]
  double expected_gain = 0;               ///< (before − after) / before
  std::string scheme;                     ///< how held-out was judged
  kinematics::GravityModel gravity;       ///< joint_compliance's model in the analysis
  std::vector<WatchedCorrelation> correlations;  ///< strongest first, at most 8
  /// Suspects the identifier does not identify yet.
  std::vector<kinematics::Effect> NewEffects() const;
};

/// True when the watch should run after this identification's latest EKF update (a multiple of
/// every_poses poses taken by the EKF, accepted or refused by its gate; the window,
/// OnlineIdentification::WindowSize, at least min_poses).
bool WatchDue(const OnlineIdentification& id, const DiscrepancyWatchSettings& s);

/// The window of `id` (OnlineIdentification::Window: its poses and contexts, and the changes
/// released inside it as geometry steps), as discrepancy::Analyze takes it.
discrepancy::PoseData WatchWindow(const OnlineIdentification& id);

/// Runs the analysis on a window taken by WatchWindow (file comment); `model` the identification's
/// geometric model, `in_model` the effects it already identifies, `gravity` its gravity model.
/// Throws std::invalid_argument when the window cannot be analysed (too few poses).
DiscrepancyReport WatchForDiscrepancy(const kinematics::KinematicModel& model,
                                      const discrepancy::PoseData& window,
                                      const std::vector<kinematics::Effect>& in_model,
                                      const kinematics::GravityModel& gravity,
                                      const DiscrepancyWatchSettings& s = {});
/// The same on `id`'s window now.
DiscrepancyReport WatchForDiscrepancy(const OnlineIdentification& id,
                                      const DiscrepancyWatchSettings& s = {});

}  // namespace rcal::cell
