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
//
// Which parameter stepped: a single-parameter step along column j from τ on has likelihood
// ∝ exp(g_j / 2), g_j = b_j² / N_jj. With no reason to expect one column more than another (equal
// priors), the probability that column j is the one is exp(g_j / 2) / Σ_i exp(g_i / 2). A few
// poses after a step, two columns that move the tool almost alike (a wrist parameter and its
// neighbour) can share that probability; the test then reports them as alternatives: the fewest
// columns, most probable first, whose probabilities add up to `naming_probability`. Columns that
// are one change under two names (a joint's offset and the parameter that is it over the window,
// as the caller labels them; or columns exactly parallel over the poses) count once.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace rcal::identification {

struct StepTestSettings {
  double false_alarm = 1e-7;        ///< probability per test of claiming a step on white noise
  int min_poses = 3;                ///< poses since the onset before a step can be claimed
  int max_params = 3;               ///< parameters a step may involve
  double fit_probability = 0.9999;  ///< post-fit χ² quantile the step must explain the poses to
  /// A single-parameter step names the fewest columns whose probability of being the one adds up
  /// to this (file comment); 0: only the most likely column.
  double naming_probability = 0;
  /// Per column, a label: columns with the same label ≥ 0 are one change under two names (they
  /// count once among the alternatives); empty, or −1: each column its own.
  std::vector<int> same_change;
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
  /// A single-parameter step the poses cannot pin on one column (file comment): the columns it
  /// may be, most probable first (alternatives[0] == columns[0]), each with its probability and
  /// its own single-column step and 1σ. Empty when one column holds naming_probability alone or
  /// the step involves several parameters.
  std::vector<int> alternatives;
  std::vector<double> alternative_probability;
  Eigen::VectorXd alternative_step, alternative_sigma;
};

/// The columns a single-parameter step may be along (file comment), given N = Σ AᵀA and
/// b = Σ Aᵀe over the poses since the onset: the fewest, most probable first, whose
/// probabilities add up to `probability`, at most `max_columns`. `same_change` as in
/// StepTestSettings (empty or one label per column); exactly parallel columns (|cos| > 1 − 1e-9)
/// count once too. Returns the columns and fills their probabilities, steps and 1σ. Throws
/// std::invalid_argument naming the input when sizes do not match.
std::vector<int> StepAlternatives(const Eigen::MatrixXd& N, const Eigen::VectorXd& b,
                                  const std::vector<int>& same_change, double probability,
                                  int max_columns,
                                  std::vector<double>* column_probability = nullptr,
                                  Eigen::VectorXd* step = nullptr,
                                  Eigen::VectorXd* sigma = nullptr);

/// The x with ln P(X > x) = log_p for X ~ χ²(dof) (log_p < 0): a threshold for probabilities
/// far below what 1 − p can hold.
double ChiSquareUpperQuantileLog(double log_p, double dof);

/// e[k]: whitened innovations (any length per pose), A[k]: whitened Jacobians (same rows, one
/// column per parameter, every pose the same columns), oldest first. Throws std::invalid_argument
/// naming the input when sizes do not match.
StepTestResult TestForStep(const std::vector<Eigen::VectorXd>& e,
                           const std::vector<Eigen::MatrixXd>& A, const StepTestSettings& s);

}  // namespace rcal::identification
