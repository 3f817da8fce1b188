#include "rcal/estimation/accel_lag.hpp"

#include <Eigen/Cholesky>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>

#include "rcal/geometry/so3.hpp"
#include "rcal/numeric/median.hpp"

namespace rcal::estimation {
namespace {

// θ = (δ, r_B, b_W[, φ]): 7 unknowns, 10 with the frame. Fixed capacity, so that a row per
// triplet and the normal equations of every Gauss–Newton pass allocate nothing.
constexpr int kMaxUnknowns = 10;
using Vec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxUnknowns, 1>;
using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxUnknowns, kMaxUnknowns>;
using Rows = Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxUnknowns>;  // ∂(y − ∫aM)/∂θ

// One triplet in the earth frame E, before the position sensor's frame W is applied: the
// hat-weighted integrals of the linear acceleration a_E = R_EB f − g·up (u_E), of δ's column R_EB ḟ
// and of the lever arm's R_EB M (B_E, four columns), and the position sensor's second divided
// difference y_W (twice it, in W).
struct Triplet {
  Eigen::Vector3d u_E, y_W;
  Eigen::Matrix<double, 3, 4> B_E;
};

// A triplet's rows in W for a frame R_WE: y = y_W − R_WE u_E against θ = (δ, r_B, b_W[, φ]),
// A = [R_WE B_E, −I[, −[R_WE u_E]×]] (φ: a small rotation of W on the left, R_WE ← Exp(φ) R_WE).
struct Row {
  Rows A;
  Eigen::Vector3d y;
};
std::vector<Row> Build(const std::vector<Triplet>& tr, const Eigen::Matrix3d& R_WE, bool frame) {
  std::vector<Row> rows(tr.size());
  for (std::size_t j = 0; j < tr.size(); ++j) {
    Row& r = rows[j];
    const Eigen::Vector3d u_W = R_WE * tr[j].u_E;
    r.A.resize(3, frame ? 10 : 7);
    r.A.leftCols<4>() = R_WE * tr[j].B_E;
    r.A.middleCols<3>(4) = -Eigen::Matrix3d::Identity();
    if (frame) r.A.rightCols<3>() = -geometry::Skew(u_W);
    r.y = tr[j].y_W - u_W;
  }
  return rows;
}

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

// The weighted normal equations of rows [first, last); w per triplet.
struct Normal {
  Mat N;
  Vec b;
};
Normal Accumulate(const std::vector<Row>& rows, const std::vector<double>& w, std::size_t first,
                  std::size_t last) {
  const Eigen::Index k = rows.empty() ? 7 : rows.front().A.cols();
  Normal n{Mat::Zero(k, k), Vec::Zero(k)};
  for (std::size_t j = first; j < last; ++j) {
    n.N.noalias() += w[j] * rows[j].A.transpose() * rows[j].A;
    n.b.noalias() += w[j] * rows[j].A.transpose() * rows[j].y;
  }
  return n;
}

Result<Vec> Solve(const Normal& n) {
  // The lag is read from the jerk column, the lever arm from the rotation, the frame from the
  // acceleration's directions: without them the system is singular.
  const Eigen::LDLT<Mat> ldlt(n.N);
  const double scale = n.N.diagonal().maxCoeff();
  if (ldlt.info() != Eigen::Success || !(scale > 0.0) ||
      !(ldlt.vectorD().cwiseAbs().minCoeff() > 1e-12 * scale))
    return Result<Vec>::Error(
        "accel_lag: the recording does not determine the lag (no motion, or no rotation for "
        "the lever arm)");
  return Vec(ldlt.solve(n.b));
}

// Huber-reweighted least squares (a few passes), one weight per triplet: the smallest over its
// axes, since a tap turned into W reaches every axis, and its ȧ makes the triplet a leverage
// point that a per-axis weight still lets pull (the taps of AccelLag.TapsDoNotPullTheLag: 2.69
// ms per axis, 2.97 ms per triplet, true 3; Tukey's biweight, 5.4 ms, is worse still).
Result<Vec> RobustFit(const std::vector<Row>& rows, std::vector<double>& w) {
  w.assign(rows.size(), 1.0);
  auto theta = Solve(Accumulate(rows, w, 0, rows.size()));
  if (!theta) return theta;
  std::vector<Eigen::Vector3d> res(rows.size());  // |y − A θ| per triplet and axis
  std::vector<double> r(rows.size());
  for (int pass = 0; pass < 6; ++pass) {
    for (std::size_t j = 0; j < rows.size(); ++j)
      res[j] = (rows[j].y - rows[j].A * *theta).cwiseAbs();
    Eigen::Vector3d sigma;
    for (int i = 0; i < 3; ++i) {
      for (std::size_t j = 0; j < rows.size(); ++j) r[j] = res[j](i);
      sigma(i) = std::max(1.4826 * numeric::UpperMedian(r), 1e-12);
    }
    for (std::size_t j = 0; j < rows.size(); ++j) {
      const double u = res[j].cwiseQuotient(sigma).maxCoeff();
      w[j] = u <= kAccelLagHuber ? 1.0 : kAccelLagHuber / u;
    }
    theta = Solve(Accumulate(rows, w, 0, rows.size()));
    if (!theta) return theta;
  }
  return theta;
}

// The frame W ← E that best turns the triplets' accelerations onto the position sensor's, both
// centred (a constant bias drops out): Kabsch, R = V diag(1, 1, det(V Uᵀ)) Uᵀ from the SVD
// U S Vᵀ of Σ (u − ū)(y − ȳ)ᵀ. Refused when the acceleration spans less than a plane.
Result<Eigen::Matrix3d> AlignFrames(const std::vector<Triplet>& tr) {
  Eigen::Vector3d u_mean = Eigen::Vector3d::Zero(), y_mean = Eigen::Vector3d::Zero();
  for (const Triplet& t : tr) {
    u_mean += t.u_E / static_cast<double>(tr.size());
    y_mean += t.y_W / static_cast<double>(tr.size());
  }
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (const Triplet& t : tr) H += (t.u_E - u_mean) * (t.y_W - y_mean).transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d sv = svd.singularValues();
  if (!(sv(1) > 1e-6 * sv(0)))
    return Result<Eigen::Matrix3d>::Error(
        "accel_lag: the motion does not determine the position sensor's frame (its acceleration "
        "spans less than a plane)");
  const Eigen::Matrix3d& U = svd.matrixU();
  const Eigen::Matrix3d& V = svd.matrixV();
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (V * U.transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  return Eigen::Matrix3d(V * D * U.transpose());
}

}  // namespace

Result<AccelLagEstimate> EstimateAccelLag(const AccelLagData& d, const AccelLagSettings& s) {
  using R = Result<AccelLagEstimate>;
  const std::size_t n = d.t_imu.size(), m = d.t_position.size();
  if (d.f_B.size() != n || d.R_EB.size() != n || d.omega_B.size() != n)
    return R::Error("accel_lag: f_B, R_EB and omega_B must have one entry per t_imu");
  if (d.p_WM_W.size() != m) return R::Error("accel_lag: p_WM_W must have one entry per t_position");
  if (!(s.blocks >= 2) || !(s.min_triplets_per_block >= 1) || !(s.max_step_ratio >= 1.0) ||
      !(s.max_imu_step > 0.0) || !std::isfinite(s.gravity) || !s.R_WE.allFinite() ||
      !(s.min_position_step >= 0.0 && std::isfinite(s.min_position_step)))
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

  // Per IMU sample in E: a = R_EB f − g·up, R_EB ([α]× + [ω]×²), and R_EB ḟ_B (δ's column), α
  // by central differences. The position sensor's frame is applied to the triplets (Build).
  const Eigen::Vector3d g_up = s.gravity * UpVector(s.earth);
  std::vector<Eigen::Vector3d> a(n), f_dot_E(n);
  std::vector<Eigen::Matrix3d> L(n);
  for (std::size_t k = 0; k < n; ++k) a[k] = d.R_EB[k] * d.f_B[k] - g_up;
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t lo = k == 0 ? 0 : k - 1, hi = k + 1 == n ? k : k + 1;
    const double span = d.t_imu[hi] - d.t_imu[lo];
    f_dot_E[k] = d.R_EB[k] * (d.f_B[hi] - d.f_B[lo]) / span;
    const Eigen::Vector3d alpha_B = (d.omega_B[hi] - d.omega_B[lo]) / span;
    const Eigen::Matrix3d W = geometry::Skew(d.omega_B[k]);
    L[k] = d.R_EB[k] * (geometry::Skew(alpha_B) + W * W);
  }

