#include "rcal/estimation/clock_offset.hpp"
#include "rcal/numeric/median.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

namespace rcal::estimation {
namespace {

std::string Fmt(const char* format, double a, double b = 0.0, double c = 0.0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, format, a, b, c);
  return buf;
}

// Weights w_k of the slope b of the least-squares quadratic a + b·τ + c·τ² through (τ_k, ·):
// b = Σ w_k y_k. Shared by every joint / axis of one fit. False when the stamps cannot carry a
// quadratic (fewer than three distinct times).
bool SlopeWeights(const std::vector<double>& tau, std::vector<double>& w) {
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  for (double t : tau) {
    const Eigen::Vector3d phi(1.0, t, t * t);
    M += phi * phi.transpose();
  }
  Eigen::LDLT<Eigen::Matrix3d> ldlt(M);
  if (ldlt.info() != Eigen::Success || !(std::abs(ldlt.vectorD().minCoeff()) > 1e-300))
    return false;
  const Eigen::Vector3d e = ldlt.solve(Eigen::Vector3d::UnitY());  // row 1 of M⁻¹ (M symmetric)
  if (!e.allFinite()) return false;
  w.resize(tau.size());
  for (size_t k = 0; k < tau.size(); ++k) w[k] = e(0) + e(1) * tau[k] + e(2) * tau[k] * tau[k];
  return true;
}

// The reference of one source as a function of joint time: |ω_T| (IMU) or |v_T + ω_T × r|
// (tracker), linearly interpolated between reference samples.
class ReferenceSignal {
 public:
  ReferenceSignal(const std::vector<ReferenceSample>& ref, ClockSource source)
      : ref_(ref), source_(source) {}
  double t_first() const { return ref_.front().t; }
  double t_last() const { return ref_.back().t; }

  // Interpolated v_T, ω_T at t (clamped to the span).
  void At(double t, Eigen::Vector3d& v, Eigen::Vector3d& w) const {
    auto it = std::upper_bound(ref_.begin(), ref_.end(), t,
                               [](double x, const ReferenceSample& s) { return x < s.t; });
    if (it == ref_.begin()) {
      v = ref_.front().v_T;
      w = ref_.front().omega_T;
      return;
    }
    if (it == ref_.end()) {
      v = ref_.back().v_T;
      w = ref_.back().omega_T;
      return;
    }
    const ReferenceSample& b = *it;
    const ReferenceSample& a = *(it - 1);
    const double u = (t - a.t) / (b.t - a.t);
    v = a.v_T + u * (b.v_T - a.v_T);
    w = a.omega_T + u * (b.omega_T - a.omega_T);
  }
  // |ω_T + b| (IMU, b the gyro bias in T) or |v_T + ω_T × r| (tracker).
  double Value(double t, const Eigen::Vector3d& vec) const {
    Eigen::Vector3d grad;
    return ValueAndGrad(t, vec, grad);
  }
  // The value and its gradient in the vector: û (IMU) or û × ω_T (tracker).
  double ValueAndGrad(double t, const Eigen::Vector3d& vec, Eigen::Vector3d& grad) const {
    Eigen::Vector3d v, w;
    At(t, v, w);
    const Eigen::Vector3d u =
        source_ == ClockSource::kImu ? Eigen::Vector3d(w + vec) : Eigen::Vector3d(v + w.cross(vec));
    const double n = u.norm();
    grad.setZero();
    if (n > 1e-12) grad = source_ == ClockSource::kImu ? Eigen::Vector3d(u / n) : (u / n).cross(w);
    return n;
  }

 private:
  const std::vector<ReferenceSample>& ref_;
  ClockSource source_;
};

// Linear interpolation of measured samples (increasing t) at t, clamped.
double InterpolateMeasured(const std::vector<SourceSample>& m, size_t& cursor, double t) {
  while (cursor + 1 < m.size() && m[cursor + 1].t <= t) ++cursor;
  if (t <= m[cursor].t || cursor + 1 >= m.size()) return m[cursor].y;
  const SourceSample& a = m[cursor];
  const SourceSample& b = m[cursor + 1];
  return a.y + (t - a.t) / (b.t - a.t) * (b.y - a.y);
}

}  // namespace

const char* ClockSourceName(ClockSource s) {
  return s == ClockSource::kImu ? "imu" : "marker";
}

