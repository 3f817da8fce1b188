#include "rcal/estimation/position_kf.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>

#include "frame_checks.hpp"
#include "rcal/geometry/so3.hpp"

namespace rcal::estimation {
namespace {

// Index of p, V, A of axis i in the Eq. 27 state order.
constexpr int IP(int i) {
  return 3 * i;
}
constexpr int IV(int i) {
  return 3 * i + 1;
}
constexpr int IA(int i) {
  return 3 * i + 2;
}

}  // namespace

Eigen::Matrix<double, 9, 9> PaperPhiPos(const Eigen::Matrix3d& M, double t) {
  Eigen::Matrix<double, 9, 9> Phi = Eigen::Matrix<double, 9, 9>::Identity();
  for (int i = 0; i < 3; ++i) {
    Phi(IP(i), IV(i)) = t;  // Eq. 26: ṗ = V (row 7 has no V_y term: NOTES.md erratum)
    for (int j = 0; j < 3; ++j) {
      // Eq. 25: V̇_i = Σ_j M(i, j) A_j.
      Phi(IP(i), IA(j)) = M(i, j) * t * t / 2.0;
      Phi(IV(i), IA(j)) = M(i, j) * t;
    }
  }
  return Phi;
}

Eigen::Matrix<double, 9, 1> PaperGammaPos(double g, double t) {
  Eigen::Matrix<double, 9, 1> u = Eigen::Matrix<double, 9, 1>::Zero();
  u(IP(2)) = -g * t * t / 2.0;
  u(IV(2)) = -g * t;
  return u;
}

PositionKfSettings AccelerometerDrivenSettings() {
  PositionKfSettings s;
  s.motion_model = MotionModel::kAccelerometerDriven;
  s.accel_bias_walk = 0.1;
  s.accel_sigma = 0.1;
  s.accel_noise_adaptation_tau = 0.1;
  return s;
}

PositionKf::PositionKf(const PositionKfSettings& settings) : settings_(settings) {
  if (!(settings_.accel_delay >= 0.0 && settings_.accel_delay <= kMaxAccelDelay)) {
    std::ostringstream o;
    o << "position_kf: accel_delay must be a time in [0, " << kMaxAccelDelay << "] s, got "
      << settings_.accel_delay;
    throw std::invalid_argument(o.str());
  }
  Reset();
}

void PositionKf::Reset() {
  initialized_ = false;
  t_ = 0.0;
  x_.setZero();
  P_.setIdentity();
  const std::int64_t resets = counters_.resets;
  counters_ = {};
  counters_.resets = resets;
  last_position_nis_ = 0.0;
  last_position_log_likelihood_ = 0.0;
  last_position_accepted_ = false;
  consecutive_rejections_ = 0;
  accel_noise_scale_ = 1.0;
  last_position_t_ = 0.0;
  has_last_omega_ = false;
  last_omega_B_.setZero();
  has_last_z_ = false;
  last_z_.setZero();
  rollback_.clear();
}

Eigen::Vector3d PositionKf::p_WM_W() const {
  return {x_(IP(0)), x_(IP(1)), x_(IP(2))};
}
Eigen::Vector3d PositionKf::v_W() const {
  return {x_(IV(0)), x_(IV(1)), x_(IV(2))};
}
Eigen::Vector3d PositionKf::a_W() const {
  return {x_(IA(0)), x_(IA(1)), x_(IA(2))};
}

Eigen::Matrix3d PositionKf::position_covariance() const {
  Eigen::Matrix3d C;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) C(i, j) = P_(IP(i), IP(j));
  return C;
}

Eigen::Matrix<double, 6, 6> PositionKf::position_velocity_covariance() const {
  const int idx[6] = {IP(0), IP(1), IP(2), IV(0), IV(1), IV(2)};
  Eigen::Matrix<double, 6, 6> C;
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) C(r, c) = P_(idx[r], idx[c]);
  return C;
}

Eigen::Vector3d PositionKf::WorldAcceleration(const Eigen::Vector3d& f_B,
                                              const Eigen::Matrix3d& R_EB) const {
  // Gravity leaves in E, before the turn into W (header comment).
  return R_WE_ * (R_EB * f_B - settings_.gravity * UpVector(settings_.earth));
}

