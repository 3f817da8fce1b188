#include "rcal/sim/imu_model.hpp"

#include <cmath>

namespace rcal::sim {

ImuModel::ImuModel(const ImuModelSettings& settings, std::uint64_t seed) : settings_(settings) {
  Reset(seed);
}

void ImuModel::Reset(std::uint64_t seed) {
  rng_.seed(seed);
  normal_.reset();
  has_last_ = false;
  t_last_ = 0.0;
  gyro_rw_.setZero();
  accel_rw_.setZero();
}

Eigen::Vector3d ImuModel::Normal3() {
  return {normal_(rng_), normal_(rng_), normal_(rng_)};
}

Eigen::Vector3d ImuModel::gyro_bias() const {
  return (settings_.constant_bias ? settings_.gyro_bias : Eigen::Vector3d::Zero()) + gyro_rw_;
}

Eigen::Vector3d ImuModel::accel_bias() const {
  return (settings_.constant_bias ? settings_.accel_bias : Eigen::Vector3d::Zero()) + accel_rw_;
}

ImuSample ImuModel::Sample(const ImuTruth& truth) {
  const ImuModelSettings& s = settings_;
  if (s.bias_random_walk && has_last_ && truth.t > t_last_) {
    const double sq = std::sqrt(truth.t - t_last_);
    gyro_rw_ += s.gyro_bias_random_walk * sq * Normal3();
    accel_rw_ += s.accel_bias_random_walk * sq * Normal3();
  }
  has_last_ = true;
  t_last_ = truth.t;

  const Eigen::Matrix3d R_SI = s.mounting ? s.R_SI : Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d R_SW = R_SI * truth.R_WI.transpose();
  Eigen::Matrix3d Mg = Eigen::Matrix3d::Identity(), Ma = Eigen::Matrix3d::Identity();
  if (s.scale_misalignment) {
    Mg += s.gyro_M;
    Ma += s.accel_M;
  }
  ImuSample out;
  out.t = truth.t;
  out.gyro_S = Mg * R_SI * truth.omega_I + gyro_bias();
  out.accel_S = Ma * R_SW * (truth.a_W - s.g_W) + accel_bias();
  out.mag_S = R_SW * s.m_W + (s.constant_bias ? s.mag_bias : Eigen::Vector3d::Zero());
  if (s.white_noise) {
    const double sr = std::sqrt(s.rate_hz);
    out.gyro_S += s.gyro_noise_density * sr * Normal3();
    out.accel_S += s.accel_noise_density * sr * Normal3();
    out.mag_S += s.mag_noise_density * sr * Normal3();
  }
  return out;
}

}  // namespace rcal::sim
