#include "rcal/estimation/orientation_kf.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>

#include "number_text.hpp"
#include "rcal/estimation/low_pass.hpp"
#include "rcal/geometry/so3.hpp"

namespace rcal::estimation {
namespace {

using detail::Num;

using geometry::QuatMultiply;
using geometry::QuatToMatrix;

// Unit quaternion [w,x,y,z] of the rotation vector v [rad].
Eigen::Vector4d QuatExp(const Eigen::Vector3d& v) {
  const double a = v.norm();
  if (a < 1e-12) {
    Eigen::Vector4d q(1.0, 0.5 * v.x(), 0.5 * v.y(), 0.5 * v.z());
    return q.normalized();
  }
  const double s = std::sin(0.5 * a) / a;
  return {std::cos(0.5 * a), s * v.x(), s * v.y(), s * v.z()};
}

std::string Vec(const Eigen::Vector3d& v) {
  std::ostringstream o;
  o << "[" << v.x() << ", " << v.y() << ", " << v.z() << "]";
  return o.str();
}

}  // namespace

Eigen::Matrix<double, 7, 7> PaperPhiOri(const Eigen::Vector4d& q, double dt) {
  // q̇ = ½ Ξ(q) ω with Ξ(q) the last three columns of the matrix in Eq. 18.
  const double h = 0.5 * dt;
  Eigen::Matrix<double, 7, 7> Phi = Eigen::Matrix<double, 7, 7>::Identity();
  Phi.block<4, 3>(0, 4) << -q(1), -q(2), -q(3),  //
      q(0), -q(3), q(2),                         // row 2: −q3 (erratum, NOTES.md)
      q(3), q(0), -q(1),                         //
      -q(2), q(1), q(0);
  Phi.block<4, 3>(0, 4) *= h;
  return Phi;
}

double MaxStepForRate(double rate_hz, double max_step) {
  if (!(std::isfinite(rate_hz) && rate_hz > 0.0)) return max_step;
  return std::max(max_step, 3.0 / rate_hz);
}

OrientationKf::OrientationKf(const OrientationKfSettings& settings) : settings_(settings) {
  Reset();
}

void OrientationKf::Reset() {
  initialized_ = false;
  t_ = 0.0;
  q_EB_ = Eigen::Vector4d(1, 0, 0, 0);
  omega_B_.setZero();
  bias_B_.setZero();
  q_IB_ = Eigen::Vector4d(1, 0, 0, 0);
  f_I_lp_.setZero();
  f_I_in1_.setZero();
  f_I_in2_.setZero();
  f_I_out2_.setZero();
  m_I_lp_.setZero();
  P_.setIdentity();
  hard_iron_ = MagHardIron(settings_.hard_iron);
  const std::int64_t resets = counters_.resets;
  counters_ = {};
  counters_.resets = resets;
  tilt_sigma_k_ = settings_.tilt_sigma;
  heading_sigma_k_ = settings_.heading_sigma;
  last_tilt_nis_ = std::numeric_limits<double>::quiet_NaN();
  last_heading_nis_ = std::numeric_limits<double>::quiet_NaN();
  last_accel_used_ = false;
  last_mag_used_ = false;
  still_count_ = 0;
  been_still_ = false;
  mag_ref_norm_ = settings_.mag_ref_norm > 0.0 ? settings_.mag_ref_norm : 0.0;
  mag_ref_dip_ = settings_.mag_ref_norm > 0.0 ? settings_.mag_ref_dip : 0.0;
  mag_ref_count_ = 0;
  mag_rejected_time_ = 0.0;
  mag_cand_norm_ = mag_cand_dip_ = 0.0;
  mag_norm_sum_ = 0.0;
  mag_dip_sum_ = 0.0;
}

Eigen::Matrix3d OrientationKf::R_EB() const {
  return QuatToMatrix(q_EB_);
}

void OrientationKf::PredictRate(double dt) {
  // ω_k = ω_{k−1} + ∫w over (t_{k−1}, t_k];  b_k = b_{k−1} + ∫w_b.
  const double sa2 = settings_.angular_accel_noise * settings_.angular_accel_noise;
  P_.block<3, 3>(3, 3) += sa2 * dt * Eigen::Matrix3d::Identity();
  if (settings_.estimate_gyro_bias) {
    const double sb2 = settings_.gyro_bias_random_walk * settings_.gyro_bias_random_walk;
    P_.block<3, 3>(6, 6) += sb2 * dt * Eigen::Matrix3d::Identity();
  }
}

void OrientationKf::PropagateAttitude(double dt) {
  // q_k = q_{k−1} ⊗ Exp(ω_k Δt), ω_k the rate over (t_{k−1}, t_k] (already updated with the
  // gyro sample at t_k); δθ_k = δθ_{k−1} + R̂_EB,k J_r(ω̂Δt) Δt δω_k.
  const Eigen::Vector3d phi = omega_B_ * dt;
  q_EB_ = QuatMultiply(q_EB_, QuatExp(phi)).normalized();
  Mat9 Phi = Mat9::Identity();
  Phi.block<3, 3>(0, 3) = QuatToMatrix(q_EB_) * geometry::RightJacobian(phi) * dt;
  P_ = Phi * P_ * Phi.transpose();
  P_.block<3, 3>(0, 0) += settings_.attitude_process_noise * settings_.attitude_process_noise * dt *
                          Eigen::Matrix3d::Identity();
  // Heading (earth z) random walk that grows with the rate: heading is observed only by the
  // magnetometer, so fast motion should hand it back to the magnetometer sooner.
  const double k_w = settings_.rate_proportional_noise * omega_B_.norm();
  P_(2, 2) += k_w * k_w * dt;
  P_ = 0.5 * (P_ + P_.transpose());
}

void OrientationKf::ApplyCorrection(const Eigen::Matrix<double, 9, 1>& dx) {
  q_EB_ = QuatMultiply(QuatExp(dx.head<3>()), q_EB_).normalized();
  omega_B_ += dx.segment<3>(3);
  if (settings_.estimate_gyro_bias) bias_B_ += dx.segment<3>(6);
}

double OrientationKf::Correct(const Eigen::MatrixXd& H, const Eigen::VectorXd& y,
                              const Eigen::MatrixXd& R) {
  // NOTES.md errata for Eqs. 15–17: K = P⁻Hᵀ(HP⁻Hᵀ + R)⁻¹, x⁺ = x⁻ + K(z − Hx⁻),
  // P⁺ = (I − KH)P⁻(I − KH)ᵀ + KRKᵀ (Joseph form).
  const Eigen::MatrixXd S = H * P_ * H.transpose() + R;
  const Eigen::LDLT<Eigen::MatrixXd> S_ldlt(S);
  Eigen::MatrixXd K = S_ldlt.solve(H * P_).transpose();  // P Hᵀ S⁻¹ (S, P symmetric)
  // Before the first rest the bias is a consider state: no correction (Joseph form keeps P
  // right for any gain).
  if (!settings_.learn_in_motion && !been_still_) K.bottomRows<3>().setZero();
  const Eigen::Matrix<double, 9, 1> dx = K * y;
  const Mat9 IKH = Mat9::Identity() - K * H;
  P_ = IKH * P_ * IKH.transpose() + K * R * K.transpose();
  P_ = 0.5 * (P_ + P_.transpose());
  ApplyCorrection(dx);
  return y.dot(S_ldlt.solve(y));
}

Status OrientationKf::Update(double t, const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B,
                             const Eigen::Vector3d& m_meas_raw_B, std::optional<bool> at_rest) {
  if (Status s = CheckInput(t, gyro_B, f_B, m_meas_raw_B); !s.ok()) return s;
  // A magnet fixed to the sensor is taken off before anything uses the field (settings). A zero
  // field, which the fit refuses, is left as it is.
  Eigen::Vector3d m_B = m_meas_raw_B;
  if (settings_.estimate_hard_iron && hard_iron_.Update(t, m_meas_raw_B).ok())
    m_B -= hard_iron_.offset_B();
  FqaSettings fqa;
  fqa.earth = settings_.earth;
  fqa.m_ref_E = MagneticNorth(settings_.earth);
  if (!initialized_) return Initialize(t, gyro_B, f_B, m_B, fqa);
  if (settings_.max_step > 0.0 && t - t_ > settings_.max_step) {
    // An IMU silence (settings): the attitude starts again from this sample. The gyro's bias,
    // which a silence does not change, and the magnetic reference are kept; whether the sensor
    // rests is not known.
    const Eigen::Vector3d bias_B = bias_B_;
    const Eigen::Matrix3d P_bb = P_.bottomRightCorner<3, 3>();
    if (Status s = Initialize(t, gyro_B, f_B, m_B, fqa); !s.ok()) return s;
    bias_B_ = bias_B;
    P_.bottomRightCorner<3, 3>() = P_bb;
    still_count_ = 0;
    // No heading row used this sample: the field from before the silence is another body's.
    last_mag_B_.setConstant(std::numeric_limits<double>::quiet_NaN());
    ++counters_.reinitialised;
    return Status::Ok();
  }

  const double dt = t - t_;
  t_ = t;
  ++counters_.samples;
  PredictRate(dt);
  UpdateGyro(gyro_B, dt);
  PropagateAttitude(dt);
  DetectRest(gyro_B, f_B.norm(), at_rest);
  if (settings_.zero_rate_update && still()) ZeroRateUpdate();

  // Strapdown frame I (gyro only, never corrected) and the sensors low-passed in it: in I,
  // gravity and the earth field are nearly constant while linear accelerations average out.
  const Eigen::Matrix3d R_IB = PropagateStrapdown(dt);
  LowPassAccel(R_IB * f_B, dt);
  const Eigen::Vector3d f_meas_B = R_IB.transpose() * f_I_lp_;

  // Accelerometer and magnetometer acceptance.
  const Eigen::Vector3d down_B = -R_EB().transpose() * UpVector(settings_.earth);
  tilt_sigma_k_ = TiltSigma(f_B - f_meas_B);
  heading_sigma_k_ = settings_.heading_sigma;  // MagAccepted inflates it with its evidence
  // The field the body sees now: a delayed magnetometer's sample turned on by the rate since.
  const Eigen::Vector3d m_now_B =
      settings_.mag_delay == 0.0
          ? m_B
          : Eigen::Vector3d(geometry::Exp(omega_B_ * settings_.mag_delay).transpose() * m_B);
  SensorUse use{AccelAccepted(f_meas_B), MagAccepted(m_now_B, f_B, down_B, dt)};
  if (use.mag)
    m_I_lp_ += FirstOrderLowPassGain(dt, settings_.mag_lowpass_tau) * (R_IB * m_now_B - m_I_lp_);
  const Eigen::Vector3d m_meas_B = R_IB.transpose() * m_I_lp_;

  last_tilt_nis_ = last_heading_nis_ = std::numeric_limits<double>::quiet_NaN();
  if (settings_.decoupled_fqa)
    use = DecoupledFqaUpdate(f_meas_B, m_meas_B, fqa, use);
  else if (use.accel || use.mag)
    use = PaperFqaUpdate(f_meas_B, m_meas_B, fqa, use);
  if (!use.accel) ++counters_.accel_rejected;
  if (!use.mag) ++counters_.mag_rejected;
  last_accel_used_ = use.accel;
  last_mag_used_ = use.mag;
  last_mag_B_ =
      use.mag ? m_meas_B : Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  if (!(q_EB_.allFinite() && omega_B_.allFinite() && bias_B_.allFinite() && P_.allFinite() &&
        q_IB_.allFinite() && f_I_lp_.allFinite() && m_I_lp_.allFinite())) {
    // Never publish or build on a NaN state: start over at the next sample.
    Reset();
    ++counters_.resets;
    return Status::Error("orientation_kf: state went non-finite at t = " + Num(t) +
                         " s; filter reset (" + std::to_string(counters_.resets) + " so far)");
  }
  return Status::Ok();
}

Status OrientationKf::Refuse(const std::string& why) {
  ++counters_.input_rejected;
  return Status::Error("orientation_kf: " + why);
}

Status OrientationKf::CheckInput(double t, const Eigen::Vector3d& gyro_B,
                                 const Eigen::Vector3d& f_B, const Eigen::Vector3d& m_B) {
  if (!std::isfinite(t)) return Refuse("time t is not finite");
  if (!gyro_B.allFinite()) return Refuse("gyro is not finite: " + Vec(gyro_B));
  if (!f_B.allFinite()) return Refuse("accelerometer is not finite: " + Vec(f_B));
  if (!m_B.allFinite()) return Refuse("magnetometer is not finite: " + Vec(m_B));
  if (gyro_B.cwiseAbs().maxCoeff() > settings_.gyro_range)
    return Refuse("gyro is beyond the sensor range (" + Num(settings_.gyro_range) +
                  " rad/s): " + Vec(gyro_B));
  if (f_B.cwiseAbs().maxCoeff() > settings_.accel_range)
    return Refuse("accelerometer is beyond the sensor range (" + Num(settings_.accel_range) +
                  " m/s^2): " + Vec(f_B));
  if (initialized_ && !(t > t_))
    return Refuse("time t = " + Num(t) + " s is not after the previous sample (" + Num(t_) + " s)");
  return Status::Ok();
}

Status OrientationKf::Initialize(double t, const Eigen::Vector3d& gyro_B,
                                 const Eigen::Vector3d& f_B, const Eigen::Vector3d& m_B,
                                 const FqaSettings& fqa) {
  const auto q0 = Fqa(f_B, m_B, fqa);
  if (!q0.ok()) return Refuse("cannot initialise: " + q0.error());
  q_EB_ = *q0;
  q_IB_ = *q0;
  f_I_lp_ = QuatToMatrix(q_IB_) * f_B;
  f_I_in1_ = f_I_in2_ = f_I_out2_ = f_I_lp_;  // the second-order low-pass at rest on it
  m_I_lp_ = QuatToMatrix(q_IB_) * m_B;
  omega_B_ = gyro_B;
  bias_B_.setZero();
  P_.setZero();
  P_.block<3, 3>(0, 0).diagonal().setConstant(std::pow(settings_.initial_attitude_sigma, 2));
  P_.block<3, 3>(3, 3).diagonal().setConstant(std::pow(settings_.initial_rate_sigma, 2));
  P_.block<3, 3>(6, 6).diagonal().setConstant(
      settings_.estimate_gyro_bias ? std::pow(settings_.initial_bias_sigma, 2) : 0.0);
  initialized_ = true;
  t_ = t;
  ++counters_.samples;
  // (The first sample counts towards the magnetic reference only when learning in motion:
  // whether the sensor is at rest is not known yet.)
  const double f_norm = f_B.norm();
  const double m_norm = m_B.norm();
  if (settings_.learn_in_motion && mag_ref_norm_ <= 0.0 && m_norm > 0.0 && f_norm > 0.0) {
    mag_norm_sum_ += m_norm;
    mag_dip_sum_ += std::asin(std::clamp(-m_B.dot(f_B) / (m_norm * f_norm), -1.0, 1.0));
    ++mag_ref_count_;
  }
  last_accel_used_ = last_mag_used_ = true;
  return Status::Ok();
}

void OrientationKf::UpdateGyro(const Eigen::Vector3d& gyro_B, double dt) {
  // z = ω_meas, h = ω̂ + b̂ (Eq. 22 with the bias).
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(3, 9);
  H.block<3, 3>(0, 3).setIdentity();
  if (settings_.estimate_gyro_bias) H.block<3, 3>(0, 6).setIdentity();
  const double sg2 = settings_.gyro_noise_density * settings_.gyro_noise_density / dt;
  Correct(H, gyro_B - omega_B_ - bias_B_, sg2 * Eigen::MatrixXd::Identity(3, 3));
}

void OrientationKf::DetectRest(const Eigen::Vector3d& gyro_B, double f_norm,
                               std::optional<bool> at_rest) {
  if (at_rest) {
    still_count_ = *at_rest ? std::max(still_count_ + 1, settings_.still_samples) : 0;
  } else {
    const bool still_now = (gyro_B - bias_B_).norm() < settings_.still_gyro &&
                           std::abs(f_norm - settings_.gravity) < settings_.still_accel;
    still_count_ = still_now ? still_count_ + 1 : 0;
  }
  been_still_ = been_still_ || still();
}

void OrientationKf::ZeroRateUpdate() {
  // At rest: the zero-rate pseudo-measurement makes the bias directly observable.
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(3, 9);
  H.block<3, 3>(0, 3).setIdentity();
  Correct(H, -omega_B_, std::pow(settings_.zero_rate_sigma, 2) * Eigen::MatrixXd::Identity(3, 3));
  ++counters_.zero_rate_updates;
}

void OrientationKf::LowPassAccel(const Eigen::Vector3d& f_I, double dt) {
  const double tau = settings_.accel_lowpass_tau;
  if (settings_.accel_lowpass_order != 2 || !(tau > 0.0)) {
    f_I_lp_ += FirstOrderLowPassGain(dt, tau) * (f_I - f_I_lp_);
    return;
  }
  // A step longer than τ (a gap in the data) would put the bilinear map's cutoff near or past
  // Nyquist (dt < π τ / √2): the filter then starts again from this sample, as at initialisation.
  if (dt > tau) {
    f_I_lp_ = f_I_in1_ = f_I_in2_ = f_I_out2_ = f_I;
    return;
  }
  const Butterworth2 c = Butterworth2::LowPass(dt, tau);
  const Eigen::Vector3d y =
      c.b0 * f_I + c.b1 * f_I_in1_ + c.b2 * f_I_in2_ - c.a1 * f_I_lp_ - c.a2 * f_I_out2_;
  f_I_in2_ = f_I_in1_;
  f_I_in1_ = f_I;
  f_I_out2_ = f_I_lp_;
  f_I_lp_ = y;
}

Eigen::Matrix3d OrientationKf::PropagateStrapdown(double dt) {
  q_IB_ = QuatMultiply(q_IB_, QuatExp(omega_B_ * dt)).normalized();
  return QuatToMatrix(q_IB_);
}

bool OrientationKf::AccelAccepted(const Eigen::Vector3d& f_meas_B) const {
  if (!(f_meas_B.norm() > 0.0)) return false;
  return !settings_.reject_accel ||
         std::abs(f_meas_B.norm() - settings_.gravity) <= settings_.accel_norm_tolerance;
}

bool OrientationKf::MagAccepted(const Eigen::Vector3d& m_B, const Eigen::Vector3d& f_B,
                                const Eigen::Vector3d& down_B, double dt) {
  const double m_norm = m_B.norm();
  if (!(m_norm > 0.0)) return false;
  if (mag_ref_norm_ <= 0.0) {
    // Reference not learned yet: the field is used ungated; learned from at rest only (or in
    // motion too with learn_in_motion).
    if (settings_.learn_in_motion || still()) LearnMagReference(m_B, f_B, down_B);
    return true;
  }
  if (!settings_.reject_mag) return true;
  const double dip = std::asin(std::clamp(m_B.dot(down_B) / m_norm, -1.0, 1.0));
  // Disturbance evidence: the departure from the reference in units of its tolerance.
  const double evidence =
      std::max(std::abs(m_norm - mag_ref_norm_) / (settings_.mag_norm_tolerance * mag_ref_norm_),
               std::abs(dip - mag_ref_dip_) / settings_.mag_dip_tolerance);
  if (evidence > 1.0) {
    FollowRejectedField(m_norm, dip, dt);
    return false;
  }
  heading_sigma_k_ = settings_.heading_sigma *
                     std::sqrt(1.0 + settings_.mag_evidence_inflation * evidence * evidence);
  FollowAcceptedField(m_norm, dip, dt);
  return true;
}

void OrientationKf::LearnMagReference(const Eigen::Vector3d& m_B, const Eigen::Vector3d& f_B,
                                      const Eigen::Vector3d& down_B) {
  const double m_norm = m_B.norm();
  const double f_norm = f_B.norm();
  const Eigen::Vector3d d_B = f_norm > 0.0 ? Eigen::Vector3d(-f_B / f_norm) : down_B;
  mag_norm_sum_ += m_norm;
  mag_dip_sum_ += std::asin(std::clamp(m_B.dot(d_B) / m_norm, -1.0, 1.0));
  if (++mag_ref_count_ >= std::max(1, settings_.mag_reference_samples)) {
    mag_ref_norm_ = mag_norm_sum_ / mag_ref_count_;
    mag_ref_dip_ = mag_dip_sum_ / mag_ref_count_;
  }
}

double OrientationKf::TiltSigma(const Eigen::Vector3d& f_motion_B) const {
  double v = 1.0;
  if (settings_.tilt_motion_accel > 0.0)
    v += (f_motion_B / settings_.tilt_motion_accel).squaredNorm();
  if (settings_.tilt_motion_rate > 0.0) {
    const double r = omega_B_.norm() / settings_.tilt_motion_rate;
    v += r * r;
  }
  return settings_.tilt_sigma * std::sqrt(v);
}

void OrientationKf::FollowAcceptedField(double m_norm, double dip, double dt) {
  if (settings_.mag_reference_tau > 0.0 && still()) {
    const double a = FirstOrderLowPassGain(dt, settings_.mag_reference_tau);
    mag_ref_norm_ += a * (m_norm - mag_ref_norm_);
    mag_ref_dip_ += a * (dip - mag_ref_dip_);
  }
  mag_rejected_time_ = 0.0;
}

void OrientationKf::FollowRejectedField(double m_norm, double dip, double dt) {
  // Candidate new reference: adopted after a long, steady rejection.
  const double a = FirstOrderLowPassGain(dt, 2.0);
  if (mag_rejected_time_ == 0.0) {
    mag_cand_norm_ = m_norm;
    mag_cand_dip_ = dip;
  } else {
    mag_cand_norm_ += a * (m_norm - mag_cand_norm_);
    mag_cand_dip_ += a * (dip - mag_cand_dip_);
  }
  const bool steady =
      std::abs(m_norm - mag_cand_norm_) < settings_.mag_norm_tolerance * mag_cand_norm_ &&
      std::abs(dip - mag_cand_dip_) < settings_.mag_dip_tolerance;
  mag_rejected_time_ = steady ? mag_rejected_time_ + dt : dt;
  if (settings_.mag_new_reference_time > 0.0 &&
      mag_rejected_time_ >= settings_.mag_new_reference_time) {
    mag_ref_norm_ = mag_cand_norm_;
    mag_ref_dip_ = mag_cand_dip_;
    mag_rejected_time_ = 0.0;
    ++counters_.mag_reference_changes;
  }
}

bool OrientationKf::GatedFqaUpdate(int row0, int rows, const Eigen::Vector3d& y_full, double sigma,
                                   double gate) {
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(rows, 9);
  H.block(0, row0, rows, rows).setIdentity();
  const Eigen::VectorXd y = y_full.segment(row0, rows);
  const Eigen::MatrixXd R = sigma * sigma * Eigen::MatrixXd::Identity(rows, rows);
  const Eigen::MatrixXd S = H * P_ * H.transpose() + R;
  const double nis = y.dot(S.ldlt().solve(y));
  (rows == 2 ? last_tilt_nis_ : last_heading_nis_) = nis;
  if (gate > 0.0 && nis > gate) return false;
  Correct(H, y, R);
  return true;
}

OrientationKf::SensorUse OrientationKf::DecoupledFqaUpdate(const Eigen::Vector3d& f_meas_B,
                                                           const Eigen::Vector3d& m_meas_B,
                                                           const FqaSettings& fqa, SensorUse use) {
  Eigen::Matrix3d R_hat = R_EB();
  if (use.accel) {
    // Tilt rows: FQA(accelerometer, predicted magnetometer).
    const Eigen::Vector3d m_pred_B = R_hat.transpose() * MagneticNorth(settings_.earth);
    const auto q_tilt = Fqa(f_meas_B, m_pred_B, fqa);
    if (q_tilt.ok()) {
      const Eigen::Vector3d y = geometry::Log(QuatToMatrix(*q_tilt) * R_hat.transpose());
      if (!GatedFqaUpdate(0, 2, y, tilt_sigma_k_, settings_.tilt_gate_chi2)) {
        use.accel = false;
        ++counters_.accel_gated;
      }
    } else {
      use.accel = false;
    }
    R_hat = R_EB();
  }
  if (use.mag) {
    // Heading row: FQA(predicted gravity, magnetometer).
    const Eigen::Vector3d f_level_B =
        settings_.gravity * R_hat.transpose() * UpVector(settings_.earth);
    const auto q_head = Fqa(f_level_B, m_meas_B, fqa);
    if (q_head.ok()) {
      const Eigen::Vector3d y = geometry::Log(QuatToMatrix(*q_head) * R_hat.transpose());
      if (!GatedFqaUpdate(2, 1, y, heading_sigma_k_, settings_.heading_gate_chi2)) {
        use.mag = false;
        ++counters_.mag_gated;
      }
    } else {
      use.mag = false;
    }
  }
  return use;
}

OrientationKf::SensorUse OrientationKf::PaperFqaUpdate(const Eigen::Vector3d& f_meas_B,
                                                       const Eigen::Vector3d& m_meas_B,
                                                       const FqaSettings& fqa, SensorUse use) {
  // The paper's measurement: one FQA quaternion; a rejected sensor is replaced by its
  // prediction so that its rows carry no information and are dropped.
  const Eigen::Matrix3d R_hat = R_EB();
  const Eigen::Vector3d m_pred_B = R_hat.transpose() * MagneticNorth(settings_.earth);
  const Eigen::Vector3d f_pred_B =
      settings_.gravity * R_hat.transpose() * UpVector(settings_.earth);
  const auto q_meas = Fqa(use.accel ? f_meas_B : f_pred_B, use.mag ? m_meas_B : m_pred_B, fqa);
  if (!q_meas.ok()) return {false, false};
  const Eigen::Vector3d y = geometry::Log(QuatToMatrix(*q_meas) * R_hat.transpose());
  if (use.accel && !GatedFqaUpdate(0, 2, y, tilt_sigma_k_, settings_.tilt_gate_chi2)) {
    use.accel = false;
    ++counters_.accel_gated;
  }
  // Sequential rows: the heading innovation is taken against the tilt-corrected state.
  const Eigen::Vector3d y2 = geometry::Log(QuatToMatrix(*q_meas) * R_EB().transpose());
  if (use.mag && !GatedFqaUpdate(2, 1, y2, heading_sigma_k_, settings_.heading_gate_chi2)) {
    use.mag = false;
    ++counters_.mag_gated;
  }
  return use;
}

}  // namespace rcal::estimation
