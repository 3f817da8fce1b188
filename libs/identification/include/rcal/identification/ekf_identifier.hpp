// The paper's EKF identifier (Du, Zhang, Li 2014, Eqs. 42–44, errata from NOTES.md applied),
// on the identifiable (base) subset of the parameter errors.
//
// State: x, the errors of the identified parameters [m | rad], constant or slowly drifting.
//   predict   x⁻ = x,  P⁻ = P + Q                          (Eq. 42; Q from the drift settings)
//   measure   J = ∂h/∂x at x⁻, ỹ = z − h(x⁻)               (Eq. 43, residual as in measurement.hpp)
//             S = J P⁻ Jᵀ + R
//   update    K = P⁻ Jᵀ S⁻¹                                 (Eq. 44, erratum: P⁻ Jᵀ, not the OCR)
//             x⁺ = x⁻ + K ỹ
//             P⁺ = (I − K J) P⁻ (I − K J)ᵀ + K R Kᵀ          (Joseph form, symmetric by
//             construction)
// Beyond the paper:
// - iterated update (IEKF): J and ỹ are re-evaluated at the updated estimate up to
//   `max_iterations` times, x_{i+1} = x⁻ + K_i (ỹ_i − J_i (x⁻ − x_i)). The pose is a strongly
//   non-linear function of the angle errors; one linearisation at a prior that is degrees off
//   leaves a bias no later pose removes. max_iterations = 1 is the paper's EKF.
// - relinearisation passes: the filter keeps the poses it accepted; when the estimate has moved by
//   more than `relinearize_threshold` since the last pass, it re-runs the update over all of them
//   from the prior, each linearised at the current estimate (one Gauss–Newton step on the same
//   MAP cost, in information form), until a pass moves it less than the threshold. This is what
//   the paper's "EKF for 200 iterations" over 50 poses amounts to, and it makes the online
//   estimate agree with the batch optimum; once converged, the passes stop costing anything.
// - bounded cost: the passes run over a window of the `window_poses` most recent accepted poses;
//   an older pose is folded into the window's prior (x0, P0) by one update linearised at the
//   current estimate (its information marginalised), so memory, time per update and checkpoint
//   size stop growing. Up to window_poses poses this is exactly the filter above (the batch
//   optimum); beyond, the folded poses keep their last linearisation.
// - change detection (change_detection.hpp): the whitened innovations of the recent poses
//   (accepted or gated out) are tested for a step in a few of the identified parameters from an
//   onset pose on (a generalised likelihood ratio, the false-alarm rate a setting). On a
//   detection the named parameters are released from that onset on (their variance inflated by
//   the size of the step, as a process-noise event between two poses), the poses since the onset
//   are taken again (also those the gate refused), and the filter re-converges. status() says
//   converging, converged, change_detected (the update that named it) or reconverging. The test
//   runs once converged, and while converging only when the gate has refused change_min_poses
//   of the poses in its window (a filter stuck behind a change it met before it settled).
// - the second look at a change: a change is named from the few poses since its onset (3 or 4
//   at detection), where a wrist parameter and its neighbour (d5, α5) can move the marker
//   almost alike. Once change_window poses have come in since the onset, the whole window
//   chooses again with the onset known: the batch generalised likelihood ratio of a step from
//   the onset on, the geometry (all of the state, with the window's prior) refitted, each
//   candidate direction (an identified parameter or a joint's offset) as a column that is zero
//   before the onset; forward selection of as many directions as were released. Where the
//   chosen directions explain the window better than the released ones (the same number of
//   parameters: a likelihood comparison, no threshold), the release is moved to them (its
//   inflation replaced, the window relinearised), changes().back() renamed, and the update
//   reports it (EkfUpdateResult::reattributed).
// - innovation gate: a pose whose normalised innovation squared ỹᵀ S⁻¹ ỹ exceeds the χ² quantile
//   `gate_probability` is rejected and counted, not absorbed.
// - invalid input (wrong joint count, NaN, bad covariance) is rejected with a reason naming the
//   field; the state is untouched.
//
// Extended models (kinematics/joint_effects.hpp): built on an ExtendedModel, the state is
// x = [x_identified; e], e the effect parameters [SI units of joint_effects.hpp], and h is the
// extended model's pose at the joints as read and the pose's context c (temperature, payload,
// time, approach direction), passed with each update:
//   h(q, c; x_identified, e),  J = [∂h/∂x_identified  ∂h/∂e]   (extended_measurement.hpp)
// Everything else (prediction, gate, iterated update, relinearisation passes, checkpoint) is the
// same filter; the accepted poses are kept with their contexts. Without effects (or built on a
// KinematicModel) h is kinematics::ResidualAndJacobian's and the filter is exactly the geometric
// one above. The effects are constant unless drift_sigma_effects says otherwise.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::identification {