Status PositionKf::SetWorldFromEarth(const Eigen::Matrix3d& R_WE,
                                     const Eigen::Matrix3d& covariance) {
  const bool rotation = detail::IsRotation(R_WE);
  const bool cov_ok = detail::IsCovariance(covariance);
  if (rotation && cov_ok) {
    R_WE_ = R_WE;
    R_WE_covariance_ = covariance;
    return Status::Ok();
  }
  ++counters_.input_rejected;
  if (!rotation)
    return Status::Error(R_WE.allFinite() ? "position_kf: R_WE is not a rotation"
                                          : "position_kf: R_WE is not finite");
  return Status::Error(
      "position_kf: R_WE's covariance is not finite, not symmetric or has a negative variance");
}

Status PositionKf::Check(double t, const Eigen::Vector3d& v, const char* name) {
  std::string why;
  if (!std::isfinite(t))
    why = "time t is not finite";
  else if (!v.allFinite())
    why = std::string(name) + " is not finite";
  else if (initialized_ && t < t_) {
    std::ostringstream o;
    o.precision(17);
    o << "time t = " << t << " s is before the last update (" << t_ << " s)";
    why = o.str();
  }
  if (why.empty()) return Status::Ok();
  ++counters_.input_rejected;
  return Status::Error("position_kf: " + why);
}

void PositionKf::PredictTo(double t) {
  const double dt = t - t_;
  t_ = t;
  if (dt > 0.0) Predict(x_, P_, dt);
}

void PositionKf::Predict(VecN& x, MatN& P, double dt, bool hold_acceleration) const {
  Eigen::Matrix3d Phi_axis;
  Phi_axis << 1, dt, dt * dt / 2, 0, 1, dt, 0, 0, 1;
  const double qj = settings_.jerk_noise * settings_.jerk_noise;
  const double dt2 = dt * dt, dt3 = dt2 * dt, dt4 = dt3 * dt, dt5 = dt4 * dt;
  Eigen::Matrix3d Q_axis = Eigen::Matrix3d::Zero();
  if (settings_.motion_model == MotionModel::kWhiteJerk)
    Q_axis << dt5 / 20, dt4 / 8, dt3 / 6, dt4 / 8, dt3 / 3, dt2 / 2, dt3 / 6, dt2 / 2, dt;
  else if (!hold_acceleration) {
    // A's ramp over the step, and p's and V's shares of it (header comment).
    const Eigen::Vector3d g(dt2 / 6, dt / 2, 1.0);
    Q_axis = dt * g * g.transpose();
  }
  Q_axis *= qj * accel_noise_scale_;              // λ: the adaptive noise (header comment)
  MatN Phi = MatN::Identity(), Q = MatN::Zero();  // r_B constant, b_W a random walk
  for (int i = 0; i < 3; ++i) {
    Phi.block<3, 3>(3 * i, 3 * i) = Phi_axis;
    Q.block<3, 3>(3 * i, 3 * i) = Q_axis;
  }
  Q.block<3, 3>(kBias, kBias)
      .diagonal()
      .setConstant(settings_.accel_bias_walk * settings_.accel_bias_walk * dt);
  x = Phi * x;
  P = Phi * P * Phi.transpose() + Q;
  P = 0.5 * (P + P.transpose());
}

PositionKf::PositionInnovation PositionKf::Innovation(const VecN& x, const MatN& P,
                                                      const Eigen::Vector3d& p) const {
  PositionInnovation in;
  in.y = p - Eigen::Vector3d(x(IP(0)), x(IP(1)), x(IP(2)));
  Eigen::Matrix3d S;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) S(i, j) = P(IP(i), IP(j));
  S.diagonal().array() += settings_.position_sigma * settings_.position_sigma;
  in.S_inv = S.inverse();
  in.nis = in.y.dot(in.S_inv * in.y);
  // ln N(y; 0, S) = −½ (NIS + ln det S + 3 ln 2π): the sample's evidence for this filter's model.
  in.log_likelihood =
      -0.5 * (in.nis + std::log(S.determinant()) + 3.0 * std::log(2.0 * std::numbers::pi));
  return in;
}

