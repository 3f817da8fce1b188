// An analytic truth for the accelerometer's lag (test_accel_lag.cpp here and in tests/tools): a
// fast tool whose IMU sits off the marker and reads late, with a 20 Hz tracker. Earth = world, ENU.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <random>

#include "rcal/estimation/accel_lag.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::estimation::lagged {

inline constexpr double kG = 9.81;

struct Truth {
  double delay = 0.003;  // [s]
  Eigen::Vector3d r_B{0.02, -0.01, 0.03};
  Eigen::Vector3d bias_W{0.05, -0.03, 0.0};  // a tilt error's share [m/s²]
  double tracker_sigma = 1e-3;               // [m] per axis
  double taps = 0.0;  // [m/s²] on one accelerometer sample every 2 s (0: none)
  bool still = false;
  int position_every = 5;  // the tracker reads every n-th IMU sample (5: 20 Hz)
  /// The tracker's frame W against E = ENU: its positions are R_WE p_E (the bias stays in E).
  Eigen::Matrix3d R_WE = Eigen::Matrix3d::Identity();
};

inline Eigen::Matrix3d R_of(double t, bool still) {
  if (still) return geometry::FromRpy(0.1, -0.2, 0.3);
  return geometry::FromRpy(0.5 * std::sin(3.0 * t), 0.3 * std::sin(2.5 * t + 1.0), 1.5 * t);
}

// The marker's position and acceleration in W = E (ENU): sinusoids of 1.1–1.8 Hz, up to 11 m/s².
inline void Marker(double t, bool still, Eigen::Vector3d* p, Eigen::Vector3d* a) {
  const Eigen::Vector3d amp(0.09, 0.06, 0.05), w(7.0, 9.0, 11.0), phase(0.3, 1.1, -0.4);
  for (int i = 0; i < 3; ++i) {
    (*p)(i) = still ? 0.0 : amp(i) * std::sin(w(i) * t + phase(i));
    (*a)(i) = still ? 0.0 : -w(i) * w(i) * (*p)(i);
  }
}

// 60 s at 100 Hz: the IMU at p_I = p_M − R r_B reads f_B(t − δ) = R(t − δ)ᵀ (p̈_I(t − δ) + g up) +
// b (turned into the body) + noise; R_EB and ω_B are the truth's at the stamp (R̈ and Ṙ by
// central differences of the analytic R).
inline AccelLagData Record(const Truth& truth, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> N(0.0, 1.0);
  AccelLagData d;
  const double h = 1e-4;
  const Eigen::Vector3d up(0, 0, 1);
  for (int k = 0; k < 6000; ++k) {
    const double t = k * 0.01, s = t - truth.delay;
    const Eigen::Matrix3d R = R_of(t, truth.still), Rs = R_of(s, truth.still);
    const Eigen::Matrix3d Rs_ddot =
        (R_of(s + h, truth.still) - 2 * Rs + R_of(s - h, truth.still)) / (h * h);
    Eigen::Vector3d p, a;
    Marker(s, truth.still, &p, &a);
    const Eigen::Vector3d a_I = a - Rs_ddot * truth.r_B;
    Eigen::Vector3d f_B =
        Rs.transpose() * (a_I + kG * up + truth.bias_W) + 6e-3 * sim::Draw3(N, rng);
    if (truth.taps != 0.0 && k % 200 == 137) f_B(k / 200 % 3) += truth.taps;
    const Eigen::Matrix3d W =
        R.transpose() * (R_of(t + h, truth.still) - R_of(t - h, truth.still)) / (2 * h);
    d.t_imu.push_back(t);
    d.f_B.push_back(f_B);
    d.R_EB.push_back(R);
    d.omega_B.push_back(Eigen::Vector3d(W(2, 1), W(0, 2), W(1, 0)));
    if (k % truth.position_every == 0) {
      Marker(t, truth.still, &p, &a);
      d.t_position.push_back(t);
      d.p_WM_W.push_back(truth.R_WE * p + truth.tracker_sigma * sim::Draw3(N, rng));
    }
  }
  return d;
}

}  // namespace rcal::estimation::lagged