struct EkfSettings {
  double prior_sigma_length = 0.01;   ///< [m] initial σ of every length error
  double prior_sigma_angle = 0.035;   ///< [rad] initial σ of every angle error (2°)
  double drift_sigma_length = 0.0;    ///< [m per update] random-walk σ (0: constant parameters)
  double drift_sigma_angle = 0.0;     ///< [rad per update]
  double gate_probability = 0.99999;  ///< χ² gate on the innovation; ≥ 1 disables the gate
  int gate_after = 0;       ///< updates accepted before the gate arms (the first poses define x)
  int max_iterations = 10;  ///< IEKF relinearisations per update (1 = plain EKF)
  double iteration_tolerance = 1e-12;   ///< stop when |Δx| [m | rad] falls below
  double relinearize_threshold = 1e-4;  ///< [m | rad] max |Δx| since the last pass; ≤ 0: never
  int max_relinearize_passes = 5;
  /// Accepted poses kept for the relinearisation passes; older ones are folded into the prior
  /// (file comment). ≤ 0: keep all (cost grows with the number of poses).
  int window_poses = 100;
  /// Change detection (file comment and change_detection.hpp).
  bool detect_changes = true;
  /// Probability per pose that an unchanged arm raises a change (the test's threshold is this,
  /// shared over the parameters and onsets tested: Bonferroni).
  double change_false_alarm = 1e-7;
  /// Recent poses the test looks at (onsets tried: all of them): a step too small to show in a
  /// few poses is found once enough of them have piled up (30: the recovery horizon).
  int change_window = 30;
  int change_min_poses = 2;  ///< poses since the onset before a step can be claimed
  /// Consecutive poses whose test must find the same step (onset and parameters) before it is
  /// claimed: a step fitted with the wrong onset (a pose before the change taken in, the step
  /// diluted and more parameters needed) moves on at the next pose; a real one stays.
  int change_confirmations = 2;
  int change_max_params = 3;  ///< parameters a change may name (forward selection)
  /// A single-parameter change the poses since its onset cannot pin on one direction is released
  /// along the fewest directions whose probability of being the one adds up to this
  /// (change_detection.hpp, DetectedChange::probability); 0: the most likely alone.
  double change_naming_probability = 0.95;
  /// The second look at a released change (file comment): once change_window poses have come in
  /// since its onset, the window's poses choose the change's directions again, and the release
  /// is moved to them where they explain the poses better than the ones named at detection.
  bool change_second_look = true;
  /// The step's fit must explain the window: post-fit χ² below this quantile (else more
  /// parameters are tried; an outlier pose explains nothing and raises no change).
  double change_fit_probability = 0.9999;
  /// Converged: `converged_poses` consecutive accepted updates each moved every identified
  /// parameter by less than converged_step_sigma of its σ.
  double converged_step_sigma = 0.5;
  int converged_poses = 5;
  /// Extended models: initial σ of each effect parameter [SI, joint_effects.hpp]; empty:
  /// DefaultEffectPriorSigma(model).
  Eigen::VectorXd prior_sigma_effects;
  /// Extended models: random-walk σ of each effect parameter [SI per update]; empty: constant.
  Eigen::VectorXd drift_sigma_effects;
};

/// A weak prior σ per effect parameter, by cause: joint_compliance 1e-5 rad/(N·m) (prismatic
/// 1e-5 m/N), joint_periodic 1e-3 rad, joint_scale 1e-3, backlash 1e-3 rad (prismatic 1e-3 m),
/// thermal 1e-4 1/K (time: 1e-7 1/s). Each is some ten times the size such effects have on
/// industrial arms, so the data, not the prior, sets the estimate.
Eigen::VectorXd DefaultEffectPriorSigma(const kinematics::ExtendedModel& model);

