#include "rcal/identification/change_detection.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "rcal/identification/chi_square.hpp"

namespace rcal::identification {

double ChiSquareUpperQuantileLog(double log_p, double dof) {
  if (!(log_p < 0) || !(dof > 0))
    throw std::invalid_argument("ChiSquareUpperQuantileLog: log_p must be < 0 and dof > 0");
  // ln P(X > x) decreases in x: bisect.
  double lo = 0, hi = dof + 10;
  while (ChiSquareLogUpper(hi, dof) > log_p) hi *= 2;
  for (int i = 0; i < 200 && hi - lo > 1e-9 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (ChiSquareLogUpper(mid, dof) > log_p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

namespace {

// ln C(n, k).
double LogChoose(int n, int k) {
  return std::lgamma(n + 1.0) - std::lgamma(k + 1.0) - std::lgamma(n - k + 1.0);
}

// 2 ln Λ for the columns J: b_Jᵀ N_JJ⁻¹ b_J (0 when N_JJ is singular).
double Glr(const Eigen::MatrixXd& N, const Eigen::VectorXd& b, const std::vector<int>& J,
           Eigen::VectorXd* step = nullptr, Eigen::VectorXd* sigma = nullptr) {
  const int k = static_cast<int>(J.size());
  Eigen::MatrixXd NJ(k, k);
  Eigen::VectorXd bJ(k);
  for (int i = 0; i < k; ++i) {
    bJ(i) = b(J[i]);
    for (int j = 0; j < k; ++j) NJ(i, j) = N(J[i], J[j]);
  }
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(NJ);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 1e-12 * NJ.trace())) return 0;
  const Eigen::VectorXd d = ldlt.solve(bJ);
  if (step) *step = d;
  if (sigma) *sigma = ldlt.solve(Eigen::MatrixXd::Identity(k, k)).diagonal().cwiseSqrt();
  return bJ.dot(d);
}

}  // namespace

std::vector<int> StepAlternatives(const Eigen::MatrixXd& N, const Eigen::VectorXd& b,
                                  const std::vector<int>& same_change, double probability,
                                  int max_columns, std::vector<double>* column_probability,
                                  Eigen::VectorXd* step, Eigen::VectorXd* sigma) {
  const int n = static_cast<int>(N.cols());
  if (N.rows() != n || b.size() != n)
    throw std::invalid_argument("StepAlternatives: N is " + std::to_string(N.rows()) + "×" +
                                std::to_string(n) + ", b has " + std::to_string(b.size()));
  if (!same_change.empty() && static_cast<int>(same_change.size()) != n)
    throw std::invalid_argument("StepAlternatives: same_change has " +
                                std::to_string(same_change.size()) + " labels for " +
                                std::to_string(n) + " columns");
  const double tiny = 1e-12 * std::max(N.trace(), 0.0);
  std::vector<int> order;
  std::vector<double> g(n, 0.0);
  for (int j = 0; j < n; ++j)
    if (N(j, j) > tiny && N(j, j) > 0) {
      g[j] = b(j) * b(j) / N(j, j);
      order.push_back(j);
    }
  std::stable_sort(order.begin(), order.end(), [&](int i, int j) { return g[i] > g[j]; });
  // One hypothesis per change: a column that is another one's change under another name, or
  // exactly parallel to it, counts once.
  std::vector<int> distinct;
  for (int j : order) {
    bool twin = false;
    for (int i : distinct)
      twin = twin ||
             (!same_change.empty() && same_change[i] >= 0 && same_change[i] == same_change[j]) ||
             std::abs(N(i, j)) > (1 - 1e-9) * std::sqrt(N(i, i) * N(j, j));
    if (!twin) distinct.push_back(j);
  }
  std::vector<int> out;
  if (distinct.empty()) return out;
  // p_j = exp(g_j/2) / Σ exp(g_i/2), summed from the largest (log-sum-exp).
  double log_sum = 0;
  for (int j : distinct) log_sum += std::exp(0.5 * (g[j] - g[distinct[0]]));
  log_sum = 0.5 * g[distinct[0]] + std::log(log_sum);
  std::vector<double> p;
  double mass = 0;
  for (int j : distinct) {
    if (static_cast<int>(out.size()) >= std::max(1, max_columns)) break;
    if (!out.empty() && mass >= probability) break;
    out.push_back(j);
    p.push_back(std::exp(0.5 * g[j] - log_sum));
    mass += p.back();
  }
  if (column_probability) *column_probability = p;
  const int m = static_cast<int>(out.size());
  if (step) step->resize(m);
  if (sigma) sigma->resize(m);
  for (int i = 0; i < m; ++i) {
    if (step) (*step)(i) = b(out[i]) / N(out[i], out[i]);
    if (sigma) (*sigma)(i) = 1 / std::sqrt(N(out[i], out[i]));
  }
  return out;
}

StepTestResult TestForStep(const std::vector<Eigen::VectorXd>& e,
                           const std::vector<Eigen::MatrixXd>& A, const StepTestSettings& s) {
  if (e.size() != A.size())
    throw std::invalid_argument("TestForStep: " + std::to_string(e.size()) + " innovations, " +
                                std::to_string(A.size()) + " Jacobians");
  StepTestResult best;
  const int L = static_cast<int>(e.size());
  if (L == 0 || L < s.min_poses) return best;
  const int n = static_cast<int>(A[0].cols());
  for (int k = 0; k < L; ++k)
    if (A[k].rows() != e[k].size() || A[k].cols() != n)
      throw std::invalid_argument("TestForStep: pose " + std::to_string(k) +
                                  ": Jacobian size does not match");
  if (!s.same_change.empty() && static_cast<int>(s.same_change.size()) != n)
    throw std::invalid_argument("TestForStep: same_change has " +
                                std::to_string(s.same_change.size()) + " labels for " +
                                std::to_string(n) + " columns");
  const int onsets = L - std::max(1, s.min_poses) + 1;
  const int max_k = std::min(s.max_params, n);
  std::vector<double> threshold(max_k + 1);
  for (int k = 1; k <= max_k; ++k)
    threshold[k] = ChiSquareUpperQuantileLog(
        std::log(s.false_alarm) - LogChoose(n, k) - std::log(static_cast<double>(onsets)), k);

  Eigen::MatrixXd N = Eigen::MatrixXd::Zero(n, n);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(n);
  double c = 0;
  int dims = 0;
  double best_margin = -std::numeric_limits<double>::infinity();
  int best_k = max_k + 1;
  Eigen::MatrixXd best_N;  // N and b at the claimed single-parameter step's onset
  Eigen::VectorXd best_b;
  // Onsets from the newest back, accumulating the poses since each.
  for (int tau = L - 1; tau >= 0; --tau) {
    N.noalias() += A[tau].transpose() * A[tau];
    b.noalias() += A[tau].transpose() * e[tau];
    c += e[tau].squaredNorm();
    dims += static_cast<int>(e[tau].size());
    if (L - tau < std::max(1, s.min_poses)) continue;
    std::vector<int> J;
    for (int k = 1; k <= max_k; ++k) {
      int pick = -1;
      double g_pick = -1;
      for (int j = 0; j < n; ++j) {
        if (std::find(J.begin(), J.end(), j) != J.end()) continue;
        J.push_back(j);
        const double g = Glr(N, b, J);
        J.pop_back();
        if (g > g_pick) g_pick = g, pick = j;
      }
      if (pick < 0) break;
      J.push_back(pick);
      const double post = std::max(0.0, c - g_pick);
      const int dof = dims - k;
      const bool fits = dof <= 0 || post < ChiSquareQuantile(s.fit_probability, dof);
      const bool detected = g_pick > threshold[k] && fits;
      // Prefer fewer parameters, then the larger margin over the threshold.
      const double margin = g_pick - threshold[k];
      const bool better =
          detected ? (!best.detected || k < best_k || (k == best_k && margin > best_margin))
                   : (!best.detected && g_pick - threshold[k] > best_margin);
      if (better) {
        best.detected = detected;
        best.onset = tau;
        best.columns = J;
        best.glr = Glr(N, b, J, &best.step, &best.step_sigma);
        best.threshold = threshold[k];
        best.post_fit_chi2 = post;
        best_margin = margin;
        if (detected) best_k = k;
        if (detected && k == 1) best_N = N, best_b = b;
      }
      if (detected) break;  // no need for more parameters at this onset
    }
  }
  if (best.detected && best.columns.size() == 1 && s.naming_probability > 0) {
    std::vector<double> p;
    Eigen::VectorXd step, sigma;
    const std::vector<int> alt = StepAlternatives(best_N, best_b, s.same_change,
                                                  s.naming_probability, max_k, &p, &step, &sigma);
    if (alt.size() > 1 && alt[0] == best.columns[0]) {
      best.alternatives = alt;
      best.alternative_probability = p;
      best.alternative_step = step;
      best.alternative_sigma = sigma;
    }
  }
  return best;
}

}  // namespace rcal::identification