void PositionKf::ApplyPosition(VecN& x, MatN& P, const PositionInnovation& in) const {
  // H selects p; K = P Hᵀ S⁻¹; Joseph form with R = σ_p² I.
  Eigen::Matrix<double, 3, kN> H = Eigen::Matrix<double, 3, kN>::Zero();
  for (int i = 0; i < 3; ++i) H(i, IP(i)) = 1.0;
  const Eigen::Matrix<double, kN, 3> K = P * H.transpose() * in.S_inv;
  x += K * in.y;
  const MatN IKH = MatN::Identity() - K * H;
  P = IKH * P * IKH.transpose() +
      settings_.position_sigma * settings_.position_sigma * K * K.transpose();
  P = 0.5 * (P + P.transpose());
}

int PositionKf::kept_accel_samples() const {
  int n = 0;
  for (const RollbackPoint& point : rollback_) n += static_cast<int>(point.accel.size());
  return n;
}

double PositionKf::RollbackReach() const {
  // A sample exactly one span back is within it whatever the rounding of its time stamp.
  return settings_.accel_rollback_span * (1.0 + 1e-9) + 1e-9;
}

void PositionKf::KeepRollbackPoint(const Eigen::Vector3d& p) {
  if (!(settings_.accel_rollback_span > 0.0)) return;
  rollback_.push_back({t_, p, x_, P_, {}});
  // Points older than the span can start no hypothesis once a newer one is there.
  while (rollback_.size() > 1 && (static_cast<int>(rollback_.size()) > kMaxRollbackPoints ||
                                  t_ - rollback_.front().t > RollbackReach()))
    rollback_.erase(rollback_.begin());
}

void PositionKf::RollBackAccelerometer(double t, const Eigen::Vector3d& p, PositionInnovation& in) {
  if (!(settings_.position_gate_chi2 > 0.0)) return;
  // A hypothesis must make this sample likelier by e^{gate/2}; none can make it likelier than
  // N(0; 0, R) (NIS 0, S = R), so while that bound is within the margin, none is tried.
  const double r = settings_.position_sigma * settings_.position_sigma;
  const double ll_bound = -1.5 * std::log(2.0 * std::numbers::pi * r);
  double best_ll = in.log_likelihood + 0.5 * settings_.position_gate_chi2;
  if (best_ll >= ll_bound) return;
  const int points = static_cast<int>(rollback_.size());
  // The best hypothesis: the point it starts from, whether it reinstates the refused samples
  // (else it takes back the applied ones), how many, and its re-run (the state after each point).
  int best = -1, best_count = 0;
  bool best_reinstates = false;
  std::vector<std::pair<VecN, MatN>> best_states, states;
  VecN best_x;
  MatN best_P;
  int applied = 0, not_applied = 0;  // accelerometer samples after point i
  bool complete = true;              // every one of them kept
  // The accelerometer-driven model's take-back hypotheses hold A (header comment).
  const bool hold = settings_.motion_model == MotionModel::kAccelerometerDriven;
  for (int i = points - 1; i >= 0; --i) {
    if (i < points - 1 && t - rollback_[i].t > RollbackReach()) break;
    int refused_here = 0;  // samples of this interval the gate refused, not since reinstated
    for (const AccelSample& a : rollback_[i].accel) {
      ++(a.applied ? applied : not_applied);
      if (a.gated && !a.applied) ++refused_here;
    }
    applied += rollback_[i].applied_not_kept;
    complete = complete && rollback_[i].complete;
    for (const bool reinstate : {false, true}) {
      const int count = reinstate ? not_applied : applied;
      // Nothing to take back, or to reinstate. A reinstatement starts where the gate refused a
      // sample: the gate may have been wrong from there on, and every sample since is applied,
      // taken back or not (a tap the positions showed as one, then a motion they show was real).
      // Where the gate refused nothing, none is tried: the take-back's alone are the positions'
      // own decisions (and a position filter without the accelerometer's gate pays nothing). It
      // needs every sample since kept.
      if (count == 0 || (reinstate && (refused_here == 0 || !complete))) continue;
      // From point i on: the motion model alone, or with every accelerometer sample; the later
      // position samples re-applied behind the gate.
      const bool hold_here = hold && !reinstate;
      VecN x = rollback_[i].x;
      MatN P = rollback_[i].P;
      double t_x = rollback_[i].t;
      states.clear();
      for (int m = i; m < points; ++m) {
        if (m > i) {
          if (rollback_[m].t > t_x) Predict(x, P, rollback_[m].t - t_x, hold_here);
          t_x = rollback_[m].t;
          const PositionInnovation im = Innovation(x, P, rollback_[m].p_WM_W);
          if (!(im.nis > settings_.position_gate_chi2)) ApplyPosition(x, P, im);
        }
        states.emplace_back(x, P);
        if (!reinstate) continue;
        for (const AccelSample& a : rollback_[m].accel) {
          if (a.t > t_x) Predict(x, P, a.t - t_x);
          t_x = std::max(t_x, a.t);
          const Eigen::Vector3d y = a.z - a.H * x;
          ApplyAccel(x, P, a, y, (a.H * P * a.H.transpose() + a.R).inverse());
        }
      }
      if (t > t_x) Predict(x, P, t - t_x, hold_here);
      const PositionInnovation alt = Innovation(x, P, p);
      if (alt.log_likelihood > best_ll) {
        best_ll = alt.log_likelihood;
        best = i;
        best_count = count;
        best_reinstates = reinstate;
        in = alt;
        best_states.swap(states);
        best_x = x;
        best_P = P;
      }
    }
  }
  if (best < 0) return;
  x_ = best_x;
  P_ = best_P;
  // The kept points are the re-run's: a later hypothesis starts from states with the
  // accelerometer as this one took it, and may reverse it.
  for (int m = best; m < points; ++m) {
    rollback_[m].x = best_states[m - best].first;
    rollback_[m].P = best_states[m - best].second;
    for (AccelSample& a : rollback_[m].accel) a.applied = best_reinstates;
    rollback_[m].applied_not_kept = 0;  // taken back with the kept ones (a take-back)
  }
  if (best_reinstates) {
    ++counters_.accel_reinstatements;
    counters_.accel_reinstated += best_count;
  } else {
    ++counters_.accel_rollbacks;
    counters_.accel_rolled_back += best_count;
  }
}