const char* ClockStateName(ClockState s) {
  switch (s) {
    case ClockState::kUnknown:
      return "unknown";
    case ClockState::kEstimating:
      return "estimating";
    case ClockState::kLocked:
      return "locked";
  }
  return "?";
}

std::vector<SourceSample> MarkerSpeeds(const std::vector<double>& t,
                                       const std::vector<Eigen::Vector3d>& p,
                                       double half_window_s) {
  std::vector<SourceSample> out;
  const size_t n = std::min(t.size(), p.size());
  if (n < 5) return out;
  out.reserve(n);
  std::vector<double> tau, w;
  size_t lo = 0, hi = 0;  // window [lo, hi)
  for (size_t i = 0; i < n; ++i) {
    // Only samples whose window lies inside the data: a one-sided fit at the ends would see
    // the motion of one side only.
    if (t[i] - half_window_s < t[0] || t[i] + half_window_s > t[n - 1]) continue;
    while (t[lo] < t[i] - half_window_s) ++lo;
    if (hi < i + 1) hi = i + 1;
    while (hi < n && t[hi] <= t[i] + half_window_s) ++hi;
    if (i - lo < 2 || hi - i < 3) continue;  // at least two samples on each side
    tau.clear();
    for (size_t k = lo; k < hi; ++k) tau.push_back(t[k] - t[i]);
    if (!SlopeWeights(tau, w)) continue;
    Eigen::Vector3d v = Eigen::Vector3d::Zero();
    for (size_t k = lo; k < hi; ++k) v += w[k - lo] * p[k];
    out.push_back({t[i], v.norm()});
  }
  return out;
}

