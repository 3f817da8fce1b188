// A step in a few parameters, tested on whitened innovations (a generalised likelihood ratio).
//
// The identifier whitens each pose's innovation with its innovation covariance S = H P Hᵀ + R:
// e_k = L_k⁻¹ r_k and A_k = L_k⁻¹ H_k (S_k = L_k L_kᵀ). An unchanged arm gives e_k ~ N(0, I).
// A step δ in the parameters J from pose τ on gives e_k ≈ A_k,J δ + noise for k ≥ τ, so
//   2 ln Λ(τ, J) = b_Jᵀ N_JJ⁻¹ b_J,   N = Σ_{k≥τ} A_kᵀ A_k,  b = Σ_{k≥τ} A_kᵀ e_k,
// which under no change is χ²(|J|). δ̂ = N_JJ⁻¹ b_J, with covariance N_JJ⁻¹.
// The test tries every onset τ with at least `min_poses` poses after it and grows J by forward
// selection up to `max_params` parameters. A step is claimed when 2 ln Λ passes the χ²(|J|)
// quantile at false_alarm / (number of subsets of that size × onsets) (Bonferroni: the rate holds
// for the maximum) and the step explains the poses since τ: the post-fit χ² Σ|e_k|² − 2 ln Λ
// stays below its quantile at fit_probability. A single outlier pose is explained by no step in
// a few parameters, so it raises no change (the gate handles it).
#pragma once

#include <Eigen/Core>
#include <vector>

namespace rcal::identification {

struct StepTestSettings {
  double false_alarm = 1e-7;        ///< probability per test of claiming a step on white noise
  int min_poses = 3;                ///< poses since the onset before a step can be claimed
  int max_params = 3;               ///< parameters a step may involve
  double fit_probability = 0.9999;  ///< post-fit χ² quantile the step must explain the poses to
};

struct StepTestResult {
  bool detected = false;
  int onset = -1;              ///< index of the first changed pose in the input
  std::vector<int> columns;    ///< the parameters (columns of A), in order of selection
  Eigen::VectorXd step;        ///< δ̂ for each column [units of the columns]
  Eigen::VectorXd step_sigma;  ///< its 1σ
  double glr = 0;              ///< 2 ln Λ of the claimed (or the largest tried) step
  double threshold = 0;        ///< the χ² threshold it was compared with
  double post_fit_chi2 = 0;    ///< Σ|e_k|² − 2 ln Λ over the poses since the onset
};

/// The x with ln P(X > x) = log_p for X ~ χ²(dof) (log_p < 0): a threshold for probabilities
/// far below what 1 − p can hold.
double ChiSquareUpperQuantileLog(double log_p, double dof);

/// e[k]: whitened innovations (any length per pose), A[k]: whitened Jacobians (same rows, one
/// column per parameter, every pose the same columns), oldest first. Throws std::invalid_argument
/// naming the input when sizes do not match.
StepTestResult TestForStep(const std::vector<Eigen::VectorXd>& e,
                           const std::vector<Eigen::MatrixXd>& A, const StepTestSettings& s);

}  // namespace rcal::identification