void PositionKf::Initialise(double t, const Eigen::Vector3d& p) {
  // The lever arm and the bias learned so far survive a re-initialisation of the position (the
  // bias keeps its σ: it has walked for no longer than the rejections lasted).
  const bool learned = initialized_ || counters_.position_samples > 0;
  const double s_r = settings_.estimate_lever_arm ? settings_.lever_arm_sigma : 0.0;
  const double s_b = settings_.accel_bias_walk > 0.0 ? settings_.initial_accel_bias_sigma : 0.0;
  const Eigen::Matrix<double, 6, 1> r_b =
      learned ? Eigen::Matrix<double, 6, 1>(x_.tail<6>())
              : (Eigen::Matrix<double, 6, 1>() << settings_.lever_arm_B, Eigen::Vector3d::Zero())
                    .finished();
  Eigen::Matrix<double, 6, 6> P_rb = Eigen::Matrix<double, 6, 6>::Zero();
  if (learned) {
    P_rb = P_.bottomRightCorner<6, 6>();
  } else {
    P_rb.topLeftCorner<3, 3>().diagonal().setConstant(s_r * s_r);
    P_rb.bottomRightCorner<3, 3>().diagonal().setConstant(s_b * s_b);
  }
  x_.setZero();
  P_.setZero();
  x_.tail<6>() = r_b;
  P_.bottomRightCorner<6, 6>() = P_rb;
  for (int i = 0; i < 3; ++i) {
    x_(IP(i)) = p(i);
    P_(IP(i), IP(i)) = settings_.position_sigma * settings_.position_sigma;
    P_(IV(i), IV(i)) = settings_.initial_velocity_sigma * settings_.initial_velocity_sigma;
    P_(IA(i), IA(i)) = settings_.initial_accel_sigma * settings_.initial_accel_sigma;
  }
  t_ = t;
  initialized_ = true;
  consecutive_rejections_ = 0;
}

