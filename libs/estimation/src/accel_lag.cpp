#include "rcal/estimation/accel_lag.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>

#include "rcal/geometry/so3.hpp"

namespace rcal::estimation {
namespace {

using Row = Eigen::Matrix<double, 3, 7>;  // ∂(y − ∫aM)/∂θ, θ = (δ, r_B, b_W)

// One triplet's rows: the regressors and the left-hand side y − ∫ a M.
struct Triplet {
  Row A;
  Eigen::Vector3d y;
};

template <class V>
bool AllFinite(const std::vector<V>& v, std::size_t* bad) {
  for (std::size_t i = 0; i < v.size(); ++i)
    if (!v[i].allFinite()) {
      *bad = i;
      return false;
    }
  return true;
}

std::string Sample(const char* field, std::size_t i) {
  std::ostringstream o;
  o << "accel_lag: " << field << " [" << i << "]";
  return o.str();
}

// The weighted normal equations of triplets [first, last); w per triplet.
struct Normal {
  Eigen::Matrix<double, 7, 7> N = Eigen::Matrix<double, 7, 7>::Zero();
  Eigen::Matrix<double, 7, 1> b = Eigen::Matrix<double, 7, 1>::Zero();
};
Normal Accumulate(const std::vector<Triplet>& tr, const std::vector<double>& w, std::size_t first,
                  std::size_t last) {
  Normal n;
  for (std::size_t j = first; j < last; ++j) {
    const Row WA = w[j] * tr[j].A;
    n.N += tr[j].A.transpose() * WA;
    n.b += WA.transpose() * tr[j].y;
  }
  return n;
}

Result<Eigen::Matrix<double, 7, 1>> Solve(const Normal& n) {
  // The lag is read from the jerk column, the lever arm from the rotation: without either the
  // system is singular.
  const Eigen::LDLT<Eigen::Matrix<double, 7, 7>> ldlt(n.N);
  const double scale = n.N.diagonal().maxCoeff();
  if (ldlt.info() != Eigen::Success || !(scale > 0.0) ||
      !(ldlt.vectorD().cwiseAbs().minCoeff() > 1e-12 * scale))
    return Result<Eigen::Matrix<double, 7, 1>>::Error(
        "accel_lag: the recording does not determine the lag (no motion, or no rotation for "
        "the lever arm)");
  return Eigen::Matrix<double, 7, 1>(ldlt.solve(n.b));
}

double Median(std::vector<double> v) {
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

}  // namespace

Result<AccelLagEstimate> EstimateAccelLag(const AccelLagData& d, const AccelLagSettings& s) {
  using R = Result<AccelLagEstimate>;
  const std::size_t n = d.t_imu.size(), m = d.t_position.size();
  if (d.f_B.size() != n || d.R_EB.size() != n || d.omega_B.size() != n)
    return R::Error("accel_lag: f_B, R_EB and omega_B must have one entry per t_imu");
  if (d.p_WM_W.size() != m) return R::Error("accel_lag: p_WM_W must have one entry per t_position");
  if (!(s.blocks >= 2) || !(s.min_triplets_per_block >= 1) || !(s.max_step_ratio >= 1.0) ||
      !(s.max_imu_step > 0.0) || !std::isfinite(s.gravity) || !s.R_WE.allFinite())
    return R::Error("accel_lag: settings out of range (blocks ≥ 2, max_step_ratio ≥ 1, ...)");
  std::size_t bad = 0;
  for (const auto& [v, field] :
       {std::pair{&d.t_imu, "t_imu"}, std::pair{&d.t_position, "t_position"}})
    for (std::size_t i = 0; i < v->size(); ++i)
      if (!std::isfinite((*v)[i]) || (i > 0 && !((*v)[i] > (*v)[i - 1])))
        return R::Error(Sample(field, i) + " is not finite or not after the one before");
  if (!AllFinite(d.f_B, &bad)) return R::Error(Sample("f_B", bad) + " is not finite");
  if (!AllFinite(d.R_EB, &bad)) return R::Error(Sample("R_EB", bad) + " is not finite");
  if (!AllFinite(d.omega_B, &bad)) return R::Error(Sample("omega_B", bad) + " is not finite");
  if (!AllFinite(d.p_WM_W, &bad)) return R::Error(Sample("p_WM_W", bad) + " is not finite");
  if (n < 3) return R::Error("accel_lag: fewer than three IMU samples");

  // Per IMU sample: a = R_WE (R_EB f − g·up), R_WB ([α]× + [ω]×²), and R_WB ḟ_B (δ's column), α
  // by central differences.
  const Eigen::Vector3d g_up = s.gravity * UpVector(s.earth);
  std::vector<Eigen::Vector3d> a(n), f_dot_W(n);
  std::vector<Eigen::Matrix3d> L(n);
  for (std::size_t k = 0; k < n; ++k) a[k] = s.R_WE * (d.R_EB[k] * d.f_B[k] - g_up);
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t lo = k == 0 ? 0 : k - 1, hi = k + 1 == n ? k : k + 1;
    const double span = d.t_imu[hi] - d.t_imu[lo];
    f_dot_W[k] = s.R_WE * d.R_EB[k] * (d.f_B[hi] - d.f_B[lo]) / span;
    const Eigen::Vector3d alpha_B = (d.omega_B[hi] - d.omega_B[lo]) / span;
    const Eigen::Matrix3d W = geometry::Skew(d.omega_B[k]);
    L[k] = s.R_WE * d.R_EB[k] * (geometry::Skew(alpha_B) + W * W);
  }