/// The directions a release's inflation spans (a sum of rank-one terms, one per released
/// direction): its eigenvectors whose eigenvalue exceeds 1e-9 of the largest, one per column,
/// unit length. None for an empty or zero inflation.
Eigen::MatrixXd InflationDirections(const Eigen::MatrixXd& inflation);

/// Where the identification stands (the CALIBRATION_STATUS states).
enum class TrackingStatus { kConverging, kConverged, kChangeDetected, kReconverging };
/// "converging", "converged", "change_detected", "reconverging".
const char* TrackingStatusName(TrackingStatus s);

/// A change the identifier detected and released.
/// Each direction of the change is either one identified parameter or one joint's offset (an
/// encoder swap, as the state change that reproduces it: θ_j on a D–H arm, a combination of the
/// base set where the base set spreads it).
struct DetectedChange {
  std::vector<int> parameters;  ///< per direction: index into model.parameters(), or −1
  std::vector<int> joints;      ///< per direction: the joint whose offset it is, or −1
  Eigen::VectorXd step;         ///< estimated step along each [m | rad], at detection
  Eigen::VectorXd step_sigma;   ///< its 1σ [m | rad]
  Eigen::MatrixXd directions;   ///< state change per unit step, one column per direction
  double glr = 0;               ///< the likelihood-ratio statistic (2 ln Λ)
  double threshold = 0;         ///< what it was compared with
  int onset_poses_ago = 0;      ///< the first changed pose, counted back from this one (0: this)
  /// Empty: one step along all the directions. Otherwise the directions are alternatives the
  /// poses could not tell apart (change_detection.hpp): one of them stepped, each with this
  /// probability (most probable first), and the release covers each.
  std::vector<double> probability;
};

struct EkfUpdateResult {
  bool accepted = false;
  double nis = 0;      ///< normalised innovation squared at the prior
  double gate = 0;     ///< the χ² threshold it was compared with
  int iterations = 0;  ///< relinearisations done
  std::string reason;  ///< why it was rejected, naming the field
  TrackingStatus status = TrackingStatus::kConverging;  ///< after this update
  /// Set on the update that detected a change (status kChangeDetected); the update's pose is
  /// then taken (accepted) with the poses since the onset.
  std::optional<DetectedChange> change;
  /// Set on the update whose second look (file comment) moved the last change's release to
  /// other directions: the change as renamed (onset_poses_ago counted from this update).
  std::optional<DetectedChange> reattributed;
};

/// Everything needed to resume an identifier exactly where it stopped (a restarted process
/// continues, it does not start over).
struct EkfCheckpoint {
  Eigen::VectorXd x0, x, x_lin;  ///< prior, estimate, last relinearisation point (the state:
                                 ///< x_identified, then e for an extended model)
  Eigen::MatrixXd P0, P;
  std::vector<kinematics::PoseMeasurement> history;  ///< accepted poses
  int accepted = 0, rejected = 0, relinearizations = 0;
  /// The contexts of the accepted poses, one per history entry; empty: all default (what a
  /// geometric model needs).
  std::vector<kinematics::EffectContext> contexts;
  /// Values of the parameters not identified, full length [m | rad] (the start the identifier
  /// was given, e.g. a set-up guess); empty: keep the identifier's own.
  Eigen::VectorXd x_fixed;
  /// Covariance added to the state before each history entry [m² | rad²] beyond the drift (a
  /// released change), one per history entry or none; an empty entry adds nothing.
  std::vector<Eigen::MatrixXd> inflations;
  /// The tracking status and its count of consecutive small steps. The change detector's recent
  /// innovations are not kept: a restored identifier starts its test afresh.
  TrackingStatus status = TrackingStatus::kConverging;
  int small_steps = 0;
  /// The history entry whose release awaits its second look (EkfSettings::change_second_look;
  /// its inflation non-empty), or −1: none.
  int second_look_onset = -1;
  /// That release's directions are alternatives (DetectedChange::probability), not one step
  /// along all of them.
  bool second_look_alternatives = false;
};