OffsetWindowEstimate EstimateOffsetWindow(const std::vector<ReferenceSample>& reference,
                                          const std::vector<SourceSample>& measured,
                                          ClockSource source, const ClockOffsetSettings& s) {
  OffsetWindowEstimate out;
  const bool imu = source == ClockSource::kImu;
  if (reference.size() < 10 || measured.size() < 10) {
    out.reason = "too few samples (" + std::to_string(reference.size()) + " joint, " +
                 std::to_string(measured.size()) + " " + ClockSourceName(source) + ")";
    return out;
  }
  const ReferenceSignal ref(reference, source);
  const double L = s.max_lag_s, step = s.coarse_step_s;
  // Source samples that map inside the joint span for every lag of the search, with a margin
  // of two steps for the refinement.
  const double lo = ref.t_first() + L + 2 * step, hi = ref.t_last() - L - 2 * step;
  // A gyro sample is the mean rate over the interval that ends at its stamp (the orientation
  // filter's convention, and a rate-integrating gyro's): it is compared with the reference at
  // that interval's midpoint, half the median stamp spacing earlier, so that the offset is the
  // stamp's and the filter fed with it integrates each interval where it happened.
  double shift = 0.0;
  if (imu) {
    std::vector<double> gaps;
    gaps.reserve(measured.size());
    for (size_t k = 1; k < measured.size(); ++k) gaps.push_back(measured[k].t - measured[k - 1].t);
    shift = 0.5 * numeric::UpperMedian(std::move(gaps));
  }
  std::vector<SourceSample> m;
  for (const auto& x : measured)
    if (x.t - shift >= lo && x.t - shift <= hi) m.push_back({x.t - shift, x.y});
  const double span = m.size() >= 2 ? m.back().t - m.front().t : 0.0;
  if (m.size() < 10 || span < s.min_window_s) {
    out.reason =
        Fmt("window %.2f s of source and joints overlapping beyond the lag range, "
            "min_window_s %.2f s",
            span, s.min_window_s);
    return out;
  }

  // Coarse: both signals on a grid of `step`; y_i at g_i = g_0 + i·step, x_k at joint time
  // g_0 + (k − K)·step, so lag d_j = (j − K)·step pairs y_i with x(g_i − d_j) = x_{i − j + 2K}.
  const int K = static_cast<int>(std::lround(L / step));
  const int M = static_cast<int>(std::floor(span / step)) + 1;
  std::vector<double> y(M), x(M + 2 * K);
  size_t cursor = 0;
  for (int i = 0; i < M; ++i) y[i] = InterpolateMeasured(m, cursor, m.front().t + i * step);
  const Eigen::Vector3d v0 = Eigen::Vector3d::Zero();
  for (int k = 0; k < M + 2 * K; ++k) x[k] = ref.Value(m.front().t + (k - K) * step, v0);
  {
    double mean = 0, sq = 0;
    for (int i = 0; i < M; ++i) mean += x[i + K];
    mean /= M;
    for (int i = 0; i < M; ++i) sq += (x[i + K] - mean) * (x[i + K] - mean);
    const double rms = std::sqrt(sq / M);
    const double min_rms = imu ? s.min_rate_rms : s.min_speed_rms;
    if (!(rms >= min_rms)) {
      out.reason = Fmt(imu ? "too little motion: reference |omega| RMS %.4f rad/s < %.4f"
                           : "too little motion: reference speed RMS %.4f m/s < %.4f",
                       rms, min_rms);
      return out;
    }
  }
  double sy = 0, syy = 0;
  for (double v : y) {
    sy += v;
    syy += v * v;
  }
  const double vy = syy - sy * sy / M;
  std::vector<double> corr(2 * K + 1, -2.0);
  // Sliding sums of the reference over the pairs of each lag.
  for (int j = 0; j <= 2 * K; ++j) {
    double sx = 0, sxx = 0, sxy = 0;
    const double* xs = x.data() + (2 * K - j);
    for (int i = 0; i < M; ++i) {
      sx += xs[i];
      sxx += xs[i] * xs[i];
      sxy += xs[i] * y[i];
    }
    const double vx = sxx - sx * sx / M, cxy = sxy - sx * sy / M;
    if (vx > 0 && vy > 0) corr[j] = cxy / std::sqrt(vx * vy);
  }
  const int jm = static_cast<int>(std::max_element(corr.begin(), corr.end()) - corr.begin());
  out.correlation = corr[jm];
  if (jm == 0 || jm == 2 * K) {
    out.reason = Fmt("correlation peak at the edge of the lag range (±%.3f s)", L);
    return out;
  }
  if (!(corr[jm] >= s.min_correlation)) {
    out.reason = Fmt("correlation peak %.3f < min_correlation %.3f", corr[jm], s.min_correlation);
    return out;
  }
  const double cm = corr[jm - 1], c0 = corr[jm], cp = corr[jm + 1];
  const double den = cm - 2 * c0 + cp;
  const double frac = den < 0 ? std::clamp(0.5 * (cm - cp) / den, -0.5, 0.5) : 0.0;
  const double d0 = (jm - K + frac) * step;

  // Refine: Gauss–Newton on θ = [d, c, vector, gain knots] (see the header). The vector is
  // the gyro bias b_T (IMU) or the marker offset r (tracker), bounded by its prior; the gain
  // g(t) is piecewise linear between knots gain_knot_s apart, each knot bounded around 1.
  const bool fit_v = imu ? s.estimate_gyro_bias : s.estimate_marker_offset;
  const double prior_v = imu ? s.gyro_bias_prior : s.marker_offset_prior_m;
  const int n = static_cast<int>(m.size());
  const double knot = s.gain_knot_s > 0 ? s.gain_knot_s : 2 * span;
  const int nk = static_cast<int>(std::ceil(span / knot)) + 1;
  const int ic = 1, iv = 2, ig = iv + (fit_v ? 3 : 0);
  const int np = ig + nk;
  double d = d0, c = 0.0;
  Eigen::Vector3d vec = Eigen::Vector3d::Zero();
  Eigen::VectorXd g = Eigen::VectorXd::Ones(nk);
  std::vector<int> knot_of(n);
  std::vector<double> frac_of(n);
  for (int k = 0; k < n; ++k) {
    const double u = (m[k].t - m.front().t) / knot;
    knot_of[k] = std::min(nk - 2, static_cast<int>(std::floor(u)));
    frac_of[k] = u - knot_of[k];
  }
  auto gain = [&](int k) {
    return (1 - frac_of[k]) * g(knot_of[k]) + frac_of[k] * g(knot_of[k] + 1);
  };
  const double h = s.slope_step_s;
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(n, np);
  Eigen::VectorXd e(n);
  Eigen::VectorXd prior_w = Eigen::VectorXd::Zero(np);  // prior information, units of s²
  Eigen::VectorXd prior_mean = Eigen::VectorXd::Zero(np);
  prior_mean.tail(nk).setOnes();
  double s2 = 0.0;
  auto theta = [&] {
    Eigen::VectorXd th = Eigen::VectorXd::Zero(np);
    th(0) = d;
    th(ic) = c;
    if (fit_v) th.segment<3>(iv) = vec;
    th.tail(nk) = g;
    return th;
  };
  auto linearise = [&] {
    for (int k = 0; k < n; ++k) {
      const double t = m[k].t - d, gk = gain(k);
      Eigen::Vector3d gv;
      const double f = ref.ValueAndGrad(t, vec, gv);
      const double fdot = (ref.Value(t + h, vec) - ref.Value(t - h, vec)) / (2 * h);
      e(k) = m[k].y - (gk * f + c);
      J(k, 0) = -gk * fdot;  // ∂(g f(s − d) + c)/∂d
      J(k, ic) = 1.0;
      if (fit_v) J.block<1, 3>(k, iv) = gk * gv.transpose();
      J(k, ig + knot_of[k]) = (1 - frac_of[k]) * f;
      J(k, ig + knot_of[k] + 1) = frac_of[k] * f;
    }
    s2 = e.squaredNorm() / std::max(1, n - np);
    if (fit_v) prior_w.segment<3>(iv).setConstant(s2 / (prior_v * prior_v));
    prior_w.tail(nk).setConstant(s2 / (s.gain_prior * s.gain_prior));
  };
  {  // c: the mean difference at the coarse offset
    double sum = 0;
    for (int k = 0; k < n; ++k) sum += m[k].y - ref.Value(m[k].t - d, vec);
    c = sum / n;
  }
  Eigen::MatrixXd H;
  for (int it = 0; it < s.gauss_newton_iterations; ++it) {
    linearise();
    H = J.transpose() * J;
    H.diagonal() += prior_w;
    const Eigen::VectorXd rhs = J.transpose() * e - prior_w.cwiseProduct(theta() - prior_mean);
    const Eigen::VectorXd delta = H.ldlt().solve(rhs);
    if (!delta.allFinite()) {
      out.reason = "refinement singular";
      return out;
    }
    const double dd = std::clamp(delta(0), -step, step);
    d += dd;
    c += delta(ic);
    if (fit_v) vec += delta.segment<3>(iv);
    g += delta.tail(nk);
    if (std::abs(dd) < 1e-8) break;
  }
  if (std::abs(d - d0) > 2 * step) {
    out.reason = Fmt("refinement left the coarse peak (%.4f s -> %.4f s)", d0, d);
    return out;
  }
  linearise();
  H = J.transpose() * J;
  H.diagonal() += prior_w;
  // σ of d: the sandwich b₀ᵀ Ω b₀, b₀ the first row of H⁻¹, Ω the Newey–West estimate of
  // Cov(Jᵀe) plus the priors' information; only the scalar series z_k = b₀ᵀ J_kᵀ e_k is needed.
  const Eigen::VectorXd b0 = H.ldlt().solve(Eigen::VectorXd::Unit(np, 0));
  const Eigen::VectorXd z = (J * b0).cwiseProduct(e);
  const double rate = (n - 1) / span;
  const int lags = std::max(0, static_cast<int>(std::lround(s.residual_correlation_s * rate)));
  double var = z.squaredNorm();
  for (int l = 1; l <= std::min(lags, n - 1); ++l) {
    const double wl = 1.0 - static_cast<double>(l) / (lags + 1);
    var += 2 * wl * z.tail(n - l).dot(z.head(n - l));
  }
  var += s2 * b0.cwiseProduct(b0).dot(prior_w);
  if (!(var > 0) || !std::isfinite(var)) {
    out.reason = "offset variance not positive";
    return out;
  }
  out.offset_s = d;
  out.sigma_s = std::sqrt(var);
  out.residual_rms = std::sqrt(e.squaredNorm() / n);
  out.gain = g.mean();
  if (imu)
    out.gyro_bias_T = vec;
  else
    out.marker_r_T = vec;
  out.samples = n;
  return out;
}

