#include "rcal/identification/extended_lm.hpp"

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "rcal/identification/extended_measurement.hpp"

namespace rcal::identification {

Eigen::VectorXd GeometryAt(const Eigen::VectorXd& x, const std::vector<GeometryStep>& steps,
                           const std::vector<Eigen::VectorXd>& amplitudes, int pose) {
  Eigen::VectorXd xi = x;
  for (size_t s = 0; s < steps.size(); ++s)
    if (steps[s].first_pose <= pose) xi += steps[s].directions * amplitudes[s];
  return xi;
}

ExtendedFit FitExtended(const kinematics::ExtendedModel& ext, const std::vector<int>& identified,
                        const std::vector<kinematics::PoseMeasurement>& ms,
                        const std::vector<kinematics::EffectContext>& ctx,
                        const Eigen::VectorXd& x0, const Eigen::VectorXd& e0, bool estimate_noise,
                        const std::vector<GeometryStep>& steps) {
  if (ctx.size() != ms.size())
    throw std::invalid_argument("FitExtended: one context per measurement");
  if (x0.size() != ext.base().num_params())
    throw std::invalid_argument("FitExtended: x0 has " + std::to_string(x0.size()) +
                                " values, expected " + std::to_string(ext.base().num_params()));
  if (e0.size() != ext.num_effect_params())
    throw std::invalid_argument("FitExtended: e0 has " + std::to_string(e0.size()) +
                                " values, expected " + std::to_string(ext.num_effect_params()));
  const int nx = ext.base().num_params();
  int na = 0;  // step amplitudes
  for (size_t s = 0; s < steps.size(); ++s) {
    const std::string name = "FitExtended: steps[" + std::to_string(s) + "]";
    if (steps[s].first_pose < 1 || steps[s].first_pose >= static_cast<int>(ms.size()))
      throw std::invalid_argument(name + ".first_pose " + std::to_string(steps[s].first_pose) +
                                  " is not in 1 … " + std::to_string(ms.size() - 1));
    if (steps[s].directions.rows() != nx || steps[s].directions.cols() < 1 ||
        !steps[s].directions.allFinite())
      throw std::invalid_argument(name + ".directions: " + std::to_string(nx) +
                                  " finite rows and at least one column expected");
    na += steps[s].directions.cols();
  }
  const int ng = identified.size(), ne = ext.num_effect_params(), np = ng + ne + na;
  ExtendedFit f{x0, e0, Eigen::VectorXd::Zero(ne), 0, {}, {}};
  for (const auto& st : steps) {
    f.step_amplitudes.push_back(Eigen::VectorXd::Zero(st.directions.cols()));
    f.step_sigma.push_back(Eigen::VectorXd::Zero(st.directions.cols()));
  }
  std::vector<int> all_params(nx);  // the Jacobian a step's columns are taken from
  for (int c = 0; c < nx; ++c) all_params[c] = c;
  int rows = 0;
  for (const auto& m : ms) rows += m.dimension();
  const auto build = [&](const Eigen::VectorXd& x, const Eigen::VectorXd& e,
                         const std::vector<Eigen::VectorXd>& a, Eigen::MatrixXd* A,
                         Eigen::VectorXd& b) {
    b.resize(rows);
    if (A) A->resize(rows, np);
    int row = 0;
    Eigen::VectorXd r;
    Eigen::MatrixXd H, Hall;
    for (size_t i = 0; i < ms.size(); ++i) {
      const auto& m = ms[i];
      const int d = m.dimension();
      if (steps.empty()) {
        ExtendedResidualAndJacobian(ext, m, ctx[i], x, e, identified, r, A ? &H : nullptr);
      } else {
        // Every geometric column, then [identified | e | the active steps' J_x·D].
        const Eigen::VectorXd xi = GeometryAt(x, steps, a, static_cast<int>(i));
        ExtendedResidualAndJacobian(ext, m, ctx[i], xi, e, all_params, r, A ? &Hall : nullptr);
        if (A) {
          H = Eigen::MatrixXd::Zero(d, np);
          for (int c = 0; c < ng; ++c) H.col(c) = Hall.col(identified[c]);
          H.middleCols(ng, ne) = Hall.rightCols(ne);
          for (int s = 0, c = ng + ne; s < static_cast<int>(steps.size()); ++s) {
            const int k = steps[s].directions.cols();
            if (steps[s].first_pose <= static_cast<int>(i))
              H.middleCols(c, k) = Hall.leftCols(nx) * steps[s].directions;
            c += k;
          }
        }
      }
      const Eigen::LLT<Eigen::MatrixXd> llt(m.covariance);
      b.segment(row, d) = llt.matrixL().solve(r);
      if (A) A->middleRows(row, d) = llt.matrixL().solve(H);
      row += d;
    }
  };
  const auto apply = [&](const Eigen::VectorXd& delta, Eigen::VectorXd& x, Eigen::VectorXd& e,
                         std::vector<Eigen::VectorXd>& a) {
    for (int c = 0; c < ng; ++c) x(identified[c]) += delta(c);
    e += delta.segment(ng, ne);
    for (size_t s = 0, c = ng + ne; s < a.size(); c += a[s].size(), ++s)
      a[s] += delta.segment(c, a[s].size());
  };
  Eigen::MatrixXd A;
  Eigen::VectorXd b;
  double lambda = 1e-6;
  build(f.x, f.e, f.step_amplitudes, &A, b);
  double cost = b.squaredNorm();
  for (int it = 0; it < 30; ++it) {
    Eigen::VectorXd scale(np);
    for (int c = 0; c < np; ++c) scale(c) = A.col(c).norm() > 0 ? 1.0 / A.col(c).norm() : 1.0;
    const Eigen::MatrixXd As = A * scale.asDiagonal();
    Eigen::MatrixXd H = As.transpose() * As;
    H.diagonal().array() += lambda;
    const Eigen::VectorXd delta = (H.ldlt().solve(As.transpose() * b).array() * scale.array());
    Eigen::VectorXd x = f.x, e = f.e, bn;
    std::vector<Eigen::VectorXd> a = f.step_amplitudes;
    apply(delta, x, e, a);
    build(x, e, a, nullptr, bn);
    const double nc = bn.squaredNorm();
    if (nc <= cost) {
      const bool done = cost - nc < 1e-12 * std::max(1.0, cost);
      f.x = x;
      f.e = e;
      f.step_amplitudes = a;
      cost = nc;
      lambda = std::max(1e-12, lambda * 0.1);
      build(f.x, f.e, f.step_amplitudes, &A, b);
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
  const auto sigma = [&](int c) { return std::sqrt(std::max(0.0, C(c, c) * s2)) * scale(c); };
  for (int k = 0; k < ne; ++k) f.sigma_e(k) = sigma(ng + k);
  for (size_t s = 0, c = ng + ne; s < steps.size(); c += f.step_sigma[s].size(), ++s)
    for (int k = 0; k < f.step_sigma[s].size(); ++k) f.step_sigma[s](k) = sigma(c + k);
  double ssp = 0;
  int pose_count = 0;
  for (size_t i = 0; i < ms.size(); ++i) {
    const Eigen::VectorXd xi = GeometryAt(f.x, steps, f.step_amplitudes, static_cast<int>(i));
    const Eigen::Vector3d r =
        ms[i].p_WM_W - ext.ForMarker(ms[i].marker).Forward(ms[i].q, ctx[i], xi, f.e).p_WM_W;
    ssp += r.squaredNorm();
    ++pose_count;
  }
  const double redundancy = 1.0 - static_cast<double>(np) / std::max(1, rows);
  f.position_sigma_m = std::sqrt(ssp / (3.0 * pose_count * std::max(0.05, redundancy)));
  return f;
}

}  // namespace rcal::identification