class EkfIdentifier {
 public:
  /// `identified`: indices into model.parameters() to estimate. The other parameters keep the
  /// values of `x_fixed` (full length [m | rad]; empty: 0, the nominal model).
  EkfIdentifier(const kinematics::KinematicModel& model, std::vector<int> identified,
                EkfSettings settings = {}, Eigen::VectorXd x_fixed = {});
  /// An extended model: the state is [x_identified; e] (file comment). Throws
  /// std::invalid_argument naming the setting when prior_sigma_effects / drift_sigma_effects
  /// have the wrong size or are not finite and positive (drift: ≥ 0).
  EkfIdentifier(const kinematics::ExtendedModel& model, std::vector<int> identified,
                EkfSettings settings = {}, Eigen::VectorXd x_fixed = {});

  /// Back to the prior: x = 0, P = diag(prior σ²), counts zeroed.
  void Reset();
  /// Replaces the state (restoring a checkpoint); the restored state becomes the prior of later
  /// relinearisation passes. Throws std::invalid_argument naming the field if sizes differ or
  /// values are not finite.
  /// `state` is x_identified (geometric) or [x_identified; e] (extended), P its covariance.
  void SetState(const Eigen::VectorXd& state, const Eigen::MatrixXd& P);

  /// The whole state, and its exact restoration. Restore throws std::invalid_argument naming the
  /// field when the checkpoint does not fit this model and parameter set; the state is then
  /// unchanged.
  EkfCheckpoint Checkpoint() const;
  void Restore(const EkfCheckpoint& c);

  /// One still-pose measurement taken under `context` (an extended model's effects depend on it;
  /// a geometric model ignores it). Never throws on bad data: a rejection (measurement or
  /// context, naming the field) is reported and counted.
  EkfUpdateResult Update(const kinematics::PoseMeasurement& z,
                         const kinematics::EffectContext& context = {});

  /// Full-length error vector (x_fixed where not identified) [m | rad].
  Eigen::VectorXd x() const;
  /// The estimated geometric errors, in the order of identified().
  Eigen::VectorXd x_identified() const { return x_.head(identified_.size()); }
  /// The effect parameters [SI] (empty for a geometric model) and their 1σ.
  Eigen::VectorXd e() const { return x_.tail(num_effect_params()); }
  Eigen::VectorXd sigma_e() const;
  /// The whole state: x_identified, then e.
  const Eigen::VectorXd& state() const { return x_; }
  /// Covariance of state() (of x_identified() for a geometric model).
  const Eigen::MatrixXd& P() const { return P_; }
  /// Full-length 1σ of the geometric errors; 0 where not identified.
  Eigen::VectorXd sigma() const;
  const std::vector<int>& identified() const { return identified_; }
  const kinematics::KinematicModel& model() const { return ext_.base(); }
  /// The model with its effects (none for a geometric identifier).
  const kinematics::ExtendedModel& extended_model() const { return ext_; }
  int num_effect_params() const { return ext_.num_effect_params(); }
  int accepted() const { return accepted_; }
  int rejected() const { return rejected_; }
  const std::string& last_rejection() const { return last_rejection_; }
  /// Runs relinearisation passes over the accepted poses until one moves the estimate by less
  /// than the threshold, at most `max_passes` (the paper's repeated EKF iterations over a batch).
  /// Returns the passes run.
  int Refine(int max_passes);
  /// −2 ln of the likelihood of the window's poses given the window's prior (x0, P0), up to a
  /// constant: the prediction-error decomposition Σ_k r_kᵀ S_k⁻¹ r_k + ln det S_k of one filter
  /// pass over the window linearised at the estimate (each pose's drift and released-change
  /// inflation included). Two models of the same poses compare by it (a Bayes factor: a released
  /// change's inflation costs its Occam factor where the poses do not need it). 0 without poses.
  double WindowEvidence() const;
  /// Relinearisation passes run so far.
  int relinearizations() const { return relinearizations_; }
  /// Accepted poses in the window (the others are folded into the prior).
  int window_size() const { return static_cast<int>(history_.size()); }
  /// The window's accepted poses, oldest first (their contexts: Checkpoint().contexts).
  const std::vector<kinematics::PoseMeasurement>& history() const { return history_; }
  /// Covariance added to the state before each history() entry beyond the drift (a released
  /// change: its directions span the change) [m² | rad²]; an empty entry adds nothing.
  const std::vector<Eigen::MatrixXd>& inflations() const { return inflations_; }
  const EkfSettings& settings() const { return settings_; }
  TrackingStatus status() const { return status_; }
  /// Changes detected so far, oldest first.
  const std::vector<DetectedChange>& changes() const { return changes_; }