Status MayFormStillWindow(const ClockOffset& o, ClockSource source, double window_s,
                          double fraction) {
  const double limit = fraction * window_s;
  if (o.state == ClockState::kUnknown || !std::isfinite(o.sigma_s))
    return Status::Error(std::string(ClockSourceName(source)) +
                         " clock offset: unknown, no still window may be formed");
  if (!(o.sigma_s <= limit))
    return Status::Error(std::string(ClockSourceName(source)) +
                         Fmt(" clock offset: sigma %.1f ms > %.3f x window %.0f ms",
                             1e3 * o.sigma_s, fraction, 1e3 * window_s));
  return Status::Ok();
}

// ---------------------------------------------------------------------------------------------

ClockOffsetEstimator::ClockOffsetEstimator(kinematics::KinematicModel model,
                                           const ClockOffsetSettings& settings)
    : model_(std::move(model)), x0_(model_.Nominal()), settings_(settings) {
  TimeGateSettings g;
  g.horizon_us = std::max<int64_t>(1, std::llround(settings_.jump_forward_s * 1e6));
  g.resync_samples = std::max(1, settings_.resync_samples);
  g.resync_min_jump_back_us = std::max<int64_t>(0, std::llround(settings_.jump_back_s * 1e6));
  g.gap_factor = 0.0;
  joint_gate_ = TimeGate(g);
  gates_ = {TimeGate(g), TimeGate(g)};
  settings_.joint_derivative_half_width = std::max(1, settings_.joint_derivative_half_width);
}

