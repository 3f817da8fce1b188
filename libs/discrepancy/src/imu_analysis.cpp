#include "rcal/discrepancy/imu_analysis.hpp"

#include <spdlog/spdlog.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <numbers>
#include <stdexcept>
#include <string>

#include "rcal/discrepancy/significance.hpp"
#include "rcal/estimation/accel_lag.hpp"
#include "rcal/estimation/position_kf.hpp"
#include "rcal/estimation/position_kf_bank.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/numeric/median.hpp"

namespace rcal::discrepancy {
namespace {

namespace est = rcal::estimation;
using numeric::UpperMedian;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr const char* kAxis[3] = {"x", "y", "z"};

// Upper-tail probability of the standard normal, P(Z > z).
double NormalUpper(double z) {
  return 0.5 * std::erfc(z / std::numbers::sqrt2);
}
// z with P(Z > z) = p (bisection on erfc; p in (0, 1)).
double NormalQuantileUpper(double p) {
  p = std::clamp(p, 1e-300, 1.0 - 1e-16);
  double lo = -40.0, hi = 40.0;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (NormalUpper(mid) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}
// ln P(X ≥ k), X ~ Binomial(n, p), summed in log space: ln p stays finite where p itself
// underflows (thousands of samples outside a 1e-3 band), so the z derived from it is exact.
double LogBinomialUpper(long k, long n, double p) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  if (k <= 0) return 0.0;
  if (k > n) return -kInf;
  if (p <= 0.0) return -kInf;
  if (p >= 1.0) return 0.0;
  const double lp = std::log(p), lq = std::log1p(-p);
  auto log_pmf = [&](long i) {
    return std::lgamma(n + 1.0) - std::lgamma(i + 1.0) - std::lgamma(n - i + 1.0) + i * lp +
           (n - i) * lq;
  };
  const double mode = std::max(static_cast<double>(k), std::floor((n + 1) * p));
  double lmax = log_pmf(static_cast<long>(std::min<double>(mode, n)));
  double sum = 0.0;
  for (long i = k; i <= n; ++i) {
    const double l = log_pmf(i);
    sum += std::exp(l - lmax);
    if (i > mode && l - lmax < -40.0) break;
  }
  return std::min(0.0, lmax + std::log(sum));
}

double Mean(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v) s += x;
  return v.empty() ? kNaN : s / static_cast<double>(v.size());
}
double Sd(const std::vector<double>& v) {
  if (v.size() < 2) return kNaN;
  const double m = Mean(v);
  double s = 0.0;
  for (double x : v) s += (x - m) * (x - m);
  return std::sqrt(s / static_cast<double>(v.size() - 1));
}

Eigen::Vector4d QuatNlerp(const Eigen::Vector4d& a, Eigen::Vector4d b, double u) {
  if (a.dot(b) < 0.0) b = -b;
  return ((1.0 - u) * a + u * b).normalized();
}

bool Moving(const ImuStreamData& d, const std::vector<char>& rest_mask, int k) {
  return d.movement.empty() ? !rest_mask[k] : d.movement[k] == 1;
}

// Overlapping Allan variance terms of one segment for cluster size m: (Σ (θ-diff)², count).
std::pair<double, long> AllanTerms(const std::vector<double>& cum, int b, int e, int m,
                                   double tau0) {
  const long n = e - b;
  const long count = n - 2L * m + 1;
  if (count <= 0) return {0.0, 0};
  double s = 0.0;
  for (long k = 0; k < count; ++k) {
    // mean over [k, k+m) and [k+m, k+2m) of the rate
    const double a1 = (cum[b + k + m] - cum[b + k]) / m;
    const double a2 = (cum[b + k + 2 * m] - cum[b + k + m]) / m;
    s += (a2 - a1) * (a2 - a1);
  }
  (void)tau0;
  return {s, count};
}

}  // namespace

std::vector<const ImuCandidate*> ImuAnalysis::effects() const {
  std::vector<const ImuCandidate*> out;
  for (const auto& c : candidates)
    if (c.named()) out.push_back(&c);
  return out;
}

std::string ImuCandidate::gain_metric() const {
  if (cause == "magnetic_disturbance") return "heading";
  return cause == "accel_lag" ? "position" : "total";
}

void MarkLosingExtensions(std::vector<ImuCandidate>& candidates) {
  for (auto& c : candidates) {
    if (!c.tested) continue;
    const std::string metric = c.gain_metric();
    const bool heading = metric == "heading", position = metric == "position";
    const double b =
        position ? c.position_before_m : (heading ? c.before.heading : c.before.total).value();
    const double e =
        position ? c.position_after_m : (heading ? c.after.heading : c.after.total).value();
    // A loss within kLoseTolerance is "gains nothing" (two filters on the same samples differ
    // by that much from noise alone: a 10 ms time offset, re-timed, scores 0.99-1.05x), not a
    // loss; trial 35's magnet gate doubled the heading error.
    constexpr double kLoseTolerance = 0.1;
    c.loses_to_truth = std::isfinite(b) && std::isfinite(e) && e > (1.0 + kLoseTolerance) * b;
    if (c.loses_to_truth && c.significant) {
      char buf[160];
      const double scale = position ? 1e3 : 180.0 / std::numbers::pi;
      std::snprintf(buf, sizeof buf,
                    "significant, but its extension raises the %s RMSE against the truth from "
                    "%.2f to %.2f %s: not named",
                    metric.c_str(), b * scale, e * scale, position ? "mm" : "deg");
      c.note += (c.note.empty() ? "" : "; ") + std::string(buf);
    }
  }
}

ImuStreamData FromSimulatedStream(const std::vector<sim::ImuStreamSample>& stream) {
  ImuStreamData d;
  for (const auto& r : stream) {
    d.t.push_back(r.t);
    d.gyro.push_back(r.gyro);
    d.accel.push_back(r.accel);
    d.mag_uT.push_back(r.mag_uT);
    d.q_truth.push_back(r.q_WI);
    d.movement.push_back(r.movement);
    d.p_W.push_back(r.p_W);
  }
  return d;
}

void ValidateImuStream(const ImuStreamData& d) {
  const size_t n = d.t.size();
  if (n < 10) throw std::invalid_argument("IMU stream: fewer than 10 samples");
  if (d.gyro.size() != n || d.accel.size() != n || d.mag_uT.size() != n)
    throw std::invalid_argument("IMU stream: gyro, accel and mag must have one row per t_s");
  if (!d.q_truth.empty() && d.q_truth.size() != n)
    throw std::invalid_argument("IMU stream: q_truth must be empty or one row per t_s");
  if (!d.movement.empty() && d.movement.size() != n)
    throw std::invalid_argument("IMU stream: movement must be empty or one row per t_s");
  if (!d.p_W.empty() && d.p_W.size() != n)
    throw std::invalid_argument("IMU stream: pos_x..pos_z must be empty or one row per t_s");
  auto row = [](size_t k) { return " at row " + std::to_string(k + 1); };
  for (size_t k = 0; k < n; ++k) {
    if (!std::isfinite(d.t[k]))
      throw std::invalid_argument("IMU stream: t_s is not finite" + row(k));
    if (k > 0 && !(d.t[k] > d.t[k - 1]))
      throw std::invalid_argument("IMU stream: t_s does not increase" + row(k));
    if (!d.gyro[k].allFinite())
      throw std::invalid_argument("IMU stream: gyr_x..gyr_z not finite" + row(k));
    if (!d.accel[k].allFinite())
      throw std::invalid_argument("IMU stream: acc_x..acc_z not finite" + row(k));
    if (!d.mag_uT[k].allFinite())
      throw std::invalid_argument("IMU stream: mag_x..mag_z not finite" + row(k));
    // NaN is an occluded position; an infinity is no measurement of anything.
    if (!d.p_W.empty() && !d.p_W[k].allFinite() && !d.p_W[k].array().isNaN().all())
      throw std::invalid_argument("IMU stream: pos_x..pos_z neither finite nor all NaN" + row(k));
  }
}