 private:
  int Relinearize(int max_passes);
  /// The measurement function: r = z − h and H = ∂h/∂state at `state`.
  void Measure(const kinematics::PoseMeasurement& z, const kinematics::EffectContext& context,
               const Eigen::VectorXd& state, Eigen::VectorXd& r, Eigen::MatrixXd& H) const;
  /// ∂h/∂q at `state` by central differences: a joint offset's signature (no analytic ∂h/∂q
  /// needed), as the residual r = z − h moves.
  Eigen::MatrixXd JointSignature(const kinematics::PoseMeasurement& z,
                                 const kinematics::EffectContext& context,
                                 const Eigen::VectorXd& state) const;
  void Reject(EkfUpdateResult& result, std::string reason);
  /// Folds the oldest window pose into the prior (x0, P0), linearised at the current estimate.
  void FoldOldest();
  /// Applies one accepted pose: iterated update from (x_, P_ + Q + inflation), history append.
  /// Returns the iterations; false in `ok` when the update diverged (state untouched). r0, H0:
  /// the measurement at x_, when already computed.
  int Absorb(const kinematics::PoseMeasurement& z, const kinematics::EffectContext& context,
             const Eigen::MatrixXd& inflation, bool& ok, const Eigen::VectorXd* r0 = nullptr,
             const Eigen::MatrixXd* H0 = nullptr);
  /// Runs the change test on the recent poses' whitened innovations and, on a detection,
  /// releases the change. Returns the change (or nothing). Not while converging unless `stuck`
  /// (the gate refused change_min_poses of the window's poses).
  std::optional<DetectedChange> TestForChange(bool stuck);
  /// Releases a detected change from the recent pose `onset` on: the history from there is
  /// replaced by the recent poses (gated ones included), the first with the inflation, and the
  /// window is relinearised.
  void Release(const DetectedChange& change, size_t onset);
  /// The second look (file comment) at the release whose onset is history entry k0: returns the
  /// change as renamed when its release was moved, else nothing.
  std::optional<DetectedChange> SecondLook(size_t k0);
  void UpdateStatus(double max_step_sigma);

  struct Recent {  // a pose the change test looks at
    kinematics::PoseMeasurement z;
    kinematics::EffectContext context;
    long seq = 0;
    bool accepted = false;
    Eigen::VectorXd e;   // whitened innovation at the estimate before it
    Eigen::MatrixXd A;   // whitened Jacobian
    Eigen::MatrixXd Aq;  // whitened ∂h/∂q (a joint offset's signature)
  };

  kinematics::ExtendedModel ext_;
  std::vector<int> identified_;
  EkfSettings settings_;
  Eigen::VectorXd x_fixed_;  // full length: values of the parameters not identified
  Eigen::VectorXd x_;        // the state: x_identified, then e
  Eigen::MatrixXd P_;
  Eigen::VectorXd prior_sigma_;  // per state entry
  Eigen::VectorXd q_diag_;       // process noise per update
  Eigen::VectorXd x0_;           // prior of the relinearisation passes
  Eigen::MatrixXd P0_;
  Eigen::VectorXd x_lin_;  // estimate at the last pass
  std::vector<kinematics::PoseMeasurement> history_;
  std::vector<kinematics::EffectContext> contexts_;  // one per history entry
  std::vector<Eigen::MatrixXd> inflations_;          // one per history entry (may be empty)
  std::vector<long> seqs_;                           // pose sequence number per history entry
  std::vector<Recent> recent_;                       // the change test's window
  long seq_ = 0;                                     // poses seen (valid ones)
  TrackingStatus status_ = TrackingStatus::kConverging;
  int small_steps_ = 0;
  std::vector<DetectedChange> changes_;
  long second_look_seq_ = -1;  // onset (seq) of the release awaiting its second look; −1: none
  bool second_look_alternatives_ = false;  // that release's directions are alternatives
  // The last test's step (onset pose and parameters) and how many consecutive tests found it.
  long candidate_onset_ = -1;
  std::vector<int> candidate_params_;
  int candidate_count_ = 0;
  int relinearizations_ = 0;
  int accepted_ = 0;
  int rejected_ = 0;
  std::string last_rejection_;
};

}  // namespace rcal::identification
