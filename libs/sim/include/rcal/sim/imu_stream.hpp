// A simulated IMU stream in the BROAD layout (../shared/data/broad/README.md): rest segments and
// motion segments, the truth orientation IMU → ENU and a movement flag, with IMU effects that can
// be switched on one at a time to hide them from the analysis (discrepancy/imu_analysis.hpp).
//
// Truth motion (earth frame W = ENU, z up, magnetic north on +y):
//   rest (movement = 0) for rest_s, then motion (movement = 1) for motion_s, repeated
//   motion_segments times, ending with a rest. In a motion segment of length T starting at t_0,
//   s = t − t_0, window w(s) = sin²(π s / T):
//     ω_I,i(t) = w(s) Σ_j A_ij sin(2π f_ij s + φ_ij)      angular rate in the IMU frame [rad/s]
//     a_W,i(t) = w(s) (Σ_j B_ij sin(2π g_ij s + ψ_ij) − c_i)   linear acceleration (effect only)
//   with 3 harmonics per axis, f, g uniform in [0.2, 1.2] Hz, phases uniform, A scaled so that
//   Σ_j |A_ij| = max_rate (B: Σ_j |B_ij| = linear_accel); c_i = (2/T) ∫ w Σ_j B_ij sin(…) ds
//   makes the segment's net velocity change zero, so the tool is still again at every rest.
//   R_WI(t) is integrated from ω_I with exact exponential steps of h = 1/(rate·substeps),
//   q̇ = ½ q ⊗ [0, ω_I]; the position p_W (0 at the start) from a_W on the same grid (midpoint
//   velocity, trapezoid position).
// IMU (ImuModel, settings.imu with g_W = [0, 0, −g], m_W in ENU [µT]):
//   gyro ω_S = ω_I(t − τ) + b_c + b_rw(t) + n_g      (b_c: the constant bias of settings.imu)
//   acc  f_S = R_WI(t − τ − δ)ᵀ (a_W(t − τ − δ) − g_W) + n_a
//   mag  m_S = R_WI(t − τ)ᵀ (m_W + d_W(t − τ)) + n_m
// Effects (ImuStreamEffects, all off by default — the base model the analysis fits):
//   gyro_bias_random_walk σ_b,i [rad/s/√s] per axis: b_rw,k = b_rw,k−1 + σ_b √Δt ν_k;
//   magnetic disturbance: d_W = mag_disturbance_uT over [start, end) of the stream clock, else 0;
//   linear_accel [m/s²]: a_W as above during motion (0 when off: rotation about the sensor);
//   time_offset τ [s]: the IMU sample stamped t measures the motion the truth shows at t − τ
//   (τ > 0: the IMU stamps late);
//   accel_delay δ [s]: the accelerometer alone reads δ later still (a MEMS accelerometer's
//   internal low-pass; estimation::PositionKfSettings::accel_delay takes it out).
// The position p_W [m] of each row is the truth's at its stamp t (a tracker on the truth clock).
// Every draw comes from the caller's std::mt19937_64: the same settings, effects and generator
// state give the same stream.
#pragma once

#include <Eigen/Core>
#include <random>
#include <vector>

#include "rcal/sim/imu_model.hpp"

namespace rcal::sim {

struct ImuStreamSettings {
  double rate_hz = 100.0;   ///< sample rate [Hz]
  int motion_segments = 3;  ///< number of motion segments (a rest before, between, after)
  double rest_s = 20.0;     ///< length of each rest segment [s]
  double motion_s = 20.0;   ///< length of each motion segment [s]
  double max_rate = 2.0;    ///< peak |ω| per axis in motion [rad/s]
  int substeps = 10;        ///< integration steps per sample [-]
  double gravity = 9.81;    ///< [m/s²]
  /// Earth field in ENU [µT] (|m| ≈ 48 µT, dip ≈ 65°).
  Eigen::Vector3d m_W_uT = Eigen::Vector3d(0.0, 20.0, -44.0);
  /// Initial orientation IMU → ENU [w, x, y, z].
  Eigen::Vector4d q0_WI = Eigen::Vector4d(1.0, 0.0, 0.0, 0.0);
  /// Noise densities and the constant bias (the base model). g_W, m_W and rate_hz are
  /// overwritten from the fields above.
  ImuModelSettings imu;
};

struct ImuStreamEffects {
  /// Gyro bias random walk per axis [rad/s/√s]; zero: constant bias only.
  Eigen::Vector3d gyro_bias_random_walk = Eigen::Vector3d::Zero();
  bool mag_disturbance = false;
  double mag_disturbance_start_s = 0.0;  ///< [s]
  double mag_disturbance_end_s = 0.0;    ///< [s]
  /// Disturbance field added in the earth frame [µT].
  Eigen::Vector3d mag_disturbance_uT = Eigen::Vector3d(10.0, 0.0, 0.0);
  double linear_accel = 0.0;   ///< Σ of harmonic amplitudes per axis during motion [m/s²]
  double time_offset_s = 0.0;  ///< τ [s], see the header comment
  double accel_delay_s = 0.0;  ///< δ [s], see the header comment
};

/// One row of the BROAD layout.
struct ImuStreamSample {
  double t = 0.0;                                        ///< [s]
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();        ///< [rad/s]
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();       ///< specific force [m/s²]
  Eigen::Vector3d mag_uT = Eigen::Vector3d::Zero();      ///< [µT]
  Eigen::Vector4d q_WI = Eigen::Vector4d(1.0, 0, 0, 0);  ///< truth IMU → ENU [w,x,y,z]
  int movement = 0;                                      ///< 1 in motion segments
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();   ///< truth total gyro bias [rad/s]
  Eigen::Vector3d p_W = Eigen::Vector3d::Zero();         ///< truth IMU position, ENU [m]
};

/// Simulates the stream; see the header comment.
std::vector<ImuStreamSample> SimulateImuStream(const ImuStreamSettings& settings,
                                               const ImuStreamEffects& effects,
                                               std::mt19937_64& rng);

}  // namespace rcal::sim