  // The triplets (header comment): y = 2 p[t₀, t₁, t₂] against ∫ (·) M by the trapezoid.
  std::vector<Triplet> tr;
  for (std::size_t j = 1; j + 1 < m; ++j) {
    const double t0 = d.t_position[j - 1], t1 = d.t_position[j], t2 = d.t_position[j + 1];
    const double h1 = t1 - t0, h2 = t2 - t1;
    if (std::max(h1, h2) > s.max_step_ratio * std::min(h1, h2)) continue;
    const auto first = std::lower_bound(d.t_imu.begin(), d.t_imu.end(), t0);
    const auto last = std::upper_bound(d.t_imu.begin(), d.t_imu.end(), t2);
    if (first == d.t_imu.begin() || last == d.t_imu.end()) continue;  // not covered
    const std::size_t k0 = static_cast<std::size_t>(first - d.t_imu.begin()) - 1;
    const std::size_t k1 = static_cast<std::size_t>(last - d.t_imu.begin());  // t_imu[k1] > t2
    bool gap = false;
    for (std::size_t k = k0; k < k1 && !gap; ++k)
      gap = d.t_imu[k + 1] - d.t_imu[k] > s.max_imu_step;
    if (gap) continue;
    Triplet t;
    t.A.setZero();
    Eigen::Vector3d int_a = Eigen::Vector3d::Zero();
    double sum_w = 0.0;
    for (std::size_t k = k0 + 1; k < k1; ++k) {
      const double tk = d.t_imu[k];
      const double hat = tk <= t1 ? (tk - t0) / h1 : (t2 - tk) / h2;  // M ∝ hat on [t₀, t₂]
      const double w = hat * 0.5 * (std::min(d.t_imu[k + 1], t2) - std::max(d.t_imu[k - 1], t0));
      if (!(w > 0.0)) continue;
      sum_w += w;
      int_a += w * a[k];
      t.A.col(0) += w * f_dot_W[k];
      t.A.middleCols<3>(1) += w * L[k];
    }
    if (!(sum_w > 0.0)) continue;
    t.A.leftCols<4>() /= sum_w;
    t.A.rightCols<3>() = -Eigen::Matrix3d::Identity();  // z = A − R_WB M r_B + b_W
    const Eigen::Vector3d y =
        2.0 * ((d.p_WM_W[j + 1] - d.p_WM_W[j]) / h2 - (d.p_WM_W[j] - d.p_WM_W[j - 1]) / h1) /
        (t2 - t0);
    t.y = y - int_a / sum_w;
    tr.push_back(t);
  }
  const std::size_t per_block = tr.size() / static_cast<std::size_t>(s.blocks);
  if (per_block < static_cast<std::size_t>(s.min_triplets_per_block)) {
    std::ostringstream o;
    o << "accel_lag: " << tr.size() << " usable position triplets, fewer than " << s.blocks
      << " blocks of " << s.min_triplets_per_block;
    return R::Error(o.str());
  }

