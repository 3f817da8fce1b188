#include "rcal/identification/batch_lm.hpp"

#include <Eigen/Cholesky>
#include <cmath>
#include <stdexcept>

namespace rcal::identification {
namespace {

// Whitened residual and Jacobian of all measurements stacked: r_w = L⁻¹ r, J_w = L⁻¹ H.
void Stack(const kinematics::KinematicModel& model, const std::vector<int>& identified,
           const std::vector<kinematics::PoseMeasurement>& ms, const Eigen::VectorXd& x,
           Eigen::VectorXd& r_w, Eigen::MatrixXd* J_w) {
  int rows = 0;
  for (const auto& m : ms) rows += m.dimension();
  r_w.resize(rows);
  if (J_w) J_w->resize(rows, static_cast<int>(identified.size()));
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  int row = 0;
  for (const auto& m : ms) {
    const int d = m.dimension();
    Eigen::LLT<Eigen::MatrixXd> llt(m.covariance);
    const Eigen::MatrixXd L = llt.matrixL();
    // No parameters (a set-up fit of a cell without set-up frames): no Jacobian to whiten (a
    // zero-column block has no data; solving into it bound a reference to null, UBSan).
    if (J_w && !identified.empty()) {
      kinematics::ResidualAndJacobian(model, m, x, identified, r, H);
      J_w->middleRows(row, d) = L.triangularView<Eigen::Lower>().solve(H);
    } else {
      r = kinematics::Residual(model, m, x);
    }
    r_w.segment(row, d) = L.triangularView<Eigen::Lower>().solve(r);
    row += d;
  }
}

}  // namespace

BatchLm::BatchLm(const kinematics::KinematicModel& model, std::vector<int> identified,
                 LmSettings settings)
    : model_(model), identified_(std::move(identified)), settings_(settings) {}

double BatchLm::Cost(const std::vector<kinematics::PoseMeasurement>& ms,
                     const Eigen::VectorXd& x) const {
  Eigen::VectorXd r;
  Stack(model_, identified_, ms, x, r, nullptr);
  return r.squaredNorm();
}

LmResult BatchLm::Solve(const std::vector<kinematics::PoseMeasurement>& ms,
                        const Eigen::VectorXd& x0,
                        const std::function<void(int, double)>& progress) const {
  for (size_t k = 0; k < ms.size(); ++k) {
    const std::string why = kinematics::Validate(model_, ms[k]);
    if (!why.empty()) throw std::invalid_argument("measurement " + std::to_string(k) + ": " + why);
  }
  if (x0.size() != model_.num_params())
    throw std::invalid_argument("x0: wrong size " + std::to_string(x0.size()));
  const int n = static_cast<int>(identified_.size());
  LmResult out;
  Eigen::VectorXd x = x0;
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  Stack(model_, identified_, ms, x, r, &J);
  double cost = r.squaredNorm();
  out.initial_cost = cost;
  double lambda = settings_.initial_lambda;
  for (int it = 0; it < settings_.max_iterations; ++it) {
    out.iterations = it + 1;
    const Eigen::MatrixXd A = J.transpose() * J;
    const Eigen::VectorXd g = J.transpose() * r;  // r(x + δ) ≈ r − Jδ ⇒ δ = (JᵀJ)⁻¹ Jᵀ r
    bool improved = false;
    double step_norm = 0;
    for (int tries = 0; tries < 20; ++tries) {
      Eigen::MatrixXd A_damped = A;
      A_damped.diagonal() += lambda * A.diagonal().cwiseMax(1e-12);
      const Eigen::VectorXd delta = A_damped.ldlt().solve(g);
      Eigen::VectorXd x_try = x;
      for (int i = 0; i < n; ++i) x_try(identified_[i]) += delta(i);
      Eigen::VectorXd r_try;
      Stack(model_, identified_, ms, x_try, r_try, nullptr);
      const double cost_try = r_try.squaredNorm();
      if (std::isfinite(cost_try) && cost_try < cost) {
        const double rel = (cost - cost_try) / std::max(cost, 1e-300);
        x = x_try;
        cost = cost_try;
        lambda = std::max(lambda / 10.0, 1e-12);
        step_norm = delta.norm();
        improved = true;
        Stack(model_, identified_, ms, x, r, &J);
        if (rel < settings_.relative_cost_tolerance) out.converged = true;
        break;
      }
      lambda *= 10.0;
    }
    if (progress) progress(out.iterations, cost);
    if (!improved || step_norm < settings_.step_tolerance) out.converged = true;
    if (out.converged) break;
  }
  out.x = x;
  out.cost = cost;
  out.covariance = (J.transpose() * J).ldlt().solve(Eigen::MatrixXd::Identity(n, n));
  out.sigma = Eigen::VectorXd::Zero(model_.num_params());
  for (int i = 0; i < n; ++i) out.sigma(identified_[i]) = std::sqrt(out.covariance(i, i));
  return out;
}

Eigen::MatrixXd CramerRaoBound(const kinematics::KinematicModel& model,
                               const std::vector<int>& identified,
                               const std::vector<kinematics::PoseMeasurement>& ms,
                               const Eigen::VectorXd& x) {
  const int n = static_cast<int>(identified.size());
  Eigen::MatrixXd info = Eigen::MatrixXd::Zero(n, n);
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  for (const auto& m : ms) {
    kinematics::ResidualAndJacobian(model, m, x, identified, r, H);
    info += H.transpose() * m.covariance.ldlt().solve(H);
  }
  return info.ldlt().solve(Eigen::MatrixXd::Identity(n, n));
}

}  // namespace rcal::identification
