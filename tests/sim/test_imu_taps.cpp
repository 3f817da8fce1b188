// Taps on the IMU: their rate, kinds, amplitudes, ringing decay and directions against the
// settings' closed forms; seeding.
#include "rcal/sim/imu_taps.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace rcal::sim {
namespace {

// One tap as the samples show it: start time, samples it touched, |f| of each.
struct SeenTap {
  double t = 0.0;
  bool ringing = false;
  std::vector<double> magnitude, age;
  std::vector<Eigen::Vector3d> direction;
};

std::vector<SeenTap> Record(ImuTaps& taps, double duration, double rate_hz) {
  std::vector<SeenTap> seen;
  int started = 0, ringing = 0;
  for (int k = 0; k * (1.0 / rate_hz) < duration; ++k) {
    const double t = k / rate_hz;
    const Eigen::Vector3d f = taps.At(t);
    if (taps.taps() > started) {  // a tap began at this sample
      seen.push_back({t, taps.ringing() > ringing, {}, {}, {}});
      started = taps.taps();
      ringing = taps.ringing();
      EXPECT_GT(f.norm(), 0.0) << "t " << t;
    }
    if (f.isZero()) continue;
    EXPECT_FALSE(seen.empty()) << "a tap before any began, t " << t;
    if (seen.empty()) continue;
    seen.back().magnitude.push_back(f.norm());
    seen.back().age.push_back(t - seen.back().t);
    seen.back().direction.push_back(f.normalized());
  }
  return seen;
}

TEST(ImuTaps, TapsComeAtTheMeanGapWithTheirAmplitudesAndKinds) {
  const ImuTapsSettings s;  // 2 s mean gap, 30–70 m/s², half ringing for 80 ms, τ 40 ms
  ImuTaps taps(7, s);
  const double duration = 4000.0;
  const std::vector<SeenTap> seen = Record(taps, duration, 100.0);
  const double n = static_cast<double>(seen.size());
  // Poisson count over (duration − first_after) / mean_gap = 1999.5 expected: within 4σ.
  EXPECT_NEAR(n, (duration - s.first_after) / s.mean_gap, 4.0 * std::sqrt(2000.0));
  ASSERT_GT(n, 1000.0);
  EXPECT_GE(seen.front().t, s.first_after);
  int ringing = 0, cos_n = 0;
  double amplitude_sum = 0.0, cos_sum = 0.0;
  Eigen::Vector3d direction_sum = Eigen::Vector3d::Zero();
  for (size_t j = 0; j < seen.size(); ++j) {
    const SeenTap& tap = seen[j];
    const double A = tap.magnitude.front();
    EXPECT_GE(A, s.min_amplitude);
    EXPECT_LE(A, s.max_amplitude);
    amplitude_sum += A;
    direction_sum += tap.direction.front();
    if (!tap.ringing) {
      EXPECT_EQ(tap.magnitude.size(), 1u) << "a one-sample tap at " << tap.t;
      continue;
    }
    ++ringing;
    // 80 ms at 100 Hz: the samples at ages 0 … 70 ms (80 ms itself may round either side), or
    // up to the next tap's start when it comes sooner.
    const double until = j + 1 < seen.size() ? seen[j + 1].t - tap.t : 1.0;
    if (until > s.ringing_duration + 0.005) {
      EXPECT_GE(tap.magnitude.size(), 8u) << tap.t;
      EXPECT_LE(tap.magnitude.size(), 9u) << tap.t;
    } else {
      EXPECT_EQ(tap.magnitude.size(), static_cast<size_t>(std::lround(until * 100.0))) << tap.t;
    }
    for (size_t i = 0; i < tap.magnitude.size(); ++i)
      EXPECT_NEAR(tap.magnitude[i], A * std::exp(-tap.age[i] / s.ringing_decay), 1e-9);
    // A new direction at each sample, as aliased ringing: |cos| of consecutive ones is uniform
    // on [0, 1] for independent uniform directions.
    for (size_t i = 1; i < tap.direction.size(); ++i) {
      cos_sum += std::abs(tap.direction[i - 1].dot(tap.direction[i]));
      ++cos_n;
    }
  }
  // Half of them ring, and the amplitude is uniform on [30, 70] (mean 50, σ 40/√12): 4σ bounds.
  EXPECT_NEAR(ringing / n, s.ringing_probability, 4.0 * std::sqrt(0.25 / n));
  EXPECT_NEAR(amplitude_sum / n, 50.0, 4.0 * (40.0 / std::sqrt(12.0)) / std::sqrt(n));
  ASSERT_GT(cos_n, 1000);
  EXPECT_NEAR(cos_sum / cos_n, 0.5, 4.0 * std::sqrt(1.0 / 12.0 / cos_n));
  // Uniform directions: the mean unit vector is 0 within 4σ (each component's σ is 1/√(3n), so
  // its norm's scale is √3 of that, 1/√n).
  EXPECT_LT(direction_sum.norm() / n, 4.0 / std::sqrt(n));
}

TEST(ImuTaps, TheSeedMakesTheTaps) {
  ImuTaps a(3), b(3), c(4);
  bool differ = false;
  for (int k = 0; k < 3000; ++k) {
    const double t = 0.01 * k;
    const Eigen::Vector3d fa = a.At(t), fb = b.At(t), fc = c.At(t);
    EXPECT_EQ(fa, fb) << t;
    differ |= fa != fc;
  }
  EXPECT_GT(a.taps(), 0);
  EXPECT_TRUE(differ);
}

TEST(ImuTaps, ATapStillRingingIsCutShortByTheNext) {
  ImuTapsSettings s;
  s.mean_gap = 0.03;  // gaps shorter than the ringing
  s.ringing_probability = 1.0;
  ImuTaps taps(11, s);
  const std::vector<SeenTap> seen = Record(taps, 60.0, 100.0);
  ASSERT_GT(seen.size(), 100u);
  for (size_t i = 0; i + 1 < seen.size(); ++i)
    for (double age : seen[i].age) EXPECT_LT(seen[i].t + age, seen[i + 1].t + 1e-12);
}

}  // namespace
}  // namespace rcal::sim