  // The triplets (header comment): y = 2 p[t₀, t₁, t₂] against ∫ (·) M by the trapezoid. With
  // min_position_step, each triplet's outer samples are the first at least that far from its
  // middle one (a fast tracker's neighbours are mostly noise in a second difference).
  std::vector<Triplet> tr;
  std::size_t lo_j = 0;
  for (std::size_t j = 1; j + 1 < m; ++j) {
    std::size_t j0 = j - 1, j2 = j + 1;
    if (s.min_position_step > 0.0) {
      // A step of exactly min_position_step (a 20 Hz tracker's stamps) is far enough.
      const double step = s.min_position_step * (1.0 - 1e-9);
      while (lo_j + 1 < j && d.t_position[j] - d.t_position[lo_j + 1] >= step) ++lo_j;
      j0 = lo_j;
      while (j2 + 1 < m && d.t_position[j2] - d.t_position[j] < step) ++j2;
      if (d.t_position[j] - d.t_position[j0] < step || d.t_position[j2] - d.t_position[j] < step)
        continue;  // the recording's ends
    }
    const double t0 = d.t_position[j0], t1 = d.t_position[j], t2 = d.t_position[j2];
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
    t.B_E.setZero();
    t.u_E.setZero();
    double sum_w = 0.0;
    for (std::size_t k = k0 + 1; k < k1; ++k) {
      const double tk = d.t_imu[k];
      const double hat = tk <= t1 ? (tk - t0) / h1 : (t2 - tk) / h2;  // M ∝ hat on [t₀, t₂]
      const double w = hat * 0.5 * (std::min(d.t_imu[k + 1], t2) - std::max(d.t_imu[k - 1], t0));
      if (!(w > 0.0)) continue;
      sum_w += w;
      t.u_E += w * a[k];
      t.B_E.col(0) += w * f_dot_E[k];
      t.B_E.rightCols<3>() += w * L[k];
    }
    if (!(sum_w > 0.0)) continue;
    t.u_E /= sum_w;
    t.B_E /= sum_w;
    t.y_W =
        2.0 * ((d.p_WM_W[j2] - d.p_WM_W[j]) / h2 - (d.p_WM_W[j] - d.p_WM_W[j0]) / h1) / (t2 - t0);
    tr.push_back(t);
  }
  const std::size_t per_block = tr.size() / static_cast<std::size_t>(s.blocks);
  if (per_block < static_cast<std::size_t>(s.min_triplets_per_block)) {
    std::ostringstream o;
    o << "accel_lag: " << tr.size() << " usable position triplets, fewer than " << s.blocks
      << " blocks of " << s.min_triplets_per_block;
    return R::Error(o.str());
  }