  // Huber-reweighted least squares (a few passes), one weight per triplet: the smallest over its
  // axes, since a tap turned into W reaches every axis, and its ȧ makes the triplet a leverage
  // point that a per-axis weight still lets pull (the taps of AccelLag.TapsDoNotPullTheLag: 2.69
  // ms per axis, 2.97 ms per triplet, true 3; Tukey's biweight, 5.4 ms, is worse still).
  std::vector<double> w(tr.size(), 1.0);
  auto theta = Solve(Accumulate(tr, w, 0, tr.size()));
  if (!theta) return R::Error(theta.error());
  for (int pass = 0; pass < 6; ++pass) {
    Eigen::Vector3d sigma;
    for (int i = 0; i < 3; ++i) {
      std::vector<double> r(tr.size());
      for (std::size_t j = 0; j < tr.size(); ++j)
        r[j] = std::abs(tr[j].y(i) - tr[j].A.row(i).dot(*theta));
      sigma(i) = std::max(1.4826 * Median(r), 1e-12);
    }
    for (std::size_t j = 0; j < tr.size(); ++j) {
      double u = 0.0;
      for (int i = 0; i < 3; ++i)
        u = std::max(u, std::abs(tr[j].y(i) - tr[j].A.row(i).dot(*theta)) / sigma(i));
      w[j] = u <= kAccelLagHuber ? 1.0 : kAccelLagHuber / u;
    }
    theta = Solve(Accumulate(tr, w, 0, tr.size()));
    if (!theta) return R::Error(theta.error());
  }

  AccelLagEstimate e;
  e.delay = (*theta)(0);
  e.lever_arm_B = theta->segment<3>(1);
  e.bias_W = theta->tail<3>();
  e.triplets = static_cast<int>(tr.size());
  double r2 = 0.0, j2 = 0.0;
  for (const Triplet& t : tr) {
    r2 += (t.y - t.A * *theta).squaredNorm();
    j2 += t.A.col(0).squaredNorm();
  }
  e.residual_rms = std::sqrt(r2 / (3.0 * static_cast<double>(tr.size())));
  e.jerk_rms = std::sqrt(j2 / (3.0 * static_cast<double>(tr.size())));
  // σ_δ: the delete-one-block jackknife over contiguous blocks (header comment), weights fixed.
  std::vector<Normal> block;
  Normal all;
  for (int b = 0; b < s.blocks; ++b) {
    const std::size_t first = static_cast<std::size_t>(b) * per_block;
    const std::size_t last = b + 1 == s.blocks ? tr.size() : first + per_block;
    block.push_back(Accumulate(tr, w, first, last));
    all.N += block.back().N;
    all.b += block.back().b;
  }
  std::vector<double> delays;
  for (const Normal& nb : block) {
    auto tb = Solve(Normal{all.N - nb.N, all.b - nb.b});
    if (!tb) return R::Error(tb.error() + " (without one block of the recording)");
    delays.push_back((*tb)(0));
  }
  const double B = static_cast<double>(delays.size());
  double mean = 0.0, ss = 0.0;
  for (double x : delays) mean += x / B;
  for (double x : delays) ss += (x - mean) * (x - mean);
  e.delay_sigma = std::sqrt((B - 1.0) / B * ss);
  return e;
}

}  // namespace rcal::estimation