Status PositionKf::UpdateAccel(double t, const Eigen::Vector3d& f_B, const Eigen::Matrix3d& R_EB,
                               const Eigen::Vector3d& omega_B) {
  if (auto s = Check(t, f_B, "accelerometer f_B"); !s) return s;
  if (auto s = Check(t, omega_B, "body rate omega_B"); !s) return s;
  if (!R_EB.allFinite()) {
    ++counters_.input_rejected;
    return Status::Error("position_kf: orientation R_EB is not finite");
  }
  // α_B by differencing the rate between accelerometer updates (zero for the first).
  const double dt = t - last_omega_t_;
  const Eigen::Vector3d alpha_B = has_last_omega_ && dt > 0.0
                                      ? Eigen::Vector3d((omega_B - last_omega_B_) / dt)
                                      : Eigen::Vector3d::Zero();
  last_omega_B_ = omega_B;
  last_omega_t_ = t;
  has_last_omega_ = true;
  // The accelerometer's lag (header comment): z(t − δ) with the attitude of then, extrapolated
  // to t along the previous sample's; κ weighs the noise.
  Eigen::Vector3d z = WorldAcceleration(f_B, R_EB);
  double kappa = 0.0;
  if (const double delay = settings_.accel_delay; delay > 0.0) {
    const Eigen::Vector3d z_then = WorldAcceleration(geometry::Exp(-delay * omega_B) * f_B, R_EB);
    const double step = t - last_z_t_;
    if (has_last_z_ && step > 0.0 && step <= kMaxAccelExtrapolationStep) kappa = delay / step;
    z = z_then + kappa * (z_then - last_z_);
    last_z_ = z_then;
    last_z_t_ = t;
    has_last_z_ = true;
  }
  if (!initialized_) return Status::Ok();
  PredictTo(t);
  // h = A − R_WB M r_B + b_W, R_WB = R_WE R_EB, M = [α]× + [ω]×² (header comment).
  const Eigen::Matrix3d W = geometry::Skew(omega_B);
  const Eigen::Matrix3d M = geometry::Skew(alpha_B) + W * W;
  AccelSample a;
  a.t = t;
  a.z = z;
  for (int i = 0; i < 3; ++i) a.H(i, IA(i)) = 1.0;
  a.H.middleCols<3>(kLever) = -(R_WE_ * R_EB) * M;
  if (settings_.accel_bias_walk > 0.0) a.H.middleCols<3>(kBias).setIdentity();
  // σ² + (σ_rel |a_W|)², times the adaptive λ (header comment).
  const double s_rel = settings_.accel_relative_sigma * z.norm();
  const double extrapolation = (1.0 + kappa) * (1.0 + kappa) + kappa * kappa;  // 1 when δ = 0
  a.R = accel_noise_scale_ * extrapolation *
        (settings_.accel_sigma * settings_.accel_sigma + s_rel * s_rel) *
        Eigen::Matrix3d::Identity();
  if (!R_WE_covariance_.isZero()) {
    // The frame's uncertainty (SetWorldFromEarth): ∂(Exp(δφ) z)/∂δφ = −[z]×.
    const Eigen::Matrix3d Z = geometry::Skew(z);
    a.R += Z * R_WE_covariance_ * Z.transpose();
  }
  const Eigen::Vector3d y = z - a.H * x_;
  const Eigen::Matrix3d S_inv = (a.H * P_ * a.H.transpose() + a.R).inverse();
  a.gated = settings_.accel_gate_chi2 > 0.0 && !(y.dot(S_inv * y) <= settings_.accel_gate_chi2);
  a.applied = !a.gated;
  // Kept, applied or not, for the rollback's hypotheses (header comment).
  if (!rollback_.empty()) {
    RollbackPoint& last = rollback_.back();
    if (static_cast<int>(last.accel.size()) < kMaxKeptAccelSamples) {
      last.accel.push_back(a);
    } else {
      last.complete = false;
      last.applied_not_kept += a.applied ? 1 : 0;
    }
  }
  if (!a.applied) {
    ++counters_.accel_rejected;
    has_last_z_ = false;   // nor is the next sample extrapolated along a refused one
    return GuardState(t);  // the prediction to t stands
  }
  ApplyAccel(x_, P_, a, y, S_inv);
  ++counters_.accel_samples;
  return GuardState(t);
}

void PositionKf::ApplyAccel(VecN& x, MatN& P, const AccelSample& a, const Eigen::Vector3d& y,
                            const Eigen::Matrix3d& S_inv) const {
  const Eigen::Matrix<double, kN, 3> K = P * a.H.transpose() * S_inv;
  x += K * y;
  const MatN IKH = MatN::Identity() - K * a.H;
  P = IKH * P * IKH.transpose() + K * a.R * K.transpose();
}

Status PositionKf::GuardState(double t) {
  if (x_.allFinite() && P_.allFinite()) return Status::Ok();
  // Never keep (or publish) a NaN state: initialise again at the next position sample.
  Reset();
  ++counters_.resets;
  std::ostringstream o;
  o.precision(17);
  o << "position_kf: state went non-finite at t = " << t << " s; filter reset (" << counters_.resets
    << " so far)";
  return Status::Error(o.str());
}

