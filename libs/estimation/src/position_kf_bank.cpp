#include "rcal/estimation/position_kf_bank.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace rcal::estimation {

std::vector<PositionKfSettings> DefaultBankModels(const PositionKfSettings& base) {
  PositionKfSettings paper;
  PositionKfSettings driven = AccelerometerDrivenSettings();
  paper.accel_sigma = 0.3;
  paper.accel_noise_adaptation_tau = driven.accel_noise_adaptation_tau;
  for (PositionKfSettings* s : {&paper, &driven}) {
    s->earth = base.earth;
    s->gravity = base.gravity;
    s->position_sigma = base.position_sigma;
    s->position_gate_chi2 = base.position_gate_chi2;
    s->accel_rollback_span = base.accel_rollback_span;
    s->accel_gate_chi2 = kBankAccelGateChi2;
    s->lever_arm_B = base.lever_arm_B;
    s->estimate_lever_arm = base.estimate_lever_arm;
    s->lever_arm_sigma = base.lever_arm_sigma;
    s->accel_delay = base.accel_delay;  // the IMU's, as the frame and the lever arm
  }
  return {paper, driven};
}

PositionKfBank::PositionKfBank(const PositionKfBankSettings& settings) : settings_(settings) {
  if (settings_.models.empty()) settings_.models = DefaultBankModels(PositionKfSettings{});
  if (!(settings_.evidence_tau > 0.0) || !std::isfinite(settings_.evidence_tau))
    throw std::invalid_argument("position_kf_bank: evidence_tau must be a positive time [s]");
  if (!(settings_.min_probability >= 0.0 && settings_.min_probability < 1.0))
    throw std::invalid_argument("position_kf_bank: min_probability must be in [0, 1)");
  for (const PositionKfSettings& s : settings_.models) filters_.emplace_back(s);
  evidence_.assign(filters_.size(), 0.0);
  mu_.assign(filters_.size(), 1.0 / static_cast<double>(filters_.size()));
}

void PositionKfBank::Reset() {
  for (PositionKf& f : filters_) f.Reset();
  evidence_.assign(filters_.size(), 0.0);
  mu_.assign(filters_.size(), 1.0 / static_cast<double>(filters_.size()));
  has_last_t_ = false;
  last_t_ = 0.0;
}

Status PositionKfBank::UpdateAccel(double t, const Eigen::Vector3d& f_B,
                                   const Eigen::Matrix3d& R_EB, const Eigen::Vector3d& omega_B) {
  Status first = Status::Ok();
  for (PositionKf& f : filters_)
    if (Status s = f.UpdateAccel(t, f_B, R_EB, omega_B); !s && first) first = s;
  return first;
}

Status PositionKfBank::SetWorldFromEarth(const Eigen::Matrix3d& R_WE,
                                         const Eigen::Matrix3d& covariance) {
  Status first = Status::Ok();
  for (PositionKf& f : filters_)
    if (Status s = f.SetWorldFromEarth(R_WE, covariance); !s && first) first = s;
  return first;
}

Status PositionKfBank::UpdatePosition(double t, const Eigen::Vector3d& p_WM_W) {
  // A filter that (re-)initialises on this sample has no evidence from it (its ℓ is 0), nor do
  // the others then: the sample starts a new comparison.
  const bool fresh = !initialized();
  Status first = Status::Ok();
  for (PositionKf& f : filters_)
    if (Status s = f.UpdatePosition(t, p_WM_W); !s && first) first = s;
  if (!first) return first;
  // L_i ← max(e^{−Δt/τ} L_i, max_j e^{−Δt/τ} L_j − ln(1/μ_min)) + ℓ_i (header comment: the
  // prior weight μ_min every model keeps before a sample).
  const double fade =
      has_last_t_ ? std::exp(-std::max(0.0, t - last_t_) / settings_.evidence_tau) : 0.0;
  for (double& L : evidence_) L *= fade;
  if (settings_.min_probability > 0.0) {
    const double floor =
        *std::max_element(evidence_.begin(), evidence_.end()) + std::log(settings_.min_probability);
    for (double& L : evidence_) L = std::max(L, floor);
  }
  for (size_t i = 0; i < filters_.size(); ++i) {
    const double l = filters_[i].last_position_log_likelihood();
    evidence_[i] += fresh || !std::isfinite(l) ? 0.0 : l;
  }
  has_last_t_ = true;
  last_t_ = t;
  Reweigh();
  return first;
}

void PositionKfBank::Reweigh() {
  const double top = *std::max_element(evidence_.begin(), evidence_.end());
  double sum = 0.0;
  for (size_t i = 0; i < mu_.size(); ++i) {
    mu_[i] = std::max(std::exp(evidence_[i] - top), settings_.min_probability);
    sum += mu_[i];
  }
  for (double& m : mu_) m /= sum;
}

bool PositionKfBank::initialized() const {
  return std::all_of(filters_.begin(), filters_.end(),
                     [](const PositionKf& f) { return f.initialized(); });
}

Eigen::Vector3d PositionKfBank::p_WM_W() const {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < filters_.size(); ++i) p += mu_[i] * filters_[i].p_WM_W();
  return p;
}

Eigen::Vector3d PositionKfBank::v_W() const {
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < filters_.size(); ++i) v += mu_[i] * filters_[i].v_W();
  return v;
}

Eigen::Matrix3d PositionKfBank::position_covariance() const {
  return position_velocity_covariance().topLeftCorner<3, 3>();
}

Eigen::Matrix<double, 6, 6> PositionKfBank::position_velocity_covariance() const {
  Eigen::Matrix<double, 6, 1> mean;
  mean << p_WM_W(), v_W();
  Eigen::Matrix<double, 6, 6> C = Eigen::Matrix<double, 6, 6>::Zero();
  for (size_t i = 0; i < filters_.size(); ++i) {
    Eigen::Matrix<double, 6, 1> d;
    d << filters_[i].p_WM_W(), filters_[i].v_W();
    d -= mean;
    C += mu_[i] * (filters_[i].position_velocity_covariance() + d * d.transpose());
  }
  return C;
}

std::int64_t PositionKfBank::resets() const {
  std::int64_t n = 0;
  for (const PositionKf& f : filters_) n += f.counters().resets;
  return n;
}

}  // namespace rcal::estimation
