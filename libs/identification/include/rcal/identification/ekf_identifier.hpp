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
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

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
};

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
  Eigen::VectorXd x0, x, x_lin;  ///< prior, estimate, last relinearisation point (identified)
  Eigen::MatrixXd P0, P;
  std::vector<kinematics::PoseMeasurement> history;  ///< accepted poses
  int accepted = 0, rejected = 0, relinearizations = 0;
};

class EkfIdentifier {
 public:
  /// `identified`: indices into model.parameters() to estimate. The other parameters keep the
  /// values of `x_fixed` (full length [m | rad]; empty: 0, the nominal model).
  EkfIdentifier(const kinematics::KinematicModel& model, std::vector<int> identified,
                EkfSettings settings = {}, Eigen::VectorXd x_fixed = {});

  /// Back to the prior: x = 0, P = diag(prior σ²), counts zeroed.
  void Reset();
  /// Replaces the state (restoring a checkpoint); the restored state becomes the prior of later
  /// relinearisation passes. Throws std::invalid_argument naming the field if sizes differ or
  /// values are not finite.
  void SetState(const Eigen::VectorXd& x_identified, const Eigen::MatrixXd& P);

  /// The whole state, and its exact restoration. Restore throws std::invalid_argument naming the
  /// field when the checkpoint does not fit this model and parameter set; the state is then
  /// unchanged.
  EkfCheckpoint Checkpoint() const;
  void Restore(const EkfCheckpoint& c);

  /// One still-pose measurement. Never throws on bad data: a rejection is reported and counted.
  EkfUpdateResult Update(const kinematics::PoseMeasurement& z);

  /// Full-length error vector (x_fixed where not identified) [m | rad].
  Eigen::VectorXd x() const;
  const Eigen::VectorXd& x_identified() const { return x_; }
  /// Covariance of x_identified().
  const Eigen::MatrixXd& P() const { return P_; }
  /// Full-length 1σ; 0 where not identified.
  Eigen::VectorXd sigma() const;
  const std::vector<int>& identified() const { return identified_; }
  const kinematics::KinematicModel& model() const { return model_; }
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

  kinematics::KinematicModel model_;
  std::vector<int> identified_;
  EkfSettings settings_;
  Eigen::VectorXd x_fixed_;  // full length: values of the parameters not identified
  Eigen::VectorXd x_;
  Eigen::MatrixXd P_;
  Eigen::VectorXd q_diag_;  // process noise per update
  Eigen::VectorXd x0_;      // prior of the relinearisation passes
  Eigen::MatrixXd P0_;
  Eigen::VectorXd x_lin_;  // estimate at the last pass
  std::vector<kinematics::PoseMeasurement> history_;
  int relinearizations_ = 0;
  int accepted_ = 0;
  int rejected_ = 0;
  std::string last_rejection_;
};

}  // namespace rcal::identification