std::vector<Eigen::Vector4d> RunOrientationFilter(const ImuStreamData& d,
                                                  const est::OrientationKfSettings& s) {
  est::OrientationKf kf(s);
  std::vector<Eigen::Vector4d> q(d.t.size(), Eigen::Vector4d::Constant(kNaN));
  for (size_t k = 0; k < d.t.size(); ++k)
    if (kf.Update(d.t[k], d.gyro[k], d.accel[k], d.mag_uT[k]).ok()) q[k] = kf.q_EB();
  return q;
}

OrientationScore ScoreAgainstTruth(const ImuStreamData& d, const std::vector<Eigen::Vector4d>& q,
                                   double offset_s, int begin, int end) {
  OrientationScore s;
  if (d.q_truth.empty()) return s;
  const int n = static_cast<int>(d.t.size());
  if (end < 0 || end > n) end = n;
  const double dt = (d.t.back() - d.t.front()) / (n - 1);
  for (int k = std::max(begin, 0); k < end; ++k) {
    if (!d.movement.empty() && d.movement[k] != 1) continue;
    if (!q[k].allFinite()) continue;
    Eigen::Vector4d qt = d.q_truth[k];
    if (offset_s != 0.0) {
      const double x = k - offset_s / dt;
      const int i = static_cast<int>(std::floor(x));
      if (i < 0 || i + 1 >= n) continue;
      if (!d.q_truth[i].allFinite() || !d.q_truth[i + 1].allFinite()) continue;
      qt = QuatNlerp(d.q_truth[i], d.q_truth[i + 1], x - i);
    }
    if (!qt.allFinite()) continue;
    s.Add(BroadErrors(q[k], qt));
  }
  return s;
}

namespace {

struct Context {
  const ImuStreamData& d;
  const ImuAnalysisSettings& s;
  int n = 0;
  double dt = 0.0, rate = 0.0;
  std::vector<char> rest_mask;  // sample in a used rest segment
  std::vector<char> ref_mask;   // sample in the reference (excluded from the field's test)
  int longest_still = 0;        // the longest still run before trimming [samples]
};

// `v` with `digits` decimals.
std::string Fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

std::vector<std::pair<int, int>> FindRests(Context& c, bool* short_rests) {
  const auto& d = c.d;
  std::vector<char> still(c.n, 0);
  if (!d.movement.empty()) {
    for (int k = 0; k < c.n; ++k) still[k] = d.movement[k] == 0;
  } else {
    std::array<std::vector<double>, 3> g;
    for (int k = 0; k < c.n; ++k)
      for (int i = 0; i < 3; ++i) g[i].push_back(d.gyro[k](i));
    Eigen::Vector3d med(UpperMedian(g[0]), UpperMedian(g[1]), UpperMedian(g[2]));
    for (int k = 0; k < c.n; ++k)
      still[k] = (d.gyro[k] - med).norm() < c.s.still_gyro &&
                 std::abs(d.accel[k].norm() - c.s.gravity) < c.s.still_accel;
  }
  // Runs of still samples, trimmed by rest_trim_s at both ends (transitions).
  const int trim = static_cast<int>(std::round(c.s.rest_trim_s * c.rate));
  std::vector<std::pair<int, int>> runs;
  int k = 0;
  while (k < c.n) {
    if (!still[k]) {
      ++k;
      continue;
    }
    int e = k;
    while (e < c.n && still[e]) ++e;
    c.longest_still = std::max(c.longest_still, e - k);
    const int b2 = k == 0 ? 0 : k + trim;
    const int e2 = e == c.n ? e : e - trim;
    if (e2 > b2) runs.emplace_back(b2, e2);
    k = e;
  }
  // The rests of min_rest_s; without any, those of min_short_rest_s (short_rests).
  const auto longer = [&](double s) {
    const int min_len = static_cast<int>(std::round(s * c.rate));
    std::vector<std::pair<int, int>> out;
    for (auto [b, e] : runs)
      if (e - b >= min_len) out.emplace_back(b, e);
    return out;
  };
  std::vector<std::pair<int, int>> rests = longer(c.s.min_rest_s);
  *short_rests = rests.empty();
  if (rests.empty()) rests = longer(std::min(c.s.min_short_rest_s, c.s.min_rest_s));
  c.rest_mask.assign(c.n, 0);
  for (auto [b, e] : rests)
    for (int i = b; i < e; ++i) c.rest_mask[i] = 1;
  return rests;
}

// Truth body rate over each sample interval, NaN where undefined.
std::vector<Eigen::Vector3d> TruthRates(const Context& c) {
  std::vector<Eigen::Vector3d> w(c.n, Eigen::Vector3d::Constant(kNaN));
  // The rate over the interval that ends at sample k, the convention of the gyro the filters
  // integrate (q_k = q_{k−1} Exp(ω_k Δt)) and of a rate-integrating gyro: a gyro that keeps it
  // reads no offset (against the rate at the instant, a central difference, it would read Δt/2).
  for (int k = 1; k < c.n; ++k) {
    const auto& a = c.d.q_truth[k - 1];
    const auto& b = c.d.q_truth[k];
    if (!a.allFinite() || !b.allFinite()) continue;
    const Eigen::Matrix3d R = geometry::QuatToMatrix(a).transpose() * geometry::QuatToMatrix(b);
    w[k] = geometry::Log(R) / c.dt;
  }
  return w;
}

// Lag τ [s] with ω_m(t) ≈ ω_truth(t − τ) over the samples idx; NaN when undefined.
double EstimateLag(const Context& c, const std::vector<Eigen::Vector3d>& w_truth,
                   const std::vector<int>& idx) {
  const int L = std::max(1, static_cast<int>(std::round(c.s.max_lag_s * c.rate)));
  std::vector<double> J(2 * L + 1, kNaN);
  for (int l = -L; l <= L; ++l) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double sq = 0.0;
    long cnt = 0;
    for (int k : idx) {
      const int j = k - l;
      if (j < 0 || j >= c.n || !w_truth[j].allFinite()) continue;
      const Eigen::Vector3d r = c.d.gyro[k] - w_truth[j];
      sum += r;
      sq += r.squaredNorm();
      ++cnt;
    }
    if (cnt > 10) J[l + L] = (sq - sum.squaredNorm() / cnt) / cnt;
  }
  int best = -1;
  for (int i = 0; i < 2 * L + 1; ++i)
    if (std::isfinite(J[i]) && (best < 0 || J[i] < J[best])) best = i;
  if (best < 0) return kNaN;
  double delta = 0.0;
  if (best > 0 && best < 2 * L && std::isfinite(J[best - 1]) && std::isfinite(J[best + 1])) {
    const double den = J[best - 1] - 2.0 * J[best] + J[best + 1];
    if (den > 0.0) delta = std::clamp(0.5 * (J[best - 1] - J[best + 1]) / den, -0.5, 0.5);
  }
  return (best - L + delta) * c.dt;
}

est::OrientationKfSettings BaseFilter(const ImuAnalysisSettings& s) {
  est::OrientationKfSettings f = s.filter;
  f.reject_mag = false;
  f.reject_accel = false;
  f.estimate_gyro_bias = true;
  f.gyro_bias_random_walk = s.base_bias_random_walk;
  return f;
}

Context MakeContext(const ImuStreamData& data, const ImuAnalysisSettings& settings) {
  const int n = static_cast<int>(data.t.size());
  const double dt = (data.t.back() - data.t.front()) / (n - 1);
  return Context{data, settings, n, dt, 1.0 / dt, {}, {}, 0};
}