Status ClockOffsetEstimator::Refuse(int64_t& counter, std::string reason) {
  ++counter;
  last_error_ = reason;
  return Status::Error(std::move(reason));
}

Status ClockOffsetEstimator::CheckStamp(TimeGate& gate, StreamCounters& c, double t,
                                        const char* stream, bool& jumped) {
  jumped = false;
  if (!std::isfinite(t) || std::abs(t) > settings_.max_abs_time_s)
    return Refuse(c.bad_value, std::string(stream) + ".t: not a time (" + Fmt("%g s", t) + ")");
  const int64_t u = std::llround(t * 1e6);
  const TimeVerdict v = gate.Offer(u);
  if (!Usable(v)) return Refuse(c.bad_time, gate.Reason(v, u, std::string(stream) + ".t"));
  if (v == TimeVerdict::kResynchronised) {
    ++c.clock_jumps;
    jumped = true;
  }
  ++c.accepted;
  return Status::Ok();
}

ReferenceSample ClockOffsetEstimator::Reference(double t, const Eigen::VectorXd& q,
                                                const Eigen::VectorXd& qd) const {
  const Eigen::MatrixXd J = model_.JointJacobian(q, x0_);
  const Eigen::Matrix3d R_WT = model_.ToolFrame(q, x0_).linear();
  ReferenceSample r;
  r.t = t;
  r.v_T = R_WT.transpose() * (J.topRows<3>() * qd);
  r.omega_T = R_WT.transpose() * (J.bottomRows<3>() * qd);
  return r;
}

Status ClockOffsetEstimator::PushJoints(double t, const Eigen::VectorXd& q) {
  return PushJoints(t, q, Eigen::VectorXd());
}

Status ClockOffsetEstimator::PushJoints(double t, const Eigen::VectorXd& q,
                                        const Eigen::VectorXd& qd) {
  auto& c = joint_counters_;
  const int nj = model_.num_joints();
  if (q.size() != nj)
    return Refuse(c.bad_value, "joints.q: " + std::to_string(q.size()) + " values, the model has " +
                                   std::to_string(nj));
  for (int i = 0; i < nj; ++i)
    if (!std::isfinite(q(i)) || std::abs(q(i)) > settings_.max_joint_value)
      return Refuse(c.bad_value, "joints.q[" + std::to_string(i) + "]: " + Fmt("%g", q(i)) +
                                     " not finite or beyond max_joint_value");
  const bool has_qd = qd.size() > 0;
  if (has_qd && qd.size() != nj)
    return Refuse(c.bad_value, "joints.qd: " + std::to_string(qd.size()) +
                                   " values, the model has " + std::to_string(nj));
  for (int i = 0; has_qd && i < nj; ++i)
    if (!std::isfinite(qd(i)) || std::abs(qd(i)) > settings_.max_joint_speed)
      return Refuse(c.bad_value, "joints.qd[" + std::to_string(i) + "]: " + Fmt("%g", qd(i)) +
                                     " not finite or beyond max_joint_speed");
  bool jumped = false;
  if (Status st = CheckStamp(joint_gate_, c, t, "joints", jumped); !st) return st;
  if (jumped) {  // every offset was against the old joint clock
    joints_.clear();
    next_joint_ = 0;
    reference_.clear();
    for (int s = 0; s < kNumClockSources; ++s) ResetSource(static_cast<ClockSource>(s));
  }
  joints_.push_back({t, q, has_qd ? std::optional<Eigen::VectorXd>(qd) : std::nullopt});
  ProcessJoints();
  while (!reference_.empty() &&
         (reference_.front().t < t - settings_.buffer_s ||
          static_cast<int>(reference_.size()) > settings_.max_buffer_samples))
    reference_.pop_front();
  return Status::Ok();
}

