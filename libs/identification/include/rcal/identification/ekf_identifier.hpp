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

struct EkfUpdateResult {
  bool accepted = false;
  double nis = 0;      ///< normalised innovation squared at the prior
  double gate = 0;     ///< the χ² threshold it was compared with
  int iterations = 0;  ///< relinearisations done
  std::string reason;  ///< why it was rejected, naming the field
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
  /// Relinearisation passes run so far.
  int relinearizations() const { return relinearizations_; }

 private:
  int Relinearize(int max_passes);
  /// The measurement function: r = z − h and H = ∂h/∂state at `state`.
  void Measure(const kinematics::PoseMeasurement& z, const kinematics::EffectContext& context,
               const Eigen::VectorXd& state, Eigen::VectorXd& r, Eigen::MatrixXd& H) const;
  void Reject(EkfUpdateResult& result, std::string reason);

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
  int relinearizations_ = 0;
  int accepted_ = 0;
  int rejected_ = 0;
  std::string last_rejection_;
};

}  // namespace rcal::identification