// The reference field (norm, dip), gravity and their noise levels on the samples of c.ref_mask
// (the first rest, or the first rests pooled).
void FitReference(const Context& c, ImuAnalysis& a) {
  const auto& data = c.d;
  const auto& s = c.s;
  std::vector<double> nm, dip, fn;
  for (int k = 0; k < c.n; ++k) {
    if (!c.ref_mask[k]) continue;
    const double m = data.mag_uT[k].norm(), f = data.accel[k].norm();
    nm.push_back(m);
    fn.push_back(f);
    dip.push_back(std::asin(std::clamp(-data.mag_uT[k].dot(data.accel[k]) / (m * f), -1.0, 1.0)));
  }
  a.mag_ref_norm_uT = Mean(nm);
  a.mag_ref_dip_rad = Mean(dip);
  a.gravity_ref = Mean(fn);
  const double sm = s.mag_noise_density_uT * std::sqrt(c.rate);
  const double sa = s.accel_noise_density * std::sqrt(c.rate);
  a.sigma_mag_norm_uT = std::max(Sd(nm), sm);
  a.sigma_accel_norm = std::max(Sd(fn), sa);
  a.sigma_dip_rad = std::max(Sd(dip), std::hypot(sm / a.mag_ref_norm_uT, sa / a.gravity_ref));
}

// ----- gyro_bias -----

// Overlapping Allan deviation per axis, pooled over the rests, at cluster sizes spaced by 0.1
// decade up to half the longest rest, where the relative confidence is allan_max_rel_sigma or
// better.
void ComputeAllanCurve(const Context& c, const std::vector<std::pair<int, int>>& rests,
                       AllanCurve& A) {
  std::array<std::vector<double>, 3> cum;
  for (int i = 0; i < 3; ++i) {
    cum[i].assign(c.n + 1, 0.0);
    for (int k = 0; k < c.n; ++k) cum[i][k + 1] = cum[i][k] + c.d.gyro[k](i);
  }
  int longest = 0;
  for (auto [b, e] : rests) longest = std::max(longest, e - b);
  std::vector<int> ms;
  for (double lm = 0.0; std::pow(10.0, lm) <= longest / 2.0; lm += 0.1) {
    const int m = static_cast<int>(std::round(std::pow(10.0, lm)));
    if (ms.empty() || m != ms.back()) ms.push_back(m);
  }
  for (int m : ms) {
    double clusters = 0.0;
    for (auto [b, e] : rests) clusters += std::max(0.0, (e - b) / static_cast<double>(m) - 1.0);
    const double rel = clusters > 0 ? 1.0 / std::sqrt(2.0 * clusters) : kNaN;
    if (!(rel <= c.s.allan_max_rel_sigma)) continue;
    std::array<double, 3> av{};
    for (int i = 0; i < 3; ++i) {
      double sum = 0.0;
      long cnt = 0;
      for (auto [b, e] : rests) {
        const auto [ss, cc] = AllanTerms(cum[i], b, e, m, c.dt);
        sum += ss;
        cnt += cc;
      }
      av[i] = cnt > 0 ? std::sqrt(0.5 * sum / cnt) : kNaN;
    }
    A.tau_s.push_back(m * c.dt);
    A.rel_sigma.push_back(rel);
    for (int i = 0; i < 3; ++i) A.adev_rad_s[i].push_back(av[i]);
  }
}

// White level N_w per axis into A.white_level: median of σ_A √τ over the short-τ range (never
// below the stated density). Returns the relative σ of each.
std::array<double, 3> FitWhiteLevels(const ImuAnalysisSettings& s, AllanCurve& A) {
  std::array<double, 3> white_rel{};
  for (int i = 0; i < 3; ++i) {
    std::vector<double> v;
    double rel = kNaN;
    for (size_t j = 0; j < A.tau_s.size(); ++j)
      if (A.tau_s[j] >= s.allan_white_tau_min_s - 1e-12 &&
          A.tau_s[j] <= s.allan_white_tau_max_s + 1e-12) {
        v.push_back(A.adev_rad_s[i][j] * std::sqrt(A.tau_s[j]));
        rel = A.rel_sigma[j];
      }
    if (v.empty() && !A.tau_s.empty()) {
      v.push_back(A.adev_rad_s[i][0] * std::sqrt(A.tau_s[0]));
      rel = A.rel_sigma[0];
    }
    const double w = v.empty() ? s.gyro_noise_density : UpperMedian(v);
    A.white_level[i] = std::max(w, s.gyro_noise_density);
    white_rel[i] = std::isfinite(rel) ? rel / std::sqrt(std::max<size_t>(1, v.size())) : 0.0;
  }
  return white_rel;
}

// White density N, bias instability B and rate random walk K per axis, with their σ.
struct AllanNoiseTerms {
  std::array<double, 3> N{}, Ns{}, B{}, Bs{}, K{}, Ks{};
};

// Fit AVAR = c0/τ + c1 + c2 τ (weighted LS) per axis: N = √c0, B = √(c1 π / 2ln2), K = √(3c2).
// Zero on an axis with fewer than 3 points.
AllanNoiseTerms FitAllanNoiseTerms(const AllanCurve& A) {
  AllanNoiseTerms t;
  const int m = static_cast<int>(A.tau_s.size());
  if (m < 3) return t;
  for (int i = 0; i < 3; ++i) {
    Eigen::MatrixXd H(m, 3);
    Eigen::VectorXd y(m);
    for (int j = 0; j < m; ++j) {
      const double av = A.adev_rad_s[i][j] * A.adev_rad_s[i][j];
      const double sd = 2.0 * A.rel_sigma[j] * av;  // σ of AVAR
      H(j, 0) = 1.0 / A.tau_s[j] / sd;
      H(j, 1) = 1.0 / sd;
      H(j, 2) = A.tau_s[j] / sd;
      y(j) = av / sd;
    }
    const Eigen::Matrix3d HtH = H.transpose() * H;
    const Eigen::Vector3d coef = HtH.ldlt().solve(H.transpose() * y);
    const Eigen::Matrix3d cov = HtH.inverse();
    auto root = [](double v, double var, double scale, double* sig) {
      const double x = std::sqrt(std::max(v, 0.0) * scale);
      // σ of √(v·scale) by the delta method; at v ≤ 0 the one-σ upper value.
      *sig = v > 0 ? 0.5 * scale * std::sqrt(var) / x
                   : std::sqrt(std::max(0.0, (v + std::sqrt(var)) * scale));
      return x;
    };
    t.N[i] = root(coef(0), cov(0, 0), 1.0, &t.Ns[i]);
    t.B[i] = root(coef(1), cov(1, 1), std::numbers::pi / (2.0 * std::log(2.0)), &t.Bs[i]);
    t.K[i] = root(coef(2), cov(2, 2), 3.0, &t.Ks[i]);
  }
  return t;
}

// The z statistics of the gyro_bias tests: the largest, and the axes above the critical value.
struct AxisZTests {
  double critical = 0.0;
  double best_z = -1e300;
  std::array<bool, 3> axis_hit{};
  void Add(int axis, double z) {
    best_z = std::max(best_z, z);
    if (z > critical) axis_hit[axis] = true;
  }
};

// Long-τ test: z(τ) of the Allan deviation above the white line at the τ of test_idx.
void TestAllanAboveWhite(const AllanCurve& A, const std::array<double, 3>& white_rel,
                         const std::vector<int>& test_idx, AxisZTests& z) {
  for (int i = 0; i < 3; ++i)
    for (int j : test_idx) {
      const double line = A.white_level[i] / std::sqrt(A.tau_s[j]);
      z.Add(i, (A.adev_rad_s[i][j] / line - 1.0) / std::hypot(A.rel_sigma[j], white_rel[i]));
    }
}

struct BiasDrift {
  std::array<double, 3> value{}, sigma{};  // mean of the last rest − mean of the first [rad/s]
};

// Drift: mean of the first rest vs the last, against the white noise and the earth rate.
BiasDrift TestBiasDrift(const Context& c, const std::vector<std::pair<int, int>>& rests,
                        const AllanCurve& A, AxisZTests& z) {
  BiasDrift drift;
  const auto [b1, e1] = rests.front();
  const auto [b2, e2] = rests.back();
  for (int i = 0; i < 3; ++i) {
    double m1 = 0, m2 = 0;
    for (int k = b1; k < e1; ++k) m1 += c.d.gyro[k](i);
    for (int k = b2; k < e2; ++k) m2 += c.d.gyro[k](i);
    m1 /= (e1 - b1);
    m2 /= (e2 - b2);
    const double w = A.white_level[i];
    drift.value[i] = m2 - m1;
    drift.sigma[i] = std::sqrt(w * w / ((e1 - b1) * c.dt) + w * w / ((e2 - b2) * c.dt) +
                               c.s.earth_rate * c.s.earth_rate);
    z.Add(i, std::abs(drift.value[i]) / drift.sigma[i]);
  }
  return drift;
}

