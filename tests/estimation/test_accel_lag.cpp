// The accelerometer's lag measured from a recording (accel_lag.hpp): an analytic truth of a fast
// tool whose IMU sits off the marker and reads late, a 20 Hz tracker with noise; the estimate
// against the lag, lever arm and bias put in, its σ against the spread over seeds, taps, and
// refused input.
#include "rcal/estimation/accel_lag.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

#include "lagged_tool.hpp"

namespace rcal::estimation {
namespace {

AccelLagSettings Enu() {
  AccelLagSettings s;
  s.earth = EarthFrame::kEnu;
  return s;
}

// Eight seeds: δ, r_B and b_W found; the jackknife σ matches the spread of the estimates.
TEST(AccelLag, FindsTheLagLeverArmAndBiasOfAFastTool) {
  const lagged::Truth truth;
  double z2 = 0.0, worst = 0.0;
  const int seeds = 8;
  for (int seed = 1; seed <= seeds; ++seed) {
    const auto e = EstimateAccelLag(lagged::Record(truth, static_cast<std::uint64_t>(seed)), Enu());
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
  lagged::Truth truth;
  truth.taps = 60.0;
  const auto e = EstimateAccelLag(lagged::Record(truth, 3), Enu());
  ASSERT_TRUE(e.ok()) << e.error();
  std::printf("with taps: lag %.3f ± %.3f ms (true 3)\n", e->delay * 1e3, e->delay_sigma * 1e3);
  EXPECT_NEAR(e->delay, truth.delay, 3e-4);
}

// Without the lag the estimate is zero within its σ (the lever arm is not mistaken for it).
TEST(AccelLag, NoLagReadsZero) {
  lagged::Truth truth;
  truth.delay = 0.0;
  const auto e = EstimateAccelLag(lagged::Record(truth, 5), Enu());
  ASSERT_TRUE(e.ok()) << e.error();
  EXPECT_LT(std::abs(e->delay), std::max(3.0 * e->delay_sigma, 1e-4));
}

TEST(AccelLag, RefusesWhatCannotGiveALag) {
  const AccelLagData good = lagged::Record(lagged::Truth{}, 1);
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
    lagged::Truth still;
    still.still = true;
    const auto e = EstimateAccelLag(lagged::Record(still, 1), Enu());
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.error().find("does not determine"), std::string::npos) << e.error();
  }
}

// A tracker whose frame is only guessed (115° from the earth frame): asked to, the estimator finds
// the frame (closed-form alignment, then refined with the rest) and the lag as if it were given;
// taken as the identity, the lag is lost and the residual is several times larger.
TEST(AccelLag, FindsThePositionSensorsFrameWhenAsked) {
  lagged::Truth truth;
  truth.R_WE = Eigen::AngleAxisd(2.0, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const AccelLagData d = lagged::Record(truth, 4);
  AccelLagSettings s = Enu();
  s.estimate_R_WE = true;
  const auto e = EstimateAccelLag(d, s);
  ASSERT_TRUE(e.ok()) << e.error();
  EXPECT_TRUE(e->R_WE_estimated);
  const double angle_err = Eigen::AngleAxisd(e->R_WE * truth.R_WE.transpose()).angle();
  EXPECT_LT(angle_err, 0.2 * std::numbers::pi / 180.0)
      << angle_err * 180.0 / std::numbers::pi << " deg";
  EXPECT_NEAR(e->delay, truth.delay, std::max(3.0 * e->delay_sigma, 3e-4));
  EXPECT_LT((e->lever_arm_B - truth.r_B).norm(), 5e-3);
  // The same data given the true frame: the same lag.
  AccelLagSettings given = Enu();
  given.R_WE = truth.R_WE;
  const auto g = EstimateAccelLag(d, given);
  ASSERT_TRUE(g.ok());
  EXPECT_FALSE(g->R_WE_estimated);
  EXPECT_NEAR(e->delay, g->delay, 2e-4);
  // Taken as the identity: the residual carries the turned acceleration.
  const auto wrong = EstimateAccelLag(d, Enu());
  ASSERT_TRUE(wrong.ok());
  EXPECT_GT(wrong->residual_rms, 3.0 * e->residual_rms);
  // A motion along one line cannot fix a frame.
  AccelLagData line = d;
  for (auto& p : line.p_WM_W) p = Eigen::Vector3d(p.x(), 0.0, 0.0);
  for (auto& f : line.f_B) f.setZero();
  const auto refused = EstimateAccelLag(line, s);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().find("frame"), std::string::npos) << refused.error();
}

// A 100 Hz tracker of 0.3 mm: second differences over its own 10 ms steps are mostly noise
// (√6 · 0.3 mm / (10 ms)² = 7 m/s²); taking each triplet's outer samples 50 ms away reads the lag
// several times better from the same samples.
TEST(AccelLag, AFastTrackersTripletsSpanTheStepAsked) {
  lagged::Truth truth;
  truth.position_every = 1;
  truth.tracker_sigma = 3e-4;
  const AccelLagData d = lagged::Record(truth, 6);
  AccelLagSettings near = Enu(), spread = Enu();
  spread.min_position_step = 0.05;
  const auto a = EstimateAccelLag(d, near), b = EstimateAccelLag(d, spread);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_NEAR(b->delay, truth.delay, std::max(3.0 * b->delay_sigma, 3e-4));
  EXPECT_LT(b->delay_sigma, 0.5 * a->delay_sigma) << a->delay_sigma << " vs " << b->delay_sigma;
  EXPECT_GT(b->triplets, 5000);  // every sample is a middle one, not one in five
  AccelLagSettings bad = Enu();
  bad.min_position_step = -1.0;
  EXPECT_FALSE(EstimateAccelLag(d, bad).ok());
}

}  // namespace
}  // namespace rcal::estimation
