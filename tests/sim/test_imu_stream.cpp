// Simulated IMU streams (sim/imu_stream.hpp): the truth is self-consistent and every switchable
// effect is there with the size asked for, checked against independent computations.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "rcal/geometry/so3.hpp"
#include "rcal/sim/imu_stream.hpp"

namespace {

using rcal::geometry::Log;
using rcal::geometry::QuatToMatrix;
namespace sim = rcal::sim;

sim::ImuStreamSettings Quiet() {
  sim::ImuStreamSettings s;
  s.motion_segments = 2;
  s.rest_s = 5.0;
  s.motion_s = 6.0;
  s.imu.white_noise = false;
  return s;
}

TEST(ImuStream, LayoutAndTruthAreConsistent) {
  std::mt19937_64 rng(1);
  const auto s = sim::SimulateImuStream(Quiet(), {}, rng);
  ASSERT_EQ(s.size(), 2700u);  // (5 + 2·(6 + 5)) s at 100 Hz
  EXPECT_EQ(s[0].movement, 0);
  EXPECT_EQ(s[600].movement, 1);   // 6 s: first motion segment
  EXPECT_EQ(s[1200].movement, 0);  // 12 s: second rest
  double max_rate_err = 0.0, max_f_err = 0.0, max_m_err = 0.0;
  for (size_t k = 1; k + 1 < s.size(); ++k) {
    // Gyro (noise off) = the truth quaternion's body rate over the interval ending at k.
    const Eigen::Vector3d w =
        Log(QuatToMatrix(s[k - 1].q_WI).transpose() * QuatToMatrix(s[k].q_WI)) / 0.01;
    max_rate_err = std::max(max_rate_err, (w - s[k].gyro).norm());
    // Specific force = gravity (up in ENU) in the body; field of constant norm and dip.
    const Eigen::Matrix3d R = QuatToMatrix(s[k].q_WI);
    max_f_err = std::max(max_f_err, (R * s[k].accel - Eigen::Vector3d(0, 0, 9.81)).norm());
    max_m_err = std::max(max_m_err, (R * s[k].mag_uT - Quiet().m_W_uT).norm());
  }
  EXPECT_LT(max_rate_err, 1e-9);
  EXPECT_LT(max_f_err, 1e-9);
  EXPECT_LT(max_m_err, 1e-9);
  EXPECT_LT(s[300].gyro.norm(), 1e-12);  // at rest
}

// The orientation filters integrate a gyro sample as the rate over the interval that ends at it,
// q_k = q_{k−1} Exp(ω_k Δt). Integrated so from the first sample, the noise-free simulated gyro
// must stay on the truth's attitude; the rate at the instant of each sample (the truth's central
// difference) drifts off it by the rate's change over half a sample, which is what put filters
// fed by the simulator half a sample ahead of its truth before the gyro was made interval-averaged.
TEST(ImuStream, TheFiltersIntervalRuleIntegratesTheGyroOntoTheTruth) {
  std::mt19937_64 rng(3);
  sim::ImuStreamSettings q = Quiet();
  q.max_rate = 4.0;
  const auto s = sim::SimulateImuStream(q, {}, rng);
  Eigen::Matrix3d R_interval = QuatToMatrix(s[0].q_WI), R_instant = R_interval;
  double err_interval = 0.0, err_instant = 0.0, max_rate = 0.0;
  for (size_t k = 1; k + 1 < s.size(); ++k) {
    R_interval = R_interval * rcal::geometry::Exp(s[k].gyro * 0.01);
    const Eigen::Vector3d w_instant =
        Log(QuatToMatrix(s[k - 1].q_WI).transpose() * QuatToMatrix(s[k + 1].q_WI)) / 0.02;
    R_instant = R_instant * rcal::geometry::Exp(w_instant * 0.01);
    const Eigen::Matrix3d R_WI = QuatToMatrix(s[k].q_WI);
    err_interval = std::max(err_interval, Log(R_WI.transpose() * R_interval).norm());
    err_instant = std::max(err_instant, Log(R_WI.transpose() * R_instant).norm());
    max_rate = std::max(max_rate, s[k].gyro.norm());
  }
  EXPECT_GT(max_rate, 2.0);       // fast enough for half a sample to matter
  EXPECT_LT(err_interval, 1e-9);  // [rad] rounding over 2700 samples
  EXPECT_GT(err_instant, 1e-3);   // the instant's rate: > 0.06° off
}

TEST(ImuStream, SameSeedSameStream) {
  std::mt19937_64 a(7), b(7), c(8);
  const auto sa = sim::SimulateImuStream(sim::ImuStreamSettings{}, {}, a);
  const auto sb = sim::SimulateImuStream(sim::ImuStreamSettings{}, {}, b);
  const auto sc = sim::SimulateImuStream(sim::ImuStreamSettings{}, {}, c);
  ASSERT_EQ(sa.size(), sb.size());
  for (size_t k = 0; k < sa.size(); k += 97) EXPECT_EQ(sa[k].gyro, sb[k].gyro);
  EXPECT_NE(sa[5000].gyro, sc[5000].gyro);
}

TEST(ImuStream, EffectsHaveTheirSize) {
  // Magnetic disturbance: the field changes by exactly d_W over its interval.
  sim::ImuStreamEffects e;
  e.mag_disturbance = true;
  e.mag_disturbance_start_s = 7.0;
  e.mag_disturbance_end_s = 9.0;
  e.mag_disturbance_uT = Eigen::Vector3d(3.0, -4.0, 0.0);
  std::mt19937_64 rng(2);
  const auto s = sim::SimulateImuStream(Quiet(), e, rng);
  for (size_t k : {650u, 850u, 950u}) {
    const Eigen::Vector3d m_W = QuatToMatrix(s[k].q_WI) * s[k].mag_uT;
    const bool in = s[k].t >= 7.0 && s[k].t < 9.0;
    EXPECT_NEAR((m_W - Quiet().m_W_uT).norm(), in ? 5.0 : 0.0, 1e-9) << s[k].t;
  }
  // Linear acceleration only during motion, bounded by its amplitude.
  sim::ImuStreamEffects la;
  la.linear_accel = 2.0;
  std::mt19937_64 rng2(3);
  const auto s2 = sim::SimulateImuStream(Quiet(), la, rng2);
  double max_rest = 0.0, max_motion = 0.0;
  for (const auto& r : s2) {
    const double a = (QuatToMatrix(r.q_WI) * r.accel - Eigen::Vector3d(0, 0, 9.81)).norm();
    (r.movement ? max_motion : max_rest) = std::max(r.movement ? max_motion : max_rest, a);
  }
  EXPECT_LT(max_rest, 1e-9);
  EXPECT_GT(max_motion, 0.5);
  // |a_i| ≤ Σ|B| + |c_i| and |c_i| ≤ Σ|B| (c_i is a w-weighted mean of Σ B sin(…)).
  EXPECT_LE(max_motion, 2.0 * 2.0 * std::sqrt(3.0) + 1e-9);
  // Time offset: the gyro at t equals the offset-free gyro at t − τ (τ = 3 samples).
  sim::ImuStreamEffects to;
  to.time_offset_s = 0.03;
  std::mt19937_64 r3(4), r4(4);
  const auto shifted = sim::SimulateImuStream(Quiet(), to, r3);
  const auto plain = sim::SimulateImuStream(Quiet(), {}, r4);
  for (size_t k = 600; k < 1100; k += 37) {
    EXPECT_LT((shifted[k].gyro - plain[k - 3].gyro).norm(), 1e-9);
    EXPECT_LT((shifted[k].q_WI - plain[k].q_WI).norm(), 1e-12);  // truth is not shifted
  }
}

TEST(ImuStream, PositionsIntegrateTheAccelerationAndAreStillAtRest) {
  sim::ImuStreamEffects la;
  la.linear_accel = 3.0;
  std::mt19937_64 rng(5);
  const auto s = sim::SimulateImuStream(Quiet(), la, rng);
  const double dt = 0.01;
  // Numerov: p(k+1) − 2 p(k) + p(k−1) = dt²/12 (a(k+1) + 10 a(k) + a(k−1)) + O(dt⁶), with a the
  // linear acceleration the (noise-free) accelerometer shows: R_WI f − g up.
  auto a_W = [&](size_t k) {
    return Eigen::Vector3d(QuatToMatrix(s[k].q_WI) * s[k].accel - Eigen::Vector3d(0, 0, 9.81));
  };
  double max_err = 0.0, max_a = 0.0;
  for (size_t k = 1; k + 1 < s.size(); ++k) {
    const Eigen::Vector3d dd = (s[k + 1].p_W - 2.0 * s[k].p_W + s[k - 1].p_W) / (dt * dt);
    const Eigen::Vector3d numerov = (a_W(k + 1) + 10.0 * a_W(k) + a_W(k - 1)) / 12.0;
    max_err = std::max(max_err, (dd - numerov).norm());
    max_a = std::max(max_a, a_W(k).norm());
  }
  EXPECT_GT(max_a, 1.0);
  EXPECT_LT(max_err, 1e-4);
  // Still at every rest: each motion segment ends with no net velocity (c_i).
  for (auto [b, e] : {std::pair{0, 499}, std::pair{1101, 1599}, std::pair{2201, 2699}})
    EXPECT_LT((s[e].p_W - s[b].p_W).norm(), 1e-5) << b;
  EXPECT_GT((s[1101].p_W - s[499].p_W).norm(), 1e-3);  // it did move
}

TEST(ImuStream, TheAccelerometersDelayShiftsItAlone) {
  // δ = one sample period, noise off: the accelerometer at k reads the delay-free one at k − 1,
  // the gyro, field, truth and positions are unchanged.
  sim::ImuStreamEffects plain_e, late_e;
  plain_e.linear_accel = late_e.linear_accel = 3.0;
  late_e.accel_delay_s = 0.01;
  std::mt19937_64 r1(6), r2(6);
  const auto plain = sim::SimulateImuStream(Quiet(), plain_e, r1);
  const auto late = sim::SimulateImuStream(Quiet(), late_e, r2);
  ASSERT_EQ(plain.size(), late.size());
  double max_shift = 0.0, max_unshifted = 0.0, max_other = 0.0;
  for (size_t k = 1; k < plain.size(); ++k) {
    max_shift = std::max(max_shift, (late[k].accel - plain[k - 1].accel).norm());
    max_unshifted = std::max(max_unshifted, (late[k].accel - plain[k].accel).norm());
    max_other =
        std::max({max_other, (late[k].gyro - plain[k].gyro).norm(),
                  (late[k].mag_uT - plain[k].mag_uT).norm(), (late[k].p_W - plain[k].p_W).norm()});
  }
  EXPECT_LT(max_shift, 1e-6);
  EXPECT_GT(max_unshifted, 0.05);  // the delay is visible
  EXPECT_LT(max_other, 1e-6);
  sim::ImuStreamEffects bad;
  bad.accel_delay_s = std::nan("");
  std::mt19937_64 r3(1);
  EXPECT_THROW(sim::SimulateImuStream(Quiet(), bad, r3), std::invalid_argument);
}

TEST(ImuStream, GyroBiasRandomWalkHasItsRate) {
  // Increments of the walk over 1 s have σ = K·√1 s, on the chosen axis only.
  sim::ImuStreamSettings st;
  st.motion_segments = 0;
  st.rest_s = 400.0;
  sim::ImuStreamEffects e;
  e.gyro_bias_random_walk = Eigen::Vector3d(0.0, 2e-4, 0.0);
  std::mt19937_64 rng(5);
  const auto s = sim::SimulateImuStream(st, e, rng);
  double sum = 0.0;
  int n = 0;
  for (size_t k = 100; k < s.size(); k += 100, ++n) {
    const Eigen::Vector3d d = s[k].gyro_bias - s[k - 100].gyro_bias;
    EXPECT_EQ(d.x(), 0.0);
    EXPECT_EQ(d.z(), 0.0);
    sum += d.y() * d.y();
  }
  const double sigma = std::sqrt(sum / n);
  EXPECT_NEAR(sigma, 2e-4, 2e-4 * 4.0 / std::sqrt(2.0 * n));  // ±4σ of a σ estimate from n
}

}  // namespace
