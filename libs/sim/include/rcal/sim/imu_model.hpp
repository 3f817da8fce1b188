// IMU sensor model: accelerometer, gyro and magnetometer sampled from truth motion.
//
// Frames: W (earth/world, the frame of a_W, g_W, m_W), I (the IMU body frame the truth
// orientation R_WI refers to), S (the sensor's own axes, rotated on the mount: v_S = R_SI v_I).
// Model, every effect switchable:
//   gyro  ω_S = (I + M_g) R_SI ω_I + b_g + n_g   (ω_I: the truth's mean rate over the sample
//         interval ending at the stamp, what a rate-integrating gyro reports and what the
//         orientation filter integrates: q_k = q_{k−1} Exp(ω_k Δt); see ImuTruth::omega_I)
//   accel f_S = (I + M_a) R_SI R_WIᵀ (a_W − g_W) + b_a + n_a      (specific force)
//   mag   m_S = R_SI R_WIᵀ m_W + b_m + n_m                       (b_m: hard iron)
//   M_*: scale (diagonal) and misalignment (off-diagonal); b_* = constant + random walk
//   (b_k = b_{k−1} + σ_rw √Δt ν); n_*: white, σ = noise density · √rate.
// Defaults: the paper's Xsens MTi-100 (gyro 0.01 °/s/√Hz, accelerometer 60 µg/√Hz,
// magnetometer 200 µG/√Hz = 0.02 µT/√Hz), 100 Hz, NED with g = 9.81 m/s².
// Seeded: std::mt19937_64 with an explicit seed; the same seed and truth give the same samples.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <random>

namespace rcal::sim {

/// One truth sample of the IMU's motion.
struct ImuTruth {
  double t = 0.0;                                      ///< [s]
  Eigen::Matrix3d R_WI = Eigen::Matrix3d::Identity();  ///< IMU → world orientation
  /// Angular rate in I [rad/s]. The simulated cells give the mean over the sample interval
  /// ending at t, Log(R_WI(t − Δt)ᵀ R_WI(t)) / Δt, so that the filters' interval rule integrates
  /// the noise-free gyro exactly; the rate at the instant t would put their attitude half a sample
  /// ahead of the truth.
  Eigen::Vector3d omega_I = Eigen::Vector3d::Zero();
  Eigen::Vector3d a_W = Eigen::Vector3d::Zero();  ///< acceleration in W, no gravity [m/s²]
  Eigen::Vector3d p_W = Eigen::Vector3d::Zero();  ///< position in W [m]
};

struct ImuSample {
  double t = 0.0;                                     ///< [s]
  Eigen::Vector3d gyro_S = Eigen::Vector3d::Zero();   ///< [rad/s]
  Eigen::Vector3d accel_S = Eigen::Vector3d::Zero();  ///< specific force [m/s²]
  Eigen::Vector3d mag_S = Eigen::Vector3d::Zero();    ///< [µT]
};

struct ImuModelSettings {
  double rate_hz = 100.0;  ///< sample rate [Hz], sets the white-noise σ
  /// Gravity vector in W [m/s²] (NED: +z down) and the earth field in W [µT].
  Eigen::Vector3d g_W = Eigen::Vector3d(0, 0, 9.81);
  Eigen::Vector3d m_W = Eigen::Vector3d(20.0, 0.0, 44.0);

  bool white_noise = true;
  double gyro_noise_density = 0.01 * 3.14159265358979 / 180.0;  ///< [rad/s/√Hz]
  double accel_noise_density = 60e-6 * 9.81;                    ///< [m/s²/√Hz]
  double mag_noise_density = 0.02;                              ///< [µT/√Hz]

  bool constant_bias = false;
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();   ///< [rad/s]
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();  ///< [m/s²]
  Eigen::Vector3d mag_bias = Eigen::Vector3d::Zero();    ///< hard iron [µT]

  bool bias_random_walk = false;
  double gyro_bias_random_walk = 1e-5;   ///< [rad/s/√s]
  double accel_bias_random_walk = 1e-4;  ///< [m/s²/√s]

  bool scale_misalignment = false;
  Eigen::Matrix3d gyro_M = Eigen::Matrix3d::Zero();   ///< scale + misalignment [-]
  Eigen::Matrix3d accel_M = Eigen::Matrix3d::Zero();  ///< scale + misalignment [-]

  bool mounting = false;
  Eigen::Matrix3d R_SI = Eigen::Matrix3d::Identity();  ///< sensor axes ← IMU body frame
};

class ImuModel {
 public:
  ImuModel(const ImuModelSettings& settings, std::uint64_t seed);
  /// Restarts the noise and the random-walk biases from `seed`.
  void Reset(std::uint64_t seed);
  /// The measurement at truth.t. Call in time order (the random walk uses the time step).
  ImuSample Sample(const ImuTruth& truth);
  /// Current total biases (constant + random walk).
  Eigen::Vector3d gyro_bias() const;
  Eigen::Vector3d accel_bias() const;
  const ImuModelSettings& settings() const { return settings_; }

 private:
  Eigen::Vector3d Normal3();
  ImuModelSettings settings_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  bool has_last_ = false;
  double t_last_ = 0.0;
  Eigen::Vector3d gyro_rw_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_rw_ = Eigen::Vector3d::Zero();
};

}  // namespace rcal::sim
