// The accelerometer's lag measured from a recording (accel_lag.hpp): an analytic truth of a fast
// tool whose IMU sits off the marker and reads late, a 20 Hz tracker with noise; the estimate
// against the lag, lever arm and bias put in, its σ against the spread over seeds, taps, and
// refused input.
#include "rcal/estimation/accel_lag.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "rcal/geometry/so3.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::estimation {
namespace {

constexpr double kG = 9.81;

struct Truth {
  double delay = 0.003;  // [s]
  Eigen::Vector3d r_B{0.02, -0.01, 0.03};
  Eigen::Vector3d bias_W{0.05, -0.03, 0.0};  // a tilt error's share [m/s²]
  double tracker_sigma = 1e-3;               // [m] per axis
  double taps = 0.0;  // [m/s²] on one accelerometer sample every 2 s (0: none)
  bool still = false;
};

Eigen::Matrix3d R_of(double t, bool still) {
  if (still) return geometry::FromRpy(0.1, -0.2, 0.3);
  return geometry::FromRpy(0.5 * std::sin(3.0 * t), 0.3 * std::sin(2.5 * t + 1.0), 1.5 * t);
}

// The marker's position and acceleration in W = E (ENU): sinusoids of 1.1–1.8 Hz, up to 11 m/s².
void Marker(double t, bool still, Eigen::Vector3d* p, Eigen::Vector3d* a) {
  const Eigen::Vector3d amp(0.09, 0.06, 0.05), w(7.0, 9.0, 11.0), phase(0.3, 1.1, -0.4);
  for (int i = 0; i < 3; ++i) {
    (*p)(i) = still ? 0.0 : amp(i) * std::sin(w(i) * t + phase(i));
    (*a)(i) = still ? 0.0 : -w(i) * w(i) * (*p)(i);
  }
}

// 60 s at 100 Hz: the IMU at p_I = p_M − R r_B reads f_B(t − δ) = R(t − δ)ᵀ (p̈_I(t − δ) + g up) +
// b (turned into the body) + noise; R_EB and ω_B are the truth's at the stamp (R̈ and Ṙ by
// central differences of the analytic R).
AccelLagData Record(const Truth& truth, std::uint64_t seed) {
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
    if (k % 5 == 0) {
      Marker(t, truth.still, &p, &a);
      d.t_position.push_back(t);
      d.p_WM_W.push_back(p + truth.tracker_sigma * sim::Draw3(N, rng));
    }
  }
  return d;
}

AccelLagSettings Enu() {
  AccelLagSettings s;
  s.earth = EarthFrame::kEnu;
  return s;
}

// Eight seeds: δ, r_B and b_W found; the jackknife σ matches the spread of the estimates.
TEST(AccelLag, FindsTheLagLeverArmAndBiasOfAFastTool) {
  const Truth truth;
  double z2 = 0.0, worst = 0.0;
  const int seeds = 8;
  for (int seed = 1; seed <= seeds; ++seed) {
    const auto e = EstimateAccelLag(Record(truth, static_cast<std::uint64_t>(seed)), Enu());
    ASSERT_TRUE(e.ok()) << e.error();
    std::printf(
        "seed %d: lag %.3f ± %.3f ms (true 3), lever arm [%.1f %.1f %.1f] mm, bias [%.3f %.3f "
        "%.3f] m/s², %d triplets, residual %.2f m/s²\n",
        seed, e->delay * 1e3, e->delay_sigma * 1e3, e->lever_arm_B.x() * 1e3,
        e->lever_arm_B.y() * 1e3, e->lever_arm_B.z() * 1e3, e->bias_W.x(), e->bias_W.y(),
        e->bias_W.z(), e->triplets, e->residual_rms);
    EXPECT_NEAR(e->delay, truth.delay, 3e-4);
    EXPECT_LT((e->lever_arm_B - truth.r_B).norm(), 5e-3);
    EXPECT_LT((e->bias_W - truth.bias_W).norm(), 0.05);
    EXPECT_GT(e->triplets, 1100);
    const double z = (e->delay - truth.delay) / e->delay_sigma;
    z2 += z * z;
    worst = std::max(worst, std::abs(z));
  }
  const double z_rms = std::sqrt(z2 / seeds);
  std::printf("(estimate − truth) / σ: RMS %.2f, worst %.2f over %d seeds\n", z_rms, worst, seeds);
  EXPECT_GT(z_rms, 0.3);  // σ is neither far too large…
  EXPECT_LT(z_rms, 2.0);  // …nor far too small (the linearisation in δ leaves ~0.1 ms)
}

// Taps (60 m/s² on one sample every 2 s, BROAD's tapping trial) would pull a plain least-squares
// fit; the Huber weights keep the lag.
TEST(AccelLag, TapsDoNotPullTheLag) {
  Truth truth;
  truth.taps = 60.0;
  const auto e = EstimateAccelLag(Record(truth, 3), Enu());
  ASSERT_TRUE(e.ok()) << e.error();
  std::printf("with taps: lag %.3f ± %.3f ms (true 3)\n", e->delay * 1e3, e->delay_sigma * 1e3);
  EXPECT_NEAR(e->delay, truth.delay, 3e-4);
}

// Without the lag the estimate is zero within its σ (the lever arm is not mistaken for it).
TEST(AccelLag, NoLagReadsZero) {
  Truth truth;
  truth.delay = 0.0;
  const auto e = EstimateAccelLag(Record(truth, 5), Enu());
  ASSERT_TRUE(e.ok()) << e.error();
  EXPECT_LT(std::abs(e->delay), std::max(3.0 * e->delay_sigma, 1e-4));
}

TEST(AccelLag, RefusesWhatCannotGiveALag) {
  const AccelLagData good = Record(Truth{}, 1);
  {
    AccelLagData d = good;
    d.f_B[100].x() = std::nan("");
    const auto e = EstimateAccelLag(d, Enu());
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.error().find("f_B [100]"), std::string::npos) << e.error();
  }
  {
    AccelLagData d = good;
    d.t_position[7] = d.t_position[6];
    const auto e = EstimateAccelLag(d, Enu());
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.error().find("t_position [7]"), std::string::npos) << e.error();
  }
  {
    AccelLagData d = good;
    d.omega_B.pop_back();
    EXPECT_FALSE(EstimateAccelLag(d, Enu()).ok());
  }
  {
    AccelLagData d = good;
    d.t_position.resize(40);
    d.p_WM_W.resize(40);
    const auto e = EstimateAccelLag(d, Enu());
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.error().find("usable position triplets"), std::string::npos) << e.error();
  }
  {
    Truth still;
    still.still = true;
    const auto e = EstimateAccelLag(Record(still, 1), Enu());
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.error().find("does not determine"), std::string::npos) << e.error();
  }
}

}  // namespace
}  // namespace rcal::estimation