  // The position sensor's frame: as given, or (estimate_R_WE) aligned in closed form and refined
  // with δ, r_B and b_W by Gauss–Newton on a small rotation φ of W (three more columns).
  Eigen::Matrix3d R_WE = s.R_WE;
  std::vector<double> w;
  if (s.estimate_R_WE) {
    const auto aligned = AlignFrames(tr);
    if (!aligned) return R::Error(aligned.error());
    R_WE = *aligned;
    for (int iter = 0; iter < 20; ++iter) {
      const auto step = RobustFit(Build(tr, R_WE, true), w);
      if (!step) return R::Error(step.error());
      const Eigen::Vector3d phi = step->tail<3>();
      R_WE = geometry::Exp(phi) * R_WE;
      if (phi.norm() < 1e-10) break;
    }
  }
  const std::vector<Row> rows = Build(tr, R_WE, s.estimate_R_WE);
  const auto theta = RobustFit(rows, w);
  if (!theta) return R::Error(theta.error());

  AccelLagEstimate e;
  e.delay = (*theta)(0);
  e.lever_arm_B = theta->segment<3>(1);
  e.bias_W = theta->segment<3>(4);
  e.R_WE = R_WE;
  e.R_WE_estimated = s.estimate_R_WE;
  e.triplets = static_cast<int>(tr.size());
  double r2 = 0.0, j2 = 0.0;
  for (const Row& r : rows) {
    r2 += (r.y - r.A * *theta).squaredNorm();
    j2 += r.A.col(0).squaredNorm();
  }
  e.residual_rms = std::sqrt(r2 / (3.0 * static_cast<double>(tr.size())));
  e.jerk_rms = std::sqrt(j2 / (3.0 * static_cast<double>(tr.size())));
  // σ_δ: the delete-one-block jackknife over contiguous blocks (header comment), weights fixed.
  std::vector<Normal> block;
  for (int b = 0; b < s.blocks; ++b) {
    const std::size_t first = static_cast<std::size_t>(b) * per_block;
    const std::size_t last = b + 1 == s.blocks ? tr.size() : first + per_block;
    block.push_back(Accumulate(rows, w, first, last));
  }
  Normal all = block.front();
  for (std::size_t b = 1; b < block.size(); ++b) {
    all.N += block[b].N;
    all.b += block[b].b;
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
