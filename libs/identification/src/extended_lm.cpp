#include "rcal/identification/extended_lm.hpp"

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "rcal/identification/extended_measurement.hpp"

namespace rcal::identification {

ExtendedFit FitExtended(const kinematics::ExtendedModel& ext, const std::vector<int>& identified,
                        const std::vector<kinematics::PoseMeasurement>& ms,
                        const std::vector<kinematics::EffectContext>& ctx,
                        const Eigen::VectorXd& x0, const Eigen::VectorXd& e0, bool estimate_noise) {
  if (ctx.size() != ms.size())
    throw std::invalid_argument("FitExtended: one context per measurement");
  if (x0.size() != ext.base().num_params())
    throw std::invalid_argument("FitExtended: x0 has " + std::to_string(x0.size()) +
                                " values, expected " + std::to_string(ext.base().num_params()));
  if (e0.size() != ext.num_effect_params())
    throw std::invalid_argument("FitExtended: e0 has " + std::to_string(e0.size()) +
                                " values, expected " + std::to_string(ext.num_effect_params()));
  const int ng = identified.size(), ne = ext.num_effect_params(), np = ng + ne;
  ExtendedFit f{x0, e0, Eigen::VectorXd::Zero(ne), 0};
  int rows = 0;
  for (const auto& m : ms) rows += m.dimension();
  const auto build = [&](const Eigen::VectorXd& x, const Eigen::VectorXd& e, Eigen::MatrixXd* A,
                         Eigen::VectorXd& b) {
    b.resize(rows);
    if (A) A->resize(rows, np);
    int row = 0;
    Eigen::VectorXd r;
    Eigen::MatrixXd H;
    for (size_t i = 0; i < ms.size(); ++i) {
      const auto& m = ms[i];
      const int d = m.dimension();
      ExtendedResidualAndJacobian(ext, m, ctx[i], x, e, identified, r, A ? &H : nullptr);
      const Eigen::LLT<Eigen::MatrixXd> llt(m.covariance);
      b.segment(row, d) = llt.matrixL().solve(r);
      if (A) A->middleRows(row, d) = llt.matrixL().solve(H);
      row += d;
    }
  };
  const auto apply = [&](const Eigen::VectorXd& delta, Eigen::VectorXd& x, Eigen::VectorXd& e) {
    for (int c = 0; c < ng; ++c) x(identified[c]) += delta(c);
    e += delta.tail(ne);
  };
  Eigen::MatrixXd A;
  Eigen::VectorXd b;
  double lambda = 1e-6;
  build(f.x, f.e, &A, b);
  double cost = b.squaredNorm();
  for (int it = 0; it < 30; ++it) {
    Eigen::VectorXd scale(np);
    for (int c = 0; c < np; ++c) scale(c) = A.col(c).norm() > 0 ? 1.0 / A.col(c).norm() : 1.0;
    const Eigen::MatrixXd As = A * scale.asDiagonal();
    Eigen::MatrixXd H = As.transpose() * As;
    H.diagonal().array() += lambda;
    const Eigen::VectorXd delta = (H.ldlt().solve(As.transpose() * b).array() * scale.array());
    Eigen::VectorXd x = f.x, e = f.e, bn;
    apply(delta, x, e);
    build(x, e, nullptr, bn);
    const double nc = bn.squaredNorm();
    if (nc <= cost) {
      const bool done = cost - nc < 1e-12 * std::max(1.0, cost);
      f.x = x;
      f.e = e;
      cost = nc;
      lambda = std::max(1e-12, lambda * 0.1);
      build(f.x, f.e, &A, b);
      if (done) break;
    } else {
      lambda *= 10;
      if (lambda > 1e6) break;
    }
  }
  // Covariance (AᵀA)⁻¹ scaled by the a-posteriori variance factor when the noise is estimated.
  const double dof = std::max(1, rows - np);
  const double s2 = estimate_noise ? cost / dof : 1.0;
  Eigen::VectorXd scale(np);
  for (int c = 0; c < np; ++c) scale(c) = A.col(c).norm() > 0 ? 1.0 / A.col(c).norm() : 1.0;
  const Eigen::MatrixXd As = A * scale.asDiagonal();
  const Eigen::MatrixXd C = (As.transpose() * As).completeOrthogonalDecomposition().pseudoInverse();
  for (int k = 0; k < ne; ++k)
    f.sigma_e(k) = std::sqrt(std::max(0.0, C(ng + k, ng + k) * s2)) * scale(ng + k);
  double ssp = 0;
  int pose_count = 0;
  for (size_t i = 0; i < ms.size(); ++i) {
    const Eigen::Vector3d r =
        ms[i].p_WM_W - ext.ForMarker(ms[i].marker).Forward(ms[i].q, ctx[i], f.x, f.e).p_WM_W;
    ssp += r.squaredNorm();
    ++pose_count;
  }
  const double redundancy = 1.0 - static_cast<double>(np) / std::max(1, rows);
  f.position_sigma_m = std::sqrt(ssp / (3.0 * pose_count * std::max(0.05, redundancy)));
  return f;
}

}  // namespace rcal::identification