void PositionKf::AdaptAccelNoise(double t) {
  const double dt = t - last_position_t_;
  last_position_t_ = t;
  if (settings_.accel_noise_adaptation_tau <= 0.0 || !std::isfinite(last_position_nis_)) return;
  // log λ ← log λ + a (min(NIS, 30)/3 − 1), a = Δt/τ ≤ 1 (header comment). Evaluated in the
  // linear domain; the clamp keeps λ finite whatever the innovation was.
  constexpr double kDof = 3.0, kNisCap = 30.0;
  const double a = std::min(1.0, dt / settings_.accel_noise_adaptation_tau);
  const double excess = std::min(last_position_nis_, kNisCap) / kDof - 1.0;
  accel_noise_scale_ = std::clamp(accel_noise_scale_ * std::exp(a * excess), 1.0,
                                  std::max(1.0, settings_.accel_noise_max_scale));
}

void PositionKf::InitialiseOn(double t, const Eigen::Vector3d& p_WM_W,
                              const std::optional<PositionSample>& previous) {
  Initialise(t, p_WM_W);
  if (previous && t > previous->t) {
    // The mean velocity over the interval, as uncertain as it is large (header comment).
    const double dt = t - previous->t;
    const Eigen::Vector3d v_W = (p_WM_W - previous->p_WM_W) / dt;
    const double s_p = settings_.position_sigma, s_v0 = settings_.initial_velocity_sigma;
    for (int i = 0; i < 3; ++i) {
      x_(IV(i)) = v_W(i);
      P_(IV(i), IV(i)) = 2.0 * s_p * s_p / (dt * dt) + s_v0 * s_v0 + v_W(i) * v_W(i);
    }
  }
  rollback_.clear();  // no hypothesis reaches back past a (re-)initialisation
  last_position_t_ = t;
  last_position_log_likelihood_ = 0.0;
  ++counters_.position_samples;
  last_position_accepted_ = true;
  last_position_nis_ = 0.0;
  KeepRollbackPoint(p_WM_W);
}

Status PositionKf::UpdatePosition(double t, const Eigen::Vector3d& p_WM_W) {
  if (auto s = Check(t, p_WM_W, "position p_WM_W"); !s) return s;
  if (!initialized_) {
    InitialiseOn(t, p_WM_W);
    return Status::Ok();
  }
  PredictTo(t);
  PositionInnovation in = Innovation(x_, P_, p_WM_W);
  if (settings_.accel_rollback_span > 0.0) RollBackAccelerometer(t, p_WM_W, in);
  last_position_nis_ = in.nis;
  last_position_log_likelihood_ = in.log_likelihood;
  AdaptAccelNoise(t);
  if (settings_.position_gate_chi2 > 0.0 && last_position_nis_ > settings_.position_gate_chi2) {
    if (settings_.accel_noise_adaptation_tau > 0.0 && settings_.accel_noise_max_scale > 1.0 &&
        accel_noise_scale_ >= settings_.accel_noise_max_scale) {
      // The adaptation has given up on the prediction (λ at its cap: the noise the innovations
      // ask for is beyond what it may take), so it is no reference by which to call a sample an
      // outlier: the sample re-initialises the position at once. (In violent shaking the
      // accelerometer-driven model ran metres off while one sample in four still passed the gate,
      // which kept the count of consecutive rejections from ever reaching its limit.)
      ++counters_.reinitialised;
      std::optional<PositionSample> previous;
      if (!rollback_.empty())
        previous = PositionSample{rollback_.back().t, rollback_.back().p_WM_W};
      InitialiseOn(t, p_WM_W, previous);
      return Status::Ok();
    }
    ++counters_.position_rejected;
    last_position_accepted_ = false;
    KeepRollbackPoint(p_WM_W);
    if (settings_.max_consecutive_rejections > 0 &&
        ++consecutive_rejections_ >= settings_.max_consecutive_rejections) {
      // The sensor keeps disagreeing: trust it again from the next sample on.
      initialized_ = false;
      ++counters_.reinitialised;
    }
    return Status::Ok();
  }
  consecutive_rejections_ = 0;
  ApplyPosition(x_, P_, in);
  ++counters_.position_samples;
  last_position_accepted_ = true;
  KeepRollbackPoint(p_WM_W);
  return GuardState(t);
}

}  // namespace rcal::estimation