void ClockOffsetEstimator::ProcessJoints() {
  const size_t hw = static_cast<size_t>(settings_.joint_derivative_half_width);
  std::vector<double> tau, w;
  while (next_joint_ < joints_.size()) {
    const JointSample& js = joints_[next_joint_];
    if (js.qd) {
      reference_.push_back(Reference(js.t, js.q, *js.qd));
    } else {
      if (next_joint_ + hw >= joints_.size()) break;  // waits for its successors
      const size_t lo = next_joint_ >= hw ? next_joint_ - hw : 0, hi = next_joint_ + hw;
      tau.clear();
      for (size_t k = lo; k <= hi; ++k) tau.push_back(joints_[k].t - js.t);
      if (SlopeWeights(tau, w)) {
        Eigen::VectorXd qd = Eigen::VectorXd::Zero(js.q.size());
        for (size_t k = lo; k <= hi; ++k) qd += w[k - lo] * joints_[k].q;
        reference_.push_back(Reference(js.t, js.q, qd));
      }
    }
    ++next_joint_;
  }
  // Keep the hw samples before the next one to process (its fit's left side).
  while (next_joint_ > hw) {
    joints_.pop_front();
    --next_joint_;
  }
}

void ClockOffsetEstimator::ResetSource(ClockSource s) {
  const int i = Index(s);
  offsets_[i] = ClockOffset{};
  combined_[i] = Combined{};
  has_samples_[i] = false;
  next_estimate_[i] = 0.0;
  if (s == ClockSource::kImu) {
    gyro_.clear();
  } else {
    marker_t_.clear();
    marker_p_.clear();
  }
}

void ClockOffsetEstimator::MaybeEstimate(ClockSource s, double t) {
  const int i = Index(s);
  if (!has_samples_[i]) {
    has_samples_[i] = true;
    next_estimate_[i] = t + settings_.estimate_every_s;
    return;
  }
  if (t >= next_estimate_[i]) {
    next_estimate_[i] = t + settings_.estimate_every_s;
    Estimate(s);
  }
}

Status ClockOffsetEstimator::PushGyro(double t, const Eigen::Vector3d& omega_S) {
  auto& c = stream_counters_[Index(ClockSource::kImu)];
  if (!omega_S.allFinite() || omega_S.norm() > settings_.max_gyro)
    return Refuse(c.bad_value, "imu.gyro: " + Fmt("|omega| %g rad/s", omega_S.norm()) +
                                   " not finite or beyond max_gyro");
  bool jumped = false;
  if (Status st = CheckStamp(gates_[Index(ClockSource::kImu)], c, t, "imu", jumped); !st) return st;
  if (jumped) ResetSource(ClockSource::kImu);
  gyro_.push_back({t, omega_S.norm()});
  while (gyro_.front().t < t - settings_.buffer_s ||
         static_cast<int>(gyro_.size()) > settings_.max_buffer_samples)
    gyro_.pop_front();
  MaybeEstimate(ClockSource::kImu, t);
  return Status::Ok();
}

Status ClockOffsetEstimator::PushMarker(double t, const Eigen::Vector3d& p_WM_W) {
  auto& c = stream_counters_[Index(ClockSource::kMarker)];
  if (!p_WM_W.allFinite() || p_WM_W.norm() > settings_.max_position_m)
    return Refuse(c.bad_value, "marker.p_WM_W: " + Fmt("|p| %g m", p_WM_W.norm()) +
                                   " not finite or beyond max_position_m");
  bool jumped = false;
  if (Status st = CheckStamp(gates_[Index(ClockSource::kMarker)], c, t, "marker", jumped); !st)
    return st;
  if (jumped) ResetSource(ClockSource::kMarker);
  marker_t_.push_back(t);
  marker_p_.push_back(p_WM_W);
  while (marker_t_.front() < t - settings_.buffer_s ||
         static_cast<int>(marker_t_.size()) > settings_.max_buffer_samples) {
    marker_t_.pop_front();
    marker_p_.pop_front();
  }
  MaybeEstimate(ClockSource::kMarker, t);
  return Status::Ok();
}