// gyro_bias: the Allan curve into a.allan, the long-τ and drift tests, the fitted noise terms and
// the extension's bias random walk (the last value).
ImuCandidate TestGyroBias(const Context& c, double alpha_c, ImuAnalysis& a) {
  const auto& s = c.s;
  ImuCandidate gb;
  gb.cause = "gyro_bias";
  gb.tested = true;
  spdlog::info("imu analysis: Allan deviation over {} rests", a.rests.size());
  auto& A = a.allan;
  ComputeAllanCurve(c, a.rests, A);
  const std::array<double, 3> white_rel = FitWhiteLevels(s, A);
  std::vector<int> test_idx;
  for (size_t j = 0; j < A.tau_s.size(); ++j)
    if (A.tau_s[j] >= s.allan_test_tau_min_s - 1e-12) test_idx.push_back(static_cast<int>(j));
  const int tests = 3 * (static_cast<int>(test_idx.size()) + 1);
  gb.critical = NormalQuantileUpper(alpha_c / std::max(1, tests));
  const AllanNoiseTerms t = FitAllanNoiseTerms(A);
  AxisZTests z{gb.critical};
  TestAllanAboveWhite(A, white_rel, test_idx, z);
  BiasDrift drift;
  if (a.rests.size() >= 2) drift = TestBiasDrift(c, a.rests, A, z);
  gb.statistic = z.best_z;
  for (int i = 0; i < 3; ++i) {
    if (z.axis_hit[i]) gb.axes.push_back(kAxis[i]);
    const std::string ax = std::string("_") + kAxis[i];
    gb.values.push_back({"white_noise_density" + ax + "_rad_s_sqrt_hz", t.N[i], t.Ns[i]});
    gb.values.push_back({"bias_instability" + ax + "_rad_s", t.B[i], t.Bs[i]});
    gb.values.push_back({"rate_random_walk" + ax + "_rad_s_sqrt_s", t.K[i], t.Ks[i]});
    if (a.rests.size() >= 2)
      gb.values.push_back({"bias_drift" + ax + "_rad_s", drift.value[i], drift.sigma[i]});
  }
  gb.significant = !gb.axes.empty();
  gb.note = "white line from the data's short-τ level (stated " +
            std::to_string(s.gyro_noise_density) + " rad/s/√Hz)";
  if (A.tau_s.empty() || test_idx.empty()) {
    gb.note = "rests too short for the long-τ Allan test (τ ≥ " + Fixed(s.allan_test_tau_min_s, 1) +
              " s needs rests of " + Fixed(2 * s.allan_test_tau_min_s, 1) + " s)";
    if (a.rests.size() >= 2)
      gb.note += ": tested only by the drift between the first and the last rest";
    else
      gb.tested = false;
  }
  double k_ext = s.base_bias_random_walk;
  for (int i = 0; i < 3; ++i)
    k_ext = std::max({k_ext, t.K[i], t.B[i] / std::sqrt(s.bias_time_constant_s)});
  gb.values.push_back({"extension_bias_random_walk_rad_s_sqrt_s", k_ext, 0.0});
  return gb;
}

// ----- magnetic_disturbance -----

// Per-sample deviations of the field from the reference, outside the reference (c.ref_mask).
struct FieldDeviations {
  std::vector<double> dn;       // |m| − m₀ [µT]
  std::vector<double> dd;       // dip (base filter's attitude) − δ₀ [rad]
  std::vector<double> dd_test;  // the test's dip − δ₀: at rests from the accelerometer, else 0
  std::vector<int> dk;          // sample index of each deviation
};

// The deviations; a.mag_norm_uT and a.mag_dip_rad (dip from the base filter's attitude) on every
// sample.
FieldDeviations DeviationsFromReference(const Context& c,
                                        const std::vector<Eigen::Vector4d>& q_base,
                                        ImuAnalysis& a) {
  const auto& data = c.d;
  const Eigen::Vector3d up(0, 0, 1);
  FieldDeviations f;
  for (int k = 0; k < c.n; ++k) {
    const double m = data.mag_uT[k].norm();
    a.mag_norm_uT[k] = m;
    if (!q_base[k].allFinite()) continue;
    const Eigen::Vector3d down_B = -geometry::QuatToMatrix(q_base[k]).transpose() * up;
    a.mag_dip_rad[k] = std::asin(std::clamp(data.mag_uT[k].dot(down_B) / m, -1.0, 1.0));
    if (c.ref_mask[k]) continue;  // the reference itself
    f.dn.push_back(m - a.mag_ref_norm_uT);
    f.dk.push_back(k);
    f.dd.push_back(a.mag_dip_rad[k] - a.mag_ref_dip_rad);
    // The test's dip: at rests from the accelerometer (gravity alone there); in motion the
    // filter's tilt may carry the accelerometer's own error, so only the norm is tested.
    const double fn = data.accel[k].norm();
    f.dd_test.push_back(
        c.rest_mask[k]
            ? std::asin(std::clamp(-data.mag_uT[k].dot(data.accel[k]) / (m * fn), -1.0, 1.0)) -
                  a.mag_ref_dip_rad
            : 0.0);
  }
  return f;
}

// Robust spread about the reference (1.4826 MAD): the field the data shows most of the time,
// never below the noise of the reference rest. A disturbance is what falls outside it.
double RobustSpread(const std::vector<double>& v, double floor) {
  std::vector<double> abs_v;
  for (double x : v) abs_v.push_back(std::abs(x));
  return std::max(1.4826 * UpperMedian(abs_v), floor);
}

struct GateCounts {
  long out_noise = 0;  // outside the reference rest's noise band
  long out_gate = 0, out_gate_norm = 0, out_gate_dip = 0;
  double max_dn = 0.0, max_dd = 0.0;
};

// Counts the deviations outside the noise band and the gate; marks a.mag_disturbed within
// ±disturbed_window_s of every sample outside the gate.
GateCounts CountOutsideGate(const Context& c, const FieldDeviations& f, double gate_n,
                            double gate_d, ImuAnalysis& a) {
  const auto& s = c.s;
  GateCounts g;
  for (size_t i = 0; i < f.dn.size(); ++i) {
    g.max_dn = std::max(g.max_dn, std::abs(f.dn[i]));
    g.max_dd = std::max(g.max_dd, std::abs(f.dd_test[i]));
    if (std::abs(f.dn[i]) > s.band_z * a.sigma_mag_norm_uT ||
        std::abs(f.dd_test[i]) > s.band_z * a.sigma_dip_rad)
      ++g.out_noise;
    const bool gn = std::abs(f.dn[i]) > gate_n, gd = std::abs(f.dd_test[i]) > gate_d;
    g.out_gate += gn || gd;
    if (gn || gd) {
      // Disturbed window: ±disturbed_window_s around each sample outside the gate.
      const int w = static_cast<int>(std::round(s.disturbed_window_s * c.rate));
      for (int j = std::max(0, f.dk[i] - w); j < std::min(c.n, f.dk[i] + w + 1); ++j)
        a.mag_disturbed[j] = 1;
    }
    g.out_gate_norm += gn;
    g.out_gate_dip += gd;
  }
  return g;
}

