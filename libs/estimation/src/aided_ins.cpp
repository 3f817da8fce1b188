#include "rcal/estimation/aided_ins.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

#include "frame_checks.hpp"
#include "number_text.hpp"
#include "rcal/geometry/so3.hpp"

namespace rcal::estimation {
namespace {

using geometry::Exp;
using geometry::Log;
using geometry::Skew;
using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

// Error-state blocks (header comment's order).
constexpr int kTheta = 0, kVel = 3, kPos = 6, kBg = 9, kBa = 12, kLever = 15, kFrame = 18;
constexpr int kN = kAidedInsStates;

using detail::Num;

bool WithinRange(const Vec3& v, double range) {
  return v.allFinite() && v.cwiseAbs().maxCoeff() <= range;
}

}  // namespace

AidedInsState Boxplus(const AidedInsState& x, const AidedInsVector& dx) {
  AidedInsState y = x;
  y.R_EB = Exp(dx.segment<3>(kTheta)) * x.R_EB;
  y.v_EB_E += dx.segment<3>(kVel);
  y.p_EB_E += dx.segment<3>(kPos);
  y.b_g_B += dx.segment<3>(kBg);
  y.b_a_B += dx.segment<3>(kBa);
  y.r_BM_B += dx.segment<3>(kLever);
  y.R_WE = Exp(dx.segment<3>(kFrame)) * x.R_WE;
  return y;
}

AidedInsVector Boxminus(const AidedInsState& y, const AidedInsState& x) {
  AidedInsVector d;
  d.segment<3>(kTheta) = Log(y.R_EB * x.R_EB.transpose());
  d.segment<3>(kVel) = y.v_EB_E - x.v_EB_E;
  d.segment<3>(kPos) = y.p_EB_E - x.p_EB_E;
  d.segment<3>(kBg) = y.b_g_B - x.b_g_B;
  d.segment<3>(kBa) = y.b_a_B - x.b_a_B;
  d.segment<3>(kLever) = y.r_BM_B - x.r_BM_B;
  d.segment<3>(kFrame) = Log(y.R_WE * x.R_WE.transpose());
  return d;
}

namespace {

// One IMU step given its rotation R_k = R_{k−1} Exp(ω Δt) (ω Δt = w_dt), formed once per sample
// for the state, its transition and the accelerometer's lag.
AidedInsState PropagateWith(const AidedInsState& x, const Mat3& R_k, const Vec3& f_prev_B,
                            const Vec3& f_B, const Vec3& g_E, double dt) {
  AidedInsState y = x;
  y.R_EB = R_k;
  // The trapezoid of the specific force turned into E at both ends of the step.
  const Vec3 a_E = 0.5 * (x.R_EB * (f_prev_B - x.b_a_B) + R_k * (f_B - x.b_a_B)) + g_E;
  y.p_EB_E = x.p_EB_E + x.v_EB_E * dt + 0.5 * a_E * dt * dt;
  y.v_EB_E = x.v_EB_E + a_E * dt;
  return y;
}

AidedInsMatrix TransitionWith(const AidedInsState& x, const Mat3& R_k, const Vec3& w_dt,
                              const Vec3& f_prev_B, const Vec3& f_B, double dt) {
  const Mat3 R_mean = 0.5 * (x.R_EB + R_k);
  const Vec3 f_corr_B = f_B - x.b_a_B;
  const Vec3 f_E = 0.5 * (x.R_EB * (f_prev_B - x.b_a_B) + R_k * f_corr_B);
  // R_k' = Exp(δθ) R_k Exp(−J_r(ωΔt) Δt δb_g): the bias turns R_k on the right.
  const Mat3 dRk_dbg = -R_k * geometry::RightJacobian(w_dt) * dt;  // δθ_k per δb_g
  // δa_E = −[f_E]× δθ − R̄ δb_a + ½ R_k [f_B − b_a]× J_r Δt δb_g  (R_k's part of the mean).
  AidedInsRow3 da = AidedInsRow3::Zero();
  da.block<3, 3>(0, kTheta) = -Skew(f_E);
  da.block<3, 3>(0, kBa) = -R_mean;
  da.block<3, 3>(0, kBg) = -0.5 * Skew(R_k * f_corr_B) * dRk_dbg;
  AidedInsMatrix F = AidedInsMatrix::Identity();
  F.block<3, 3>(kTheta, kBg) = dRk_dbg;
  F.block<3, kN>(kVel, 0) += da * dt;
  F.block<3, 3>(kPos, kVel) = Mat3::Identity() * dt;
  F.block<3, kN>(kPos, 0) += da * (0.5 * dt * dt);
  return F;
}

}  // namespace

AidedInsState PropagateAidedIns(const AidedInsState& x, const Vec3& gyro_B, const Vec3& f_prev_B,
                                const Vec3& f_B, const Vec3& g_E, double dt) {
  return PropagateWith(x, x.R_EB * Exp((gyro_B - x.b_g_B) * dt), f_prev_B, f_B, g_E, dt);
}

AidedInsMatrix AidedInsTransition(const AidedInsState& x, const Vec3& gyro_B, const Vec3& f_prev_B,
                                  const Vec3& f_B, double dt) {
  const Vec3 w_dt = (gyro_B - x.b_g_B) * dt;
  return TransitionWith(x, x.R_EB * Exp(w_dt), w_dt, f_prev_B, f_B, dt);
}

Vec3 MarkerPosition(const AidedInsState& x) {
  return x.p_EB_E + x.R_EB * x.r_BM_B;
}

Vec3 TrackerPosition(const AidedInsState& x) {
  return x.R_WE * MarkerPosition(x);
}

Vec3 TrackerVelocity(const AidedInsState& x, const Vec3& omega_B) {
  return x.R_WE * (x.v_EB_E + x.R_EB * omega_B.cross(x.r_BM_B));
}

AidedInsRow3 TrackerVelocityJacobian(const AidedInsState& x, const Vec3& omega_B) {
  // u = R_EB (ω × r): δθ → −[u]×, δr → R_EB [ω]×, δb_g → R_EB [r]× (ω = ω_m − b_g); δv → R_WE;
  // δφ → −[R_WE (v + u)]×.
  const Vec3 u_E = x.R_EB * omega_B.cross(x.r_BM_B);
  AidedInsRow3 J = AidedInsRow3::Zero();
  J.block<3, 3>(0, kTheta) = -x.R_WE * Skew(u_E);
  J.block<3, 3>(0, kVel) = x.R_WE;
  J.block<3, 3>(0, kBg) = x.R_WE * x.R_EB * Skew(x.r_BM_B);
  J.block<3, 3>(0, kLever) = x.R_WE * x.R_EB * Skew(omega_B);
  J.block<3, 3>(0, kFrame) = -Skew(x.R_WE * (x.v_EB_E + u_E));
  return J;
}

Vec3 TrackerPositionBefore(const AidedInsState& x, double tau, const Vec3& omega_B,
                           const Vec3& a_E) {
  const Mat3 R_then = x.R_EB * Exp(-tau * omega_B);
  return x.R_WE * (x.p_EB_E - tau * x.v_EB_E + 0.5 * tau * tau * a_E + R_then * x.r_BM_B);
}

AidedInsRow3 TrackerPositionBeforeJacobian(const AidedInsState& x, double tau, const Vec3& omega_B,
                                           const Vec3& a_E) {
  // As TrackerPositionJacobian with R_then = R_EB Exp(−ω τ) (δθ on the left turns it as R_EB),
  // and −τ R_WE on δv.
  AidedInsState then = x;
  then.R_EB = x.R_EB * Exp(-tau * omega_B);
  AidedInsRow3 H = TrackerPositionJacobian(then);
  H.block<3, 3>(0, kVel) = -tau * x.R_WE;
  // δφ turns the whole of h, which is the marker then.
  H.block<3, 3>(0, kFrame) = -Skew(TrackerPositionBefore(x, tau, omega_B, a_E));
  return H;
}

AidedInsRow3 TrackerPositionJacobian(const AidedInsState& x) {
  // h = R_WE (p + R_EB r): δp → R_WE, δθ → −R_WE [R r]×, δr → R_WE R, δφ → −[h]×.
  AidedInsRow3 H = AidedInsRow3::Zero();
  H.block<3, 3>(0, kTheta) = -x.R_WE * Skew(x.R_EB * x.r_BM_B);
  H.block<3, 3>(0, kPos) = x.R_WE;
  H.block<3, 3>(0, kLever) = x.R_WE * x.R_EB;
  H.block<3, 3>(0, kFrame) = -Skew(TrackerPosition(x));
  return H;
}

AidedIns::AidedIns(const AidedInsSettings& settings) : settings_(settings) {
  const AidedInsSettings& s = settings_;
  // Each setting's domain, named in the error: a NaN, a negative σ or a zero time is refused.
  const auto require = [](bool ok, const char* name, double v, const char* domain) {
    if (!ok)
      throw std::invalid_argument(std::string("aided_ins: ") + name + " must be " + domain +
                                  ", got " + Num(v));
  };
  for (const auto& [name, v] : {std::pair{"gravity", s.gravity},
                                {"position_sigma", s.position_sigma},
                                {"heading_sigma", s.heading_sigma},
                                {"mag_heading_sigma", s.mag_heading_sigma},
                                {"initial_attitude_sigma", s.initial_attitude_sigma},
                                {"initial_velocity_sigma", s.initial_velocity_sigma},
                                {"initial_gyro_bias_sigma", s.initial_gyro_bias_sigma},
                                {"initial_accel_bias_sigma", s.initial_accel_bias_sigma},
                                {"gyro_range", s.gyro_range},
                                {"accel_range", s.accel_range},
                                {"max_step", s.max_step}})
    require(std::isfinite(v) && v > 0.0, name, v, "finite and positive");
  for (const auto& [name, v] : {std::pair{"gyro_noise_density", s.gyro_noise_density},
                                {"attitude_process_noise", s.attitude_process_noise},
                                {"accel_noise_density", s.accel_noise_density},
                                {"gyro_bias_random_walk", s.gyro_bias_random_walk},
                                {"accel_bias_random_walk", s.accel_bias_random_walk},
                                {"lever_arm_sigma", s.lever_arm_sigma},
                                {"position_gate_chi2", s.position_gate_chi2},
                                {"accel_noise_adaptation_tau", s.accel_noise_adaptation_tau},
                                {"accel_shock_sigma", s.accel_shock_sigma},
                                {"accel_change_sigma", s.accel_change_sigma}})
    require(std::isfinite(v) && v >= 0.0, name, v, "finite and ≥ 0");
  require(s.accel_delay >= 0.0 && s.accel_delay <= kMaxAccelDelay, "accel_delay [s]", s.accel_delay,
          "in [0, kMaxAccelDelay = 0.05] s");
  require(std::isfinite(s.accel_noise_max_scale) && s.accel_noise_max_scale >= 1.0,
          "accel_noise_max_scale", s.accel_noise_max_scale, "finite and ≥ 1");
  require(s.max_consecutive_rejections >= 0, "max_consecutive_rejections",
          s.max_consecutive_rejections, "≥ 0");
  require(s.lever_arm_B.allFinite(), "lever_arm_B", s.lever_arm_B.norm(), "finite");
  g_E_ = -settings_.gravity * UpVector(settings_.earth);
  Reset();
}

void AidedIns::Reset() {
  initialized_ = false;
  has_time_ = false;
  has_attitude_ = has_position_ = false;
  t_ = 0.0;
  x_ = AidedInsState{};
  q_EB_ = Eigen::Vector4d(1, 0, 0, 0);
  P_.setIdentity();
  last_position_nis_ = 0.0;
  consecutive_rejections_ = 0;
  shock_covariance_.setZero();
  accel_noise_scale_ = 1.0;
  has_last_position_t_ = false;
  step_dt_ = 0.0;
  step_omega_B_.setZero();
  step_a_E_.setZero();
  const std::int64_t resets = counters_.resets;
  counters_ = {};
  counters_.resets = resets;
}

void AidedIns::ResetKeepingTime() {
  const double t = t_;
  const bool has_time = has_time_;
  Reset();
  t_ = t;
  has_time_ = has_time;
}

Status AidedIns::Refuse(const std::string& why) {
  ++counters_.input_rejected;
  return Status::Error("aided_ins: " + why);
}

Status AidedIns::UpdateImu(double t, const Vec3& gyro_B, const Vec3& f_B) {
  if (!std::isfinite(t)) return Refuse("t is not finite");
  if (has_time_ && !(t > t_))
    return Refuse("t = " + Num(t) + " s does not follow the last sample's " + Num(t_) + " s");
  if (!WithinRange(gyro_B, settings_.gyro_range))
    return Refuse("gyro_B is not finite or beyond ±" + Num(settings_.gyro_range) + " rad/s");
  if (!WithinRange(f_B, settings_.accel_range))
    return Refuse("f_B is not finite or beyond ±" + Num(settings_.accel_range) + " m/s²");
  const double dt = has_time_ ? t - t_ : 0.0;
  t_ = t;
  has_time_ = true;
  // The step's rotation, once: for the lag's extrapolation, the state and its transition.
  const Vec3 w_dt = (gyro_B - x_.b_g_B) * dt;
  const Mat3 step = Exp(w_dt);
  // The accelerometer's lag (settings): the sample is the specific force of t − δ in the body of
  // then, Exp(−δω) f_B in the body's axes now; extrapolated to t along the previous one (turned
  // into the same axes by the step's rotation, Exp(ωΔt)ᵀ).
  Vec3 f_now_B = f_B;
  if (const double delay = settings_.accel_delay; delay > 0.0) {
    const Vec3 f_then_B = Exp(-delay * (gyro_B - x_.b_g_B)) * f_B;
    if (initialized_ && dt > 0.0 && dt <= settings_.max_step)
      f_now_B = f_then_B + (delay / dt) * (f_then_B - step.transpose() * f_then_B_);
    else
      f_now_B = f_then_B;
    f_then_B_ = f_then_B;
  }
  // The step a position within it is taken back along (before initialisation, and over a gap, a
  // position only starts the filter: nothing is taken back).
  const auto record_step = [&](const Vec3& omega_B, const Vec3& a_E) {
    step_dt_ = dt;
    step_omega_B_ = omega_B;
    step_a_E_ = a_E;
  };
  if (!initialized_) {
    f_prev_B_ = f_now_B;
    record_step(Vec3::Zero(), Vec3::Zero());
    return Status::Ok();
  }
  if (dt > settings_.max_step) {
    // The strapdown integral over a gap is no estimate: start again from the next sources.
    const std::int64_t reinitialised = counters_.reinitialised + 1;
    ResetKeepingTime();
    counters_.reinitialised = reinitialised;
    record_step(Vec3::Zero(), Vec3::Zero());
    return Status::Ok();
  }
  const Mat3 R_k = x_.R_EB * step;
  record_step(gyro_B - x_.b_g_B,
              0.5 * (x_.R_EB * (f_prev_B_ - x_.b_a_B) + R_k * (f_now_B - x_.b_a_B)) + g_E_);
  // The force's change across the step in E: the shock hypothesis's and the motion weighting's
  // measure of what the trapezoid may have missed (settings).
  const double force_change =
      (R_k * (f_now_B - x_.b_a_B) - x_.R_EB * (f_prev_B_ - x_.b_a_B)).norm();
  // The shock hypothesis (settings): that change as a velocity error; the earlier ones carried
  // along δp_k = δp + Δt δv.
  if (const double kappa = settings_.accel_shock_sigma; kappa > 0.0) {
    Eigen::Matrix2d F2;
    F2 << 1.0, dt, 0.0, 1.0;
    shock_covariance_ = F2 * shock_covariance_ * F2.transpose();
    shock_covariance_(1, 1) += std::pow(kappa * force_change * dt, 2);
  }
  const AidedInsMatrix F = TransitionWith(x_, R_k, w_dt, f_prev_B_, f_now_B, dt);
  x_ = PropagateWith(x_, R_k, f_prev_B_, f_now_B, g_E_, dt);
  f_prev_B_ = f_now_B;
  // Φ differs from I only in the rows of δθ, δv and δp (the first 9): Φ P Φᵀ by blocks costs
  // 0.43× the dense product (BM_AidedInsRate).
  constexpr int kMoved = 9;
  AidedInsMatrix FP = P_;
  FP.topRows<kMoved>() = F.topRows<kMoved>() * P_;
  P_ = FP;
  P_.leftCols<kMoved>() = FP * F.topRows<kMoved>().transpose();
  P_.block<3, 3>(kTheta, kTheta).diagonal().array() +=
      (std::pow(settings_.gyro_noise_density, 2) + std::pow(settings_.attitude_process_noise, 2)) *
      dt;
  P_.block<3, 3>(kVel, kVel).diagonal().array() +=
      accel_noise_scale_ * std::pow(settings_.accel_noise_density, 2) * dt +
      std::pow(settings_.accel_change_sigma * force_change * dt, 2);
  P_.block<3, 3>(kBg, kBg).diagonal().array() += std::pow(settings_.gyro_bias_random_walk, 2) * dt;
  P_.block<3, 3>(kBa, kBa).diagonal().array() += std::pow(settings_.accel_bias_random_walk, 2) * dt;
  ++counters_.imu_samples;
  Commit();
  return Status::Ok();
}

Status AidedIns::CheckMeasurementTime(double t, const char* what) {
  std::ostringstream o;
  o << what << ": t ";
  if (!std::isfinite(t)) {
    o << "is not finite";
    return Refuse(o.str());
  }
  if (!has_time_ || std::abs(t - t_) > 1e-9) {
    o << "= " << t << " s is not the last IMU sample's time";
    if (has_time_) o << " (" << t_ << " s)";
    return Refuse(o.str());
  }
  return Status::Ok();
}

void AidedIns::TryInitialise() {
  if (initialized_ || !has_attitude_ || !has_position_) return;
  x_ = AidedInsState{};
  x_.R_EB = R_init_;
  x_.r_BM_B = settings_.lever_arm_B;
  x_.R_WE = R_WE_;
  // The IMU below the first marker sample: p = R_WEᵀ z − R r.
  const Mat3 R_EW = R_WE_.transpose();
  x_.p_EB_E = R_EW * p_init_ - R_init_ * settings_.lever_arm_B;
  P_.setZero();
  const auto set = [&](int block, double sigma) {
    P_.block<3, 3>(block, block).diagonal().setConstant(sigma * sigma);
  };
  set(kTheta, settings_.initial_attitude_sigma);
  set(kVel, settings_.initial_velocity_sigma);
  set(kBg, settings_.initial_gyro_bias_sigma);
  set(kBa, settings_.initial_accel_bias_sigma);
  set(kLever, settings_.lever_arm_sigma);
  P_.block<3, 3>(kFrame, kFrame) = R_WE_covariance_;
  // p = R_EW z − R r inherits the sensor's noise, the lever arm's and the frame's uncertainty:
  // ∂p/∂δr = −R, ∂p/∂δφ = R_EW [z]× (R_EW = R̂_EW Exp(−δφ)).
  const Mat3 R = R_init_;
  const Mat3 J_frame = R_EW * Skew(p_init_);
  P_.block<3, 3>(kPos, kPos) =
      settings_.position_sigma * settings_.position_sigma * Mat3::Identity() +
      R * P_.block<3, 3>(kLever, kLever) * R.transpose() +
      J_frame * R_WE_covariance_ * J_frame.transpose();
  P_.block<3, 3>(kPos, kLever) = -R * P_.block<3, 3>(kLever, kLever);
  P_.block<3, 3>(kLever, kPos) = P_.block<3, 3>(kPos, kLever).transpose();
  P_.block<3, 3>(kPos, kFrame) = J_frame * R_WE_covariance_;
  P_.block<3, 3>(kFrame, kPos) = P_.block<3, 3>(kPos, kFrame).transpose();
  initialized_ = true;
  Commit();
}

Status AidedIns::SetWorldFromEarth(const Mat3& R_WE, const Mat3& covariance) {
  if (initialized_ || has_position_)
    return Refuse("world frame: R_WE is set before the first position sample");
  if (!detail::IsRotation(R_WE)) return Refuse("world frame: R_WE is not a rotation");
  if (!detail::IsCovariance(covariance))
    return Refuse("world frame: its covariance is not finite, symmetric and non-negative");
  R_WE_ = R_WE_reference_ = R_WE;
  R_WE_covariance_ = R_WE_reference_covariance_ = covariance;
  return Status::Ok();
}

Status AidedIns::UpdateWorldFromEarth(const Mat3& R_WE, const Mat3& covariance) {
  if (!initialized_)
    return Refuse("world frame: no state yet to update (SetWorldFromEarth tells the frame then)");
  if (R_WE_covariance_.isZero())
    return Refuse("world frame: told as known exactly (zero covariance), it is not updated");
  if (!detail::IsRotation(R_WE)) return Refuse("world frame: R_WE is not a rotation");
  const Eigen::LLT<Mat3> llt(covariance);
  if (!detail::IsCovariance(covariance) || llt.info() != Eigen::Success)
    return Refuse("world frame: its covariance is not finite, symmetric and positive definite");
  // Both estimates about the current frame, R = Exp(x) R̂_WE.
  const Mat3 I_new = llt.solve(Mat3::Identity());
  const Vec3 x_new = Log(R_WE * x_.R_WE.transpose());
  const Eigen::LLT<Mat3> llt_prev(R_WE_reference_covariance_);
  const Mat3 I_prev = llt_prev.info() == Eigen::Success ? Mat3(llt_prev.solve(Mat3::Identity()))
                                                        : Mat3(Mat3::Zero());
  const Vec3 x_prev = Log(R_WE_reference_ * x_.R_WE.transpose());
  // The reference for the next estimate, and the frame a re-initialisation starts from.
  R_WE_ = R_WE_reference_ = R_WE;
  R_WE_covariance_ = R_WE_reference_covariance_ = covariance;
  const Mat3 dI = 0.5 * (I_new - I_prev + (I_new - I_prev).transpose());
  const Eigen::SelfAdjointEigenSolver<Mat3> eig(dI);
  if (!(eig.eigenvalues().minCoeff() > 1e-9 * eig.eigenvalues().cwiseAbs().maxCoeff())) {
    ++counters_.frame_uninformative;
    return Status::Ok();
  }
  const Mat3 R_z = eig.eigenvectors() * eig.eigenvalues().cwiseInverse().asDiagonal() *
                   eig.eigenvectors().transpose();
  const Vec3 z = R_z * (I_new * x_new - I_prev * x_prev);
  AidedInsRow3 H = AidedInsRow3::Zero();
  H.block<3, 3>(0, kFrame).setIdentity();
  bool gated = false;
  (void)Correct<3>(H, z, R_z, 0.0, &gated);
  ++counters_.frame_updates;
  return Status::Ok();
}

Status AidedIns::UpdatePosition(double t, const Vec3& p_WM_W) {
  if (!std::isfinite(t)) return Refuse("position: t is not finite");
  // τ: how long before the IMU's last sample the tracker saw the marker, within the last step.
  const double tau = t_ - t;
  if (!has_time_ || tau < -1e-9 || tau > step_dt_ + 1e-9) {
    std::ostringstream o;
    o << "position: t = " << t << " s is not within the last IMU step";
    if (has_time_) o << " (" << t_ - step_dt_ << " s to " << t_ << " s)";
    return Refuse(o.str());
  }
  if (!p_WM_W.allFinite()) return Refuse("position: p_WM_W is not finite");
  if (!initialized_) {
    p_init_ = p_WM_W;
    has_position_ = true;
    TryInitialise();
    return Status::Ok();
  }
  const double tau_s = std::max(tau, 0.0);
  const AidedInsRow3 H = TrackerPositionBeforeJacobian(x_, tau_s, step_omega_B_, step_a_E_);
  const Vec3 y = p_WM_W - TrackerPositionBefore(x_, tau_s, step_omega_B_, step_a_E_);
  const Mat3 R = Mat3::Identity() * settings_.position_sigma * settings_.position_sigma;
  bool gated = false;
  double gate = settings_.position_gate_chi2;
  if (settings_.max_consecutive_rejections > 0 &&
      consecutive_rejections_ >= settings_.max_consecutive_rejections) {
    // Re-anchor (settings): the integral went wrong, the tracker did not.
    P_.block<3, 3>(kVel, kVel).diagonal().array() += std::pow(settings_.initial_velocity_sigma, 2);
    P_.block<3, 3>(kPos, kPos) += y * y.transpose();
    gate = 0.0;
    ++counters_.reanchored;
  }
  last_position_nis_ = Correct<3>(H, y, R, gate, &gated);
  if (gated && shock_covariance_(1, 1) > 0.0) {
    // The accelerometer-shock hypothesis (settings): the same sample, with the velocity and
    // position errors the force's changes since the last position taken may have made.
    const AidedInsMatrix P_before = P_;
    const Mat3 I3 = Mat3::Identity();
    P_.block<3, 3>(kPos, kPos) += shock_covariance_(0, 0) * I3;
    P_.block<3, 3>(kPos, kVel) += shock_covariance_(0, 1) * I3;
    P_.block<3, 3>(kVel, kPos) += shock_covariance_(1, 0) * I3;
    P_.block<3, 3>(kVel, kVel) += shock_covariance_(1, 1) * I3;
    last_position_nis_ = Correct<3>(H, y, R, gate, &gated);
    if (gated)
      P_ = P_before;
    else
      ++counters_.shocks_taken;
  }
  if (!gated) shock_covariance_.setZero();
  consecutive_rejections_ = gated ? consecutive_rejections_ + 1 : 0;
  // Covariance matching (settings): a stochastic-approximation step toward E[NIS] = 3.
  if (const double tau = settings_.accel_noise_adaptation_tau;
      tau > 0.0 && has_last_position_t_ && std::isfinite(last_position_nis_)) {
    const double a = std::min(1.0, (t - last_position_t_) / tau);
    const double step = a * (std::min(last_position_nis_, 30.0) / 3.0 - 1.0);
    accel_noise_scale_ =
        std::clamp(accel_noise_scale_ * std::exp(step), 1.0, settings_.accel_noise_max_scale);
  }
  last_position_t_ = t;
  has_last_position_t_ = true;
  if (gated)
    ++counters_.position_rejected;
  else
    ++counters_.positions;
  return Status::Ok();
}

Eigen::Matrix<double, 6, 6> AidedIns::marker_covariance() const {
  Eigen::Matrix<double, 6, kN> J;
  J.topRows<3>() = TrackerPositionJacobian(x_);
  J.bottomRows<3>() = TrackerVelocityJacobian(x_, step_omega_B_);
  const Eigen::Matrix<double, 6, 6> C = J * P_ * J.transpose();
  return 0.5 * (C + C.transpose());
}

Status AidedIns::UpdateHeading(double t, const Eigen::Vector4d& q_EB_ref) {
  if (Status s = CheckMeasurementTime(t, "heading"); !s) return s;
  if (!q_EB_ref.allFinite() || std::abs(q_EB_ref.norm() - 1.0) > 1e-3)
    return Refuse("heading: q_EB_ref is not a finite unit quaternion");
  const Mat3 R_ref = geometry::QuatToMatrix(q_EB_ref);
  if (!initialized_) {
    R_init_ = R_ref;
    has_attitude_ = true;
    TryInitialise();
    return Status::Ok();
  }
  // The angle about the earth's z axis of R_ref R̂ᵀ (exact for a rotation about z; the tilt
  // between the two is left out).
  const Mat3 E = R_ref * x_.R_EB.transpose();
  CorrectHeading(std::atan2(E(1, 0) - E(0, 1), E(0, 0) + E(1, 1)), settings_.heading_sigma);
  ++counters_.headings;
  return Status::Ok();
}

Status AidedIns::UpdateMagnetometer(double t, const Vec3& m_B) {
  if (Status s = CheckMeasurementTime(t, "magnetometer"); !s) return s;
  if (!m_B.allFinite() || m_B.norm() <= 0.0)
    return Refuse("magnetometer: m_B is not finite and non-zero");
  if (!initialized_) return Refuse("magnetometer: the filter has no attitude yet (UpdateHeading)");
  const Vec3 up_E = UpVector(settings_.earth);
  const Vec3 m_E = x_.R_EB * m_B;
  const Vec3 h_E = m_E - m_E.dot(up_E) * up_E;
  if (h_E.norm() < 0.1 * m_E.norm())
    return Refuse("magnetometer: the field is nearly vertical, its heading is undefined");
  // The rotation about E's z axis that takes the levelled field to magnetic north.
  const Vec3 n_E = MagneticNorth(settings_.earth);
  CorrectHeading(std::atan2(h_E.cross(n_E).z(), h_E.dot(n_E)), settings_.mag_heading_sigma);
  ++counters_.mag_headings;
  return Status::Ok();
}

void AidedIns::CorrectHeading(double y_rad, double sigma_rad) {
  // A rotation about E's z axis: H = e_zᵀ on δθ.
  Eigen::Matrix<double, 1, kN> H = Eigen::Matrix<double, 1, kN>::Zero();
  H(0, kTheta + 2) = 1.0;
  const Eigen::Matrix<double, 1, 1> y = Eigen::Matrix<double, 1, 1>::Constant(y_rad);
  const Eigen::Matrix<double, 1, 1> R =
      Eigen::Matrix<double, 1, 1>::Constant(sigma_rad * sigma_rad);
  bool gated = false;
  (void)Correct<1>(H, y, R, 0.0, &gated);
}

template <int M>
double AidedIns::Correct(const Eigen::Matrix<double, M, kN>& H,
                         const Eigen::Matrix<double, M, 1>& y, const Eigen::Matrix<double, M, M>& R,
                         double gate_chi2, bool* gated) {
  const Eigen::Matrix<double, kN, M> PHt = P_ * H.transpose();
  // M ≤ 3: the fixed-size inverse is closed-form.
  const Eigen::Matrix<double, M, M> S = H * PHt + R;
  const Eigen::Matrix<double, M, M> S_inv = S.inverse();
  const double nis = y.dot(S_inv * y);
  *gated = gate_chi2 > 0.0 && !(nis <= gate_chi2);
  if (*gated) return nis;
  const Eigen::Matrix<double, kN, M> K = PHt * S_inv;
  // P − K S Kᵀ (= (I − KH) P with the optimal gain; symmetric by construction, symmetrised again
  // in Commit): M ≤ 3 columns, against the Joseph form's two dense 21×21 products.
  P_ -= K * S * K.transpose();
  x_ = Boxplus(x_, K * y);
  Commit();
  return nis;
}

void AidedIns::Commit() {
  P_ = 0.5 * (P_ + P_.transpose());
  const bool finite = x_.R_EB.allFinite() && x_.v_EB_E.allFinite() && x_.p_EB_E.allFinite() &&
                      x_.b_g_B.allFinite() && x_.b_a_B.allFinite() && x_.r_BM_B.allFinite() &&
                      x_.R_WE.allFinite() && P_.allFinite();
  if (!finite) {
    ResetKeepingTime();  // `resets` survives a Reset
    ++counters_.resets;
    return;
  }
  Eigen::Vector4d q = geometry::MatrixToQuat(x_.R_EB);
  if (q.dot(q_EB_) < 0.0) q = -q;
  q_EB_ = q;
}

Status StepAfterOrientationKf(AidedIns& ins, const OrientationKf& okf, double t, const Vec3& gyro_B,
                              const Vec3& f_B, bool heading_from_kf) {
  if (Status s = ins.UpdateImu(t, gyro_B, f_B); !s) return s;
  if (!okf.initialized()) return Status::Ok();
  if (!ins.initialized() || heading_from_kf)
    (void)ins.UpdateHeading(t, okf.q_EB());
  else if (okf.last_mag_B().allFinite())
    (void)ins.UpdateMagnetometer(t, okf.last_mag_B());
  return Status::Ok();
}

}  // namespace rcal::estimation