OffsetWindowEstimate ClockOffsetEstimator::Estimate(ClockSource s) {
  const int i = Index(s);
  const std::vector<ReferenceSample> ref(reference_.begin(), reference_.end());
  std::vector<SourceSample> meas;
  if (s == ClockSource::kImu) {
    meas.assign(gyro_.begin(), gyro_.end());
  } else {
    meas = MarkerSpeeds(std::vector<double>(marker_t_.begin(), marker_t_.end()),
                        std::vector<Eigen::Vector3d>(marker_p_.begin(), marker_p_.end()),
                        settings_.marker_derivative_half_window_s);
  }
  const OffsetWindowEstimate w = EstimateOffsetWindow(ref, meas, s, settings_);
  auto& sc = source_counters_[i];
  ++sc.windows;
  if (!w.ok()) {
    ++sc.no_estimate;
    sc.last_reason = w.reason;
    return w;
  }
  ++sc.estimates;
  ClockOffset& o = offsets_[i];
  // Windows overlap (buffer_s long, one every estimate_every_s), so their estimates are combined
  // with inverse-variance weights and the variance inflated by the overlap; the scatter of the
  // windows about the mean (what the reference's model error moves from window to window, which
  // no single window's σ sees) bounds σ from below, over the independent windows it spans.
  const double window = meas.empty() ? 0.0 : meas.back().t - meas.front().t;
  if (o.state != ClockState::kUnknown &&
      std::abs(w.offset_s - o.offset_s) > 5.0 * std::hypot(w.sigma_s, o.sigma_s))
    ++sc.disagreements;
  Combined& cb = combined_[i];
  const double wt = 1.0 / (w.sigma_s * w.sigma_s);
  if (cb.n == 0) cb.first_t = meas.front().t;
  cb.last_t = meas.back().t;
  ++cb.n;
  cb.sw += wt;
  cb.swx += wt * w.offset_s;
  cb.swxx += wt * w.offset_s * w.offset_s;
  const double mean = cb.swx / cb.sw;
  const double overlap = std::max(1.0, window / std::max(1e-9, settings_.estimate_every_s));
  const double spanned = std::max(1.0, (cb.last_t - cb.first_t) / std::max(1e-9, window));
  const double scatter = std::max(0.0, cb.swxx / cb.sw - mean * mean);
  const double var = std::max(std::min(overlap, static_cast<double>(cb.n)) / cb.sw,
                              cb.n > 1 ? scatter / spanned : 0.0);
  // One window's σ does not see the model error (header): no lock before the scatter of
  // lock_min_windows independent windows bounds σ.
  const double covered = (cb.last_t - cb.first_t) / std::max(1e-9, window);
  const bool usable =
      std::sqrt(var) < settings_.max_sigma_s && covered >= settings_.lock_min_windows;
  o.state = usable ? ClockState::kLocked : ClockState::kEstimating;
  o.usable = usable;
  o.offset_s = mean;
  o.sigma_s = std::sqrt(var);
  o.correlation = w.correlation;
  o.residual_rms = w.residual_rms;
  o.window_s = window;
  o.estimated_at_s = meas.empty() ? 0.0 : meas.back().t;
  o.gain = w.gain;
  o.marker_r_T = w.marker_r_T;
  o.gyro_bias_T = w.gyro_bias_T;
  return w;
}

Status ClockOffsetEstimator::MayFormStillWindow(double window_s) const {
  for (int i = 0; i < kNumClockSources; ++i) {
    if (!has_samples_[i]) continue;
    if (Status st = estimation::MayFormStillWindow(offsets_[i], static_cast<ClockSource>(i),
                                                   window_s, settings_.still_window_sigma_fraction);
        !st)
      return st;
  }
  return Status::Ok();
}

void ClockOffsetEstimator::Reset() {
  joints_.clear();
  next_joint_ = 0;
  reference_.clear();
  joint_gate_.Reset();
  for (int i = 0; i < kNumClockSources; ++i) {
    gates_[i].Reset();
    ResetSource(static_cast<ClockSource>(i));
  }
}

}  // namespace rcal::estimation