// magnetic_disturbance: the binomial test of the samples outside the fitted gate; the gate into
// a.mag_gate_*; the per-sample field series into a.
ImuCandidate TestMagneticDisturbance(const Context& c, const std::vector<Eigen::Vector4d>& q_base,
                                     double alpha_c, ImuAnalysis& a) {
  const auto& s = c.s;
  ImuCandidate md;
  md.cause = "magnetic_disturbance";
  md.tested = true;
  md.axes = {"magnetometer"};
  a.mag_norm_uT.assign(c.n, kNaN);
  a.mag_dip_rad.assign(c.n, kNaN);
  a.mag_disturbed.assign(c.n, 0);
  const FieldDeviations f = DeviationsFromReference(c, q_base, a);
  const double sig_n = RobustSpread(f.dn, a.sigma_mag_norm_uT),
               sig_d = RobustSpread(f.dd, a.sigma_dip_rad);
  const double gate_n = s.band_z * sig_n, gate_d = s.band_z * sig_d;
  const long n_all = static_cast<long>(f.dn.size());
  const GateCounts g = CountOutsideGate(c, f, gate_n, gate_d, a);
  const double p_band = std::max(4.0 * NormalUpper(s.band_z), s.outlier_rate);
  const double p_noise = std::exp(LogBinomialUpper(g.out_noise, n_all, p_band));
  md.log_p = LogBinomialUpper(g.out_gate, n_all, p_band);
  const double p_gate = std::exp(md.log_p);
  md.statistic = NormalUpperQuantileLog(md.log_p);
  md.critical = NormalQuantileUpper(alpha_c);
  md.significant = n_all > 0 && p_gate < alpha_c;
  a.mag_gate_norm_uT = gate_n;
  a.mag_gate_dip_rad = gate_d;
  const double frac_noise = n_all ? static_cast<double>(g.out_noise) / n_all : 0.0;
  const double frac_gate = n_all ? static_cast<double>(g.out_gate) / n_all : 0.0;
  auto binom_sigma = [&](double fr) { return n_all ? std::sqrt(fr * (1 - fr) / n_all) : 0.0; };
  md.values = {{"reference_norm_uT", a.mag_ref_norm_uT, a.sigma_mag_norm_uT},
               {"reference_dip_rad", a.mag_ref_dip_rad, a.sigma_dip_rad},
               {"robust_sigma_norm_uT", sig_n, sig_n / std::sqrt(2.0 * std::max(1L, n_all))},
               {"robust_sigma_dip_rad", sig_d, sig_d / std::sqrt(2.0 * std::max(1L, n_all))},
               {"max_norm_deviation_uT", g.max_dn, sig_n},
               {"max_dip_deviation_at_rest_rad", g.max_dd, sig_d},
               {"fraction_outside_reference_noise_band", frac_noise, binom_sigma(frac_noise)},
               {"fraction_outside_gate", frac_gate, binom_sigma(frac_gate)},
               {"samples_outside_gate_norm", static_cast<double>(g.out_gate_norm), 0.0},
               {"samples_outside_gate_dip", static_cast<double>(g.out_gate_dip), 0.0},
               {"p_value_reference_noise_band", p_noise, 0.0},
               {"p_value_gate", p_gate, 0.0},
               {"extension_mag_norm_tolerance", gate_n / a.mag_ref_norm_uT, 0.0},
               {"extension_mag_dip_tolerance_rad", gate_d, 0.0}};
  return md;
}

// ----- accel_motion -----

// accel_motion: binomial test of |f| − g₀ in motion outside the noise band, and the RMS angle
// between f and the base filter's gravity direction.
ImuCandidate TestAccelMotion(const Context& c, const std::vector<Eigen::Vector4d>& q_base,
                             double alpha_c, const ImuAnalysis& a) {
  const auto& data = c.d;
  const auto& s = c.s;
  const Eigen::Vector3d up(0, 0, 1);
  ImuCandidate am;
  am.cause = "accel_motion";
  am.tested = true;
  am.axes = {"accelerometer"};
  long n_mov = 0, out = 0;
  Rms norm_err, angle;
  for (int k = 0; k < c.n; ++k) {
    if (!Moving(data, c.rest_mask, k)) continue;
    ++n_mov;
    const double f = data.accel[k].norm();
    const double dn = f - a.gravity_ref;
    norm_err.Add(dn);
    if (std::abs(dn) > s.band_z * a.sigma_accel_norm) ++out;
    if (q_base[k].allFinite() && f > 0) {
      const Eigen::Vector3d up_B = geometry::QuatToMatrix(q_base[k]).transpose() * up;
      angle.Add(std::acos(std::clamp(up_B.dot(data.accel[k]) / f, -1.0, 1.0)));
    }
  }
  const double p0 = std::max(2.0 * NormalUpper(s.band_z), s.outlier_rate);
  am.log_p = LogBinomialUpper(out, n_mov, p0);
  const double p = std::exp(am.log_p);
  am.statistic = NormalUpperQuantileLog(am.log_p);
  am.critical = NormalQuantileUpper(alpha_c);
  am.significant = n_mov > 0 && p < alpha_c;
  const double frac = n_mov ? static_cast<double>(out) / n_mov : 0.0;
  am.values = {
      {"gravity_reference_m_s2", a.gravity_ref, a.sigma_accel_norm},
      {"rms_norm_minus_g_in_motion_m_s2", norm_err.value(), a.sigma_accel_norm},
      {"rms_gravity_disagreement_rad", angle.value(), a.sigma_accel_norm / a.gravity_ref},
      {"fraction_outside_noise_band", frac, n_mov ? std::sqrt(frac * (1 - frac) / n_mov) : 0.0},
      {"p_value", p, 0.0}};
  if (n_mov == 0) {
    am.tested = false;
    am.note = "no motion samples";
  }
  return am;
}

// ----- time_offset -----

// A lag's test, its z already in `cand`: significant beyond the two-sided critical value at α_c
// and `large` (each test's own criterion of mattering); a measurable lag that is not large says
// why (`why_small`) in the candidate's note.
void JudgeLag(double alpha_c, bool large, const std::string& why_small, ImuCandidate& cand) {
  cand.critical = NormalQuantileUpper(alpha_c / 2.0);
  cand.significant = cand.statistic > cand.critical && large;
  if (cand.statistic > cand.critical && !large)
    cand.note = why_small + ": too small to matter, not significant as an effect";
}

struct TimeOffsetTest {
  ImuCandidate candidate;
  double tau_first = kNaN, tau_second = kNaN;  // lag fitted on each half of the motion samples
  int split = 0;                               // first sample of the second half
};

// σ of the lag over the motion samples: sd / √B of the lags of B contiguous blocks (NaN with
// fewer than two finite); `blocks` the number that gave a lag.
double LagSigma(const Context& c, const std::vector<Eigen::Vector3d>& w_truth,
                const std::vector<int>& motion_idx, int* blocks) {
  const int B = std::max(2, c.s.offset_blocks);
  std::vector<double> taus;
  for (int b = 0; b < B; ++b) {
    const size_t i0 = motion_idx.size() * b / B, i1 = motion_idx.size() * (b + 1) / B;
    const std::vector<int> blk(motion_idx.begin() + static_cast<long>(i0),
                               motion_idx.begin() + static_cast<long>(i1));
    const double t = EstimateLag(c, w_truth, blk);
    if (std::isfinite(t)) taus.push_back(t);
  }
  *blocks = static_cast<int>(taus.size());
  return taus.size() >= 2 ? Sd(taus) / std::sqrt(taus.size()) : kNaN;
}

