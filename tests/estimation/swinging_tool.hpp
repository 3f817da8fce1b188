// An analytic truth for the position KF's tests (test_position_kf.cpp, test_position_kf_bank.cpp):
// a tool swinging on three sinusoids while it turns, and what its accelerometer reads, with or
// without taps. Earth = world, ENU.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <random>

#include "rcal/estimation/position_kf.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::estimation::swing {

/// The marker's position p [m] and acceleration a [m/s²] in the world (= earth) frame, and the
/// orientation R_EB, at one time.
struct SwingState {
  Eigen::Vector3d p, a;
  Eigen::Matrix3d R_EB;
};

/// The tool at t [s]: p_i = amp_i sin(w_i t + φ_i) with w = (0.9, 1.7, 2.3) rad/s (|a| up to
/// amp · 5.3 m/s² per axis), turning about all three axes.
inline SwingState SwingingTool(double t, const Eigen::Vector3d& amp_m) {
  const Eigen::Vector3d w(0.9, 1.7, 2.3), phase(0.3, 1.1, -0.4);
  SwingState s;
  for (int i = 0; i < 3; ++i) {
    s.p(i) = amp_m(i) * std::sin(w(i) * t + phase(i));
    s.a(i) = -w(i) * w(i) * s.p(i);
  }
  s.R_EB = geometry::FromRpy(0.3 * std::sin(0.5 * t), 0.2, 0.4 * t);
  return s;
}

/// A tap: one 100 Hz sample (sample k) of 60 m/s² on one body axis in turn, every 2 s — what
/// BROAD's tapping trial shows.
inline bool IsTap(int k) {
  return k % 200 == 137;
}

/// The accelerometer's specific force f_B [m/s²] at sample k of the tool in state s: the body's own
/// acceleration times `scale` (1: a calibrated accelerometer) plus gravity, white noise of
/// `noise_sigma` [m/s²] per axis (one Draw3 from rng), and with `tapping` the tap of sample k.
inline Eigen::Vector3d Accelerometer(const SwingState& s, int k, bool tapping, double noise_sigma,
                                     std::normal_distribution<double>& N, std::mt19937_64& rng,
                                     double scale = 1.0) {
  constexpr double kG = 9.81;
  Eigen::Vector3d f_B = s.R_EB.transpose() * (scale * s.a + kG * UpVector(EarthFrame::kEnu)) +
                        noise_sigma * sim::Draw3(N, rng);
  if (tapping && IsTap(k)) f_B(k / 200 % 3) += 60.0;
  return f_B;
}

}  // namespace rcal::estimation::swing