// time_offset (truth present): the lag between gyro and truth rate over the motion samples, and
// on each half of them (for the cross-fitted gain).
TimeOffsetTest TestTimeOffset(const Context& c, const OrientationScore& base_score, double alpha_c,
                              bool has_truth) {
  TimeOffsetTest r;
  r.split = c.n;
  ImuCandidate& to = r.candidate;
  to.cause = "time_offset";
  to.axes = {"imu"};
  if (!has_truth) {
    to.note = "no truth orientation (q_w..q_z) in the stream: no second source to time";
    return r;
  }
  spdlog::info("imu analysis: time offset gyro vs truth rate");
  const std::vector<Eigen::Vector3d> w_truth = TruthRates(c);
  std::vector<int> motion_idx;
  for (int k = 0; k < c.n; ++k)
    if (Moving(c.d, c.rest_mask, k) && w_truth[k].allFinite()) motion_idx.push_back(k);
  if (motion_idx.size() <= 100) {
    to.note = "too few motion samples with truth";
    return r;
  }
  to.tested = true;
  const double tau = EstimateLag(c, w_truth, motion_idx);
  int blocks = 0;
  const double sigma = LagSigma(c, w_truth, motion_idx, &blocks);
  const size_t h = motion_idx.size() / 2;
  r.split = motion_idx[h];
  r.tau_first =
      EstimateLag(c, w_truth, {motion_idx.begin(), motion_idx.begin() + static_cast<long>(h)});
  r.tau_second =
      EstimateLag(c, w_truth, {motion_idx.begin() + static_cast<long>(h), motion_idx.end()});
  // τ/σ over the blocks is Student's t with B − 1 degrees of freedom, written as the z of the
  // same tail probability (as accel_lag's).
  to.statistic = std::isfinite(sigma) && sigma > 0
                     ? NormalUpperQuantileLog(LogStudentTUpper(std::abs(tau) / sigma, blocks - 1.0))
                     : 0.0;
  // Does it matter? The offset alone turns the attitude by |τ| |ω|: RMS over the motion samples
  // e_τ = |τ| ω_rms. Against the base filter's total RMSE e (movement samples), in quadrature
  // with the rest of its error, re-timing is expected to lower e by 1 − √(1 − (e_τ/e)²).
  Rms w_rms;
  for (int k : motion_idx) w_rms.Add(w_truth[k].norm());
  const double e_tau = std::abs(tau) * w_rms.value();
  const double e_base = base_score.total.value();
  const double share = e_tau / e_base;
  const double expected_gain =
      std::isfinite(share) ? (share >= 1.0 ? 1.0 : 1.0 - std::sqrt(1.0 - share * share)) : 0.0;
  JudgeLag(alpha_c, expected_gain >= c.s.min_offset_gain,
           "the offset is measurable (z beyond critical) but the attitude error it causes, |" +
               Fixed(tau * 1e3, 2) + " ms| x " + Fixed(w_rms.value(), 2) +
               " rad/s RMS = " + Fixed(e_tau * 180.0 / std::numbers::pi, 3) + " deg, is " +
               Fixed(100.0 * share, 1) + " % of the base filter's total RMSE (" +
               Fixed(e_base * 180.0 / std::numbers::pi, 2) +
               " deg): re-timing is expected to gain " + Fixed(100.0 * expected_gain, 1) +
               " %, below " + Fixed(100.0 * c.s.min_offset_gain, 0) + " %",
           to);
  to.values = {{"time_offset_s", tau, sigma},
               {"time_offset_first_half_s", r.tau_first, sigma * std::sqrt(2.0)},
               {"time_offset_second_half_s", r.tau_second, sigma * std::sqrt(2.0)},
               {"sample_period_s", c.dt, 0.0},
               {"motion_rate_rms_rad_s", w_rms.value(), 0.0},
               {"attitude_error_of_offset_rad", e_tau, 0.0},
               {"base_total_rmse_rad", e_base, 0.0},
               {"expected_retiming_gain", expected_gain, 0.0}};
  return r;
}

// ----- accel_lag -----

struct AccelLagTest {
  ImuCandidate candidate;
  double delay_first = kNaN, delay_second = kNaN;  // δ fitted on each half of the stream
  int split = 0;                                   // first sample of the second half
  std::vector<char> tracker;  // 1: a position the position KF fuses and the lag is read from
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();  // the reference rest's mean gyro [rad/s]
};

// One finite position per accel_lag_position_period_s, on the grid of the first (as a tracker
// at that rate on the stream's clock).
std::vector<char> TrackerSamples(const Context& c) {
  std::vector<char> tracker(c.n, 0);
  double next = -std::numeric_limits<double>::infinity();
  for (int k = 0; k < c.n; ++k) {
    if (!c.d.p_W[k].allFinite() || c.d.t[k] < next - 1e-9) continue;
    next = (std::isfinite(next) ? next : c.d.t[k]) + c.s.accel_lag_position_period_s;
    tracker[k] = 1;
  }
  return tracker;
}

// The lag estimator's input over the samples [begin, end): the accelerometer with the attitude
// q_WI (NaN: the sample is left out) and ω = gyro − the reference rest's mean, and the tracker's
// positions.
est::AccelLagData LagData(const Context& c, const std::vector<Eigen::Vector4d>& q_WI,
                          const AccelLagTest& r, int begin, int end) {
  est::AccelLagData d;
  for (int k = begin; k < end; ++k) {
    if (!q_WI[k].allFinite()) continue;
    d.t_imu.push_back(c.d.t[k]);
    d.f_B.push_back(c.d.accel[k]);
    d.R_EB.push_back(geometry::QuatToMatrix(q_WI[k]));
    d.omega_B.push_back(c.d.gyro[k] - r.gyro_bias);
    if (r.tracker[k]) {
      d.t_position.push_back(c.d.t[k]);
      d.p_WM_W.push_back(c.d.p_W[k]);
    }
  }
  return d;
}

// accel_lag (positions present): the lag of the accelerometer behind the positions, on the whole
// stream and on each half (for the cross-fitted gain).
AccelLagTest TestAccelLag(const Context& c, const std::vector<Eigen::Vector4d>& q_WI,
                          double alpha_c, const ImuAnalysis& a) {
  AccelLagTest r;
  r.split = c.n;
  ImuCandidate& al = r.candidate;
  al.cause = "accel_lag";
  al.axes = {"accelerometer"};
  if (!a.has_positions) {
    al.note =
        "no positions (pos_x..pos_z) in the stream: nothing to time the accelerometer against";
    return r;
  }
  spdlog::info("imu analysis: accelerometer lag against the positions");
  r.tracker = TrackerSamples(c);
  long n_ref = 0;
  for (int k = 0; k < c.n; ++k)
    if (c.ref_mask[k]) {
      r.gyro_bias += c.d.gyro[k];
      ++n_ref;
    }
  if (n_ref > 0) r.gyro_bias /= static_cast<double>(n_ref);
  est::AccelLagSettings ls;
  ls.earth = est::EarthFrame::kEnu;
  ls.gravity = a.gravity_ref;
  ls.blocks = c.s.accel_lag_blocks;
  const auto whole = est::EstimateAccelLag(LagData(c, q_WI, r, 0, c.n), ls);
  if (!whole) {
    al.note = "not measurable: " + whole.error();
    return r;
  }
  al.tested = true;
  std::vector<int> motion_idx;
  for (int k = 0; k < c.n; ++k)
    if (Moving(c.d, c.rest_mask, k)) motion_idx.push_back(k);
  r.split = motion_idx.empty() ? c.n / 2 : motion_idx[motion_idx.size() / 2];
  const auto first = est::EstimateAccelLag(LagData(c, q_WI, r, 0, r.split), ls);
  const auto second = est::EstimateAccelLag(LagData(c, q_WI, r, r.split, c.n), ls);
  r.delay_first = first ? first->delay : kNaN;
  r.delay_second = second ? second->delay : kNaN;
  const double delay = whole->delay, sigma = whole->delay_sigma;
  // δ/σ_δ over the jackknife's blocks is Student's t with B − 1 degrees of freedom: written as
  // the z of the same tail probability, so that one critical value serves every candidate.
  al.statistic =
      sigma > 0 ? NormalUpperQuantileLog(LogStudentTUpper(std::abs(delay) / sigma, ls.blocks - 1.0))
                : 0.0;
  JudgeLag(alpha_c, std::abs(delay) >= c.s.min_accel_lag_periods * c.dt,
           "the lag is measurable (z beyond critical) but |" + Fixed(delay * 1e3, 3) +
               " ms| is below " + Fixed(c.s.min_accel_lag_periods, 2) + " sample periods",
           al);
  if (!first || !second)
    al.note += std::string(al.note.empty() ? "" : "; ") + "a half of the stream gives no lag (" +
               (first ? second.error() : first.error()) + "): the gain is not measured";
  if (al.significant && delay < 0)
    al.note += std::string(al.note.empty() ? "" : "; ") +
               "the accelerometer leads the positions (or the position sensor is late): the "
               "position KF cannot take out a lead, its extension applies 0";
  const double half_sigma = sigma * std::sqrt(2.0);
  al.values = {{"accel_lag_s", delay, sigma},
               {"accel_lag_first_half_s", r.delay_first, half_sigma},
               {"accel_lag_second_half_s", r.delay_second, half_sigma},
               {"lever_arm_x_m", whole->lever_arm_B.x(), 0.0},
               {"lever_arm_y_m", whole->lever_arm_B.y(), 0.0},
               {"lever_arm_z_m", whole->lever_arm_B.z(), 0.0},
               {"jerk_rms_m_s3", whole->jerk_rms, 0.0},
               {"residual_rms_m_s2", whole->residual_rms, 0.0},
               {"position_triplets", static_cast<double>(whole->triplets), 0.0},
               {"position_period_s", c.s.accel_lag_position_period_s, 0.0}};
  return r;
}

// The position KF as position_kf runs it by default (the bank of DefaultBankModels, ENU, the
// lever arm estimated) with accel_delay δ (a lead applied as 0) over the stream: its error |p̂ − p|
// [m] at the movement samples in [begin, end) it did not fuse, into err[k] (NaN elsewhere left).
void PositionErrors(const Context& c, const std::vector<Eigen::Vector4d>& q_base,
                    const AccelLagTest& r, double gravity, double delay, int begin, int end,
                    std::vector<double>& err) {
  est::PositionKfSettings base;
  base.earth = est::EarthFrame::kEnu;
  base.gravity = gravity;
  base.position_sigma = c.s.accel_lag_position_sigma;
  base.estimate_lever_arm = true;  // the IMU is seldom at the tracked point
  base.accel_delay = std::clamp(delay, 0.0, est::kMaxAccelDelay);
  est::PositionKfBankSettings bank_settings;
  bank_settings.models = est::DefaultBankModels(base);
  est::PositionKfBank kf(bank_settings);
  for (int k = 0; k < end; ++k) {
    if (!q_base[k].allFinite()) continue;
    (void)kf.UpdateAccel(c.d.t[k], c.d.accel[k], geometry::QuatToMatrix(q_base[k]),
                         c.d.gyro[k] - r.gyro_bias);
    if (r.tracker[k]) {
      (void)kf.UpdatePosition(c.d.t[k], c.d.p_W[k]);
      continue;
    }
    if (k >= begin && kf.initialized() && Moving(c.d, c.rest_mask, k) && c.d.p_W[k].allFinite())
      err[k] = (kf.p_WM_W() - c.d.p_W[k]).norm();
  }
}

double RmsOfFinite(const std::vector<double>& v) {
  Rms r;
  for (double x : v)
    if (std::isfinite(x)) r.Add(x);
  return r.value();
}

// accel_lag's gain: the base position KF (δ = 0) against δ of one half applied to the other; the
// per-sample errors into a (for the report's plot).
void MeasureAccelLagGain(const Context& c, const std::vector<Eigen::Vector4d>& q_base,
                         const AccelLagTest& r, double gravity, ImuAnalysis& a) {
  ImuCandidate& al = a.candidates[4];
  if (!al.tested || !std::isfinite(r.delay_first) || !std::isfinite(r.delay_second)) return;
  spdlog::info("imu analysis: position KF with and without the accelerometer's lag");
  a.position_err_base_m.assign(c.n, kNaN);
  a.position_err_ext_m.assign(c.n, kNaN);
  PositionErrors(c, q_base, r, gravity, 0.0, 0, c.n, a.position_err_base_m);
  PositionErrors(c, q_base, r, gravity, r.delay_second, 0, r.split, a.position_err_ext_m);
  PositionErrors(c, q_base, r, gravity, r.delay_first, r.split, c.n, a.position_err_ext_m);
  al.position_before_m = RmsOfFinite(a.position_err_base_m);
  al.position_after_m = RmsOfFinite(a.position_err_ext_m);
}

// ----- Gains -----

// The fitted extensions' filter settings (see the header comment).
struct ExtensionSettings {
  double gyro_bias_random_walk = 0.0;
  double mag_ref_norm = 0.0, mag_ref_dip = 0.0;
  double mag_norm_tolerance = 0.0, mag_dip_tolerance = 0.0;
};

// The base filter with any of the fitted extensions, each run once.
class ExtendedFilters {
 public:
  ExtendedFilters(const ImuStreamData& data, const est::OrientationKfSettings& base,
                  const ExtensionSettings& ext)
      : data_(data), base_(base), ext_(ext) {}

  // q per sample of the base filter with the extensions chosen.
  const std::vector<Eigen::Vector4d>& Run(bool bias, bool mag, bool acc) {
    const std::string key = std::string(bias ? "B" : "-") + (mag ? "M" : "-") + (acc ? "A" : "-");
    if (!runs_.count(key)) {
      spdlog::info("imu analysis: filter run '{}'", key);
      runs_[key] = RunOrientationFilter(data_, Settings(bias, mag, acc));
    }
    return runs_[key];
  }

 private:
  est::OrientationKfSettings Settings(bool bias, bool mag, bool acc) const {
    est::OrientationKfSettings f = base_;
    if (bias) f.gyro_bias_random_walk = ext_.gyro_bias_random_walk;
    if (mag) {
      f.reject_mag = true;
      f.mag_ref_norm = ext_.mag_ref_norm;
      f.mag_ref_dip = ext_.mag_ref_dip;
      f.mag_norm_tolerance = ext_.mag_norm_tolerance;
      f.mag_dip_tolerance = ext_.mag_dip_tolerance;
    }
    if (acc) f.reject_accel = true;
    return f;
  }

  const ImuStreamData& data_;
  const est::OrientationKfSettings base_;
  const ExtensionSettings ext_;
  std::map<std::string, std::vector<Eigen::Vector4d>> runs_;
};

// Cross-fitted offset scoring: τ from one half applied to the other.
OrientationScore ScoreShifted(const Context& c, const std::vector<Eigen::Vector4d>& q,
                              const TimeOffsetTest& t) {
  OrientationScore s1 = ScoreAgainstTruth(c.d, q, t.tau_second, 0, t.split);
  const OrientationScore s2 = ScoreAgainstTruth(c.d, q, t.tau_first, t.split, c.n);
  s1.total.sum += s2.total.sum;
  s1.total.n += s2.total.n;
  s1.heading.sum += s2.heading.sum;
  s1.heading.n += s2.heading.n;
  s1.inclination.sum += s2.inclination.sum;
  s1.inclination.n += s2.inclination.n;
  return s1;
}

// Each candidate's gain alone (truth present): base filter vs base + its extension.
void MeasureCandidateGains(const Context& c, const std::vector<Eigen::Vector4d>& q_base,
                           const TimeOffsetTest& t, ExtendedFilters& filters, ImuAnalysis& a) {
  const auto& data = c.d;
  ImuCandidate &gb = a.candidates[0], &md = a.candidates[1], &am = a.candidates[2],
               &to = a.candidates[3];
  gb.before = md.before = am.before = to.before = a.base_score;
  gb.after = ScoreAgainstTruth(data, filters.Run(true, false, false));
  const auto& q_mag = filters.Run(false, true, false);
  md.after = ScoreAgainstTruth(data, q_mag);
  // Heading over the disturbed windows alone (movement samples), where the gate acts.
  Rms hb, he;
  for (int k = 0; k < c.n; ++k) {
    if (!a.mag_disturbed[k] || !Moving(data, c.rest_mask, k) || !data.q_truth[k].allFinite() ||
        !q_base[k].allFinite() || !q_mag[k].allFinite())
      continue;
    hb.Add(BroadErrors(q_base[k], data.q_truth[k]).heading);
    he.Add(BroadErrors(q_mag[k], data.q_truth[k]).heading);
  }
  md.values.push_back({"disturbed_window_samples", static_cast<double>(hb.n), 0.0});
  md.values.push_back({"heading_rmse_disturbed_windows_base_rad", hb.value(), 0.0});
  md.values.push_back({"heading_rmse_disturbed_windows_extended_rad", he.value(), 0.0});
  am.after = ScoreAgainstTruth(data, filters.Run(false, false, true));
  if (to.tested && std::isfinite(t.tau_first) && std::isfinite(t.tau_second))
    to.after = ScoreShifted(c, q_base, t);
}

// Per-sample heading and total errors of the base and the extended filter into a.
void StoreErrorSeries(const Context& c, const std::vector<Eigen::Vector4d>& q_base,
                      const std::vector<Eigen::Vector4d>& q_ext, ImuAnalysis& a) {
  a.heading_err_base_rad.assign(c.n, kNaN);
  a.heading_err_ext_rad.assign(c.n, kNaN);
  a.total_err_base_rad.assign(c.n, kNaN);
  a.total_err_ext_rad.assign(c.n, kNaN);
  for (int k = 0; k < c.n; ++k) {
    const auto& qt = c.d.q_truth[k];
    if (!qt.allFinite()) continue;
    if (q_base[k].allFinite()) {
      const AngleErrors e = BroadErrors(q_base[k], qt);
      a.heading_err_base_rad[k] = e.heading;
      a.total_err_base_rad[k] = e.total;
    }
    if (q_ext[k].allFinite()) {
      const AngleErrors e = BroadErrors(q_ext[k], qt);
      a.heading_err_ext_rad[k] = e.heading;
      a.total_err_ext_rad[k] = e.total;
    }
  }
}

// The gain of all selected extensions together (truth present), and the error series.
void MeasureSelectionGain(const Context& c, const std::vector<Eigen::Vector4d>& q_base,
                          const TimeOffsetTest& t, ExtendedFilters& filters, ImuAnalysis& a) {
  const bool sb = a.candidates[0].named(), sm = a.candidates[1].named(),
             sa = a.candidates[2].named(), st = a.candidates[3].named();
  const auto& q_ext = filters.Run(sb, sm, sa);
  a.extended_score = st ? ScoreShifted(c, q_ext, t) : ScoreAgainstTruth(c.d, q_ext);
  a.time_offset_s = st ? a.candidates[3].values[0].value : 0.0;
  StoreErrorSeries(c, q_base, q_ext, a);
}

}  // namespace

ImuAnalysis AnalyzeImuStream(const ImuStreamData& data, const ImuAnalysisSettings& settings) {
  ValidateImuStream(data);
  Context c = MakeContext(data, settings);
  const auto& s = settings;
  ImuAnalysis a;
  a.has_positions = false;
  for (const auto& p : data.p_W) a.has_positions |= p.allFinite();
  // Bonferroni over the candidates this stream can test: four, five with positions.
  const double alpha_c = s.alpha / (a.has_positions ? 5.0 : 4.0);

  a.samples = c.n;
  a.rate_hz = c.rate;
  a.has_movement = !data.movement.empty();
  a.has_truth = false;
  for (const auto& q : data.q_truth) a.has_truth |= q.allFinite();
  a.rests = FindRests(c, &a.short_rests);
  spdlog::info("imu analysis: {} samples at {:.1f} Hz, {} rest segments{}, truth {}", c.n, c.rate,
               a.rests.size(), a.short_rests ? " (short)" : "", a.has_truth ? "yes" : "no");
  if (a.rests.empty())
    throw std::invalid_argument(
        "IMU stream: no rest segment of at least " + Fixed(s.min_short_rest_s, 1) + " s (" +
        Fixed(s.min_rest_s, 1) + " s for every test) after cutting " + Fixed(s.rest_trim_s, 1) +
        " s from each end of every still run (movement = 0 or still); the longest still run is " +
        Fixed(c.longest_still / c.rate, 2) + " s");

  // The reference: the first rest (at most reference_max_s of it); with short rests the first
  // rests pooled until they hold min_rest_s.
  c.ref_mask.assign(c.n, 0);
  const int ref_max = static_cast<int>(s.reference_max_s * c.rate);
  const int ref_want = a.short_rests ? static_cast<int>(std::round(s.min_rest_s * c.rate)) : 1;
  int ref_len = 0;
  for (auto [b, e] : a.rests) {
    if (ref_len >= ref_want || ref_len >= ref_max) break;
    const int e2 = std::min(e, b + ref_max - ref_len);
    for (int k = b; k < e2; ++k) c.ref_mask[k] = 1;
    ref_len += e2 - b;
    ++a.reference_rests;
  }
  a.reference_s = ref_len / c.rate;
  FitReference(c, a);
  if (a.short_rests) {
    int longest = 0;
    for (auto [b, e] : a.rests) longest = std::max(longest, e - b);
    a.rest_note = "no rest of " + Fixed(s.min_rest_s, 1) + " s: " + std::to_string(a.rests.size()) +
                  " short rests used (longest " + Fixed(longest / c.rate, 2) +
                  " s, after cutting " + Fixed(s.rest_trim_s, 1) +
                  " s from each end); the reference field and noise pooled over the first " +
                  std::to_string(a.reference_rests) + " (" + Fixed(a.reference_s, 2) +
                  " s); the Allan deviation reaches τ = " + Fixed(longest / 2 / c.rate, 2) +
                  " s, so the long-τ Allan test (τ ≥ " + Fixed(s.allan_test_tau_min_s, 1) +
                  " s, rests of " + Fixed(2 * s.allan_test_tau_min_s, 1) +
                  " s) cannot run: gyro_bias is tested only by the drift between the first and "
                  "the last rest (a bias that wanders and returns is not seen)";
    spdlog::warn("imu analysis: {}", a.rest_note);
  }

  spdlog::info("imu analysis: base filter (trusts every sample, constant gyro bias)");
  est::OrientationKfSettings base_f = BaseFilter(s);
  base_f.max_step = est::MaxStepForRate(c.rate, base_f.max_step);  // a slow IMU is not silent
  const std::vector<Eigen::Vector4d> q_base = RunOrientationFilter(data, base_f);

  const ImuCandidate gb = TestGyroBias(c, alpha_c, a);
  const ImuCandidate md = TestMagneticDisturbance(c, q_base, alpha_c, a);
  const ImuCandidate am = TestAccelMotion(c, q_base, alpha_c, a);
  // The base filter against the truth (movement samples; empty without truth), scored once.
  a.base_score = ScoreAgainstTruth(data, q_base);
  const TimeOffsetTest to = TestTimeOffset(c, a.base_score, alpha_c, a.has_truth);
  const ExtensionSettings ext{gb.values.back().value, a.mag_ref_norm_uT, a.mag_ref_dip_rad,
                              a.mag_gate_norm_uT / a.mag_ref_norm_uT, a.mag_gate_dip_rad};
  ExtendedFilters filters(data, base_f, ext);
  // The lag is fitted with the truth's attitude where the stream has one (as the time offset is):
  // the base filter's, which trusts a linearly accelerating accelerometer, scatters it by its tilt
  // errors (simulated streams with 6 m/s²: σ 0.2–0.5 ms against 0.02–0.04 ms) and shifts it by its
  // own timing. The gain is the position KF's with the filter's attitude, as the pipeline runs it.
  const AccelLagTest al = TestAccelLag(c, a.has_truth ? data.q_truth : q_base, alpha_c, a);
  a.candidates = {gb, md, am, to.candidate, al.candidate};
  MeasureAccelLagGain(c, q_base, al, a.gravity_ref, a);
  if (a.has_truth) MeasureCandidateGains(c, q_base, to, filters, a);
  MarkLosingExtensions(a.candidates);  // accel_lag's truth is the positions, with or without q
  a.gain_metric = a.candidates[1].named() ? "heading" : "total";  // the gate acts on heading
  if (a.has_truth) MeasureSelectionGain(c, q_base, to, filters, a);
  for (const auto& cnd : a.candidates)
    spdlog::info("imu analysis: {} {} (z {}, critical {:.2f}){}{}", cnd.cause,
                 !cnd.tested       ? "not tested"
                 : cnd.named()     ? "FOUND"
                 : cnd.significant ? "significant but not named"
                                   : "not significant",
                 ZText(cnd.statistic, 2), cnd.critical, cnd.note.empty() ? "" : ": ", cnd.note);
  return a;
}

}  // namespace rcal::discrepancy
