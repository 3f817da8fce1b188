// IMU-stream analysis (discrepancy/imu_analysis.hpp): each effect hidden in a simulated stream
// (sim/imu_stream.hpp) must be named with its axis, a clean stream must give no effect, and the
// gain must be positive and close to what the true model gets. Plus BROAD trial 30 (real data).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>
#include <sstream>
#include <string>

#include "rcal/discrepancy/imu_analysis.hpp"
#include "rcal/sim/imu_stream.hpp"

namespace {

namespace disc = rcal::discrepancy;
namespace sim = rcal::sim;

sim::ImuStreamSettings Short() {
  sim::ImuStreamSettings s;
  s.motion_segments = 3;
  s.rest_s = 15.0;
  s.motion_s = 15.0;
  s.imu.constant_bias = true;  // the base model allows a constant gyro bias
  s.imu.gyro_bias = Eigen::Vector3d(0.002, -0.001, 0.003);
  return s;
}

const disc::ImuCandidate& Cand(const disc::ImuAnalysis& a, const std::string& cause) {
  for (const auto& c : a.candidates)
    if (c.cause == cause) return c;
  throw std::runtime_error("no candidate " + cause);
}

std::vector<std::string> Causes(const disc::ImuAnalysis& a) {
  std::vector<std::string> v;
  for (const auto* c : a.effects()) v.push_back(c->cause);
  return v;
}

std::string Join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += x + " ";
  return s;
}

TEST(ImuAnalysis, CleanStreamsGiveNoEffect) {
  for (std::uint64_t seed : {1u, 2u, 3u, 4u}) {
    std::mt19937_64 rng(seed);
    const auto a =
        disc::AnalyzeImuStream(disc::FromSimulatedStream(sim::SimulateImuStream(Short(), {}, rng)));
    EXPECT_TRUE(a.effects().empty()) << "seed " << seed << ": " << Join(Causes(a));
    EXPECT_TRUE(a.has_truth);
    // The gyro keeps the truth's time: the rate over each interval read against the truth's rate
    // over the same interval, no lag (against the rate at the instant it would read Δt/2 = 5 ms).
    const auto& to = Cand(a, "time_offset");
    ASSERT_TRUE(to.tested);
    EXPECT_LT(std::abs(to.values[0].value), 0.1e-3) << "seed " << seed;
    // With nothing selected the extended model is the base model.
    EXPECT_DOUBLE_EQ(a.extended_score.total.value(), a.base_score.total.value());
    // The Allan white level matches the simulator's density (σ ~ 10 %).
    for (int i = 0; i < 3; ++i)
      EXPECT_NEAR(a.allan.white_level[i], sim::ImuModelSettings{}.gyro_noise_density,
                  0.25 * sim::ImuModelSettings{}.gyro_noise_density);
  }
}

TEST(ImuAnalysis, FindsAGyroBiasRandomWalkOnItsAxis) {
  int found = 0, runs = 0;
  for (double K : {2e-4, 3e-4}) {
    for (std::uint64_t seed : {11u, 12u}) {
      sim::ImuStreamEffects e;
      e.gyro_bias_random_walk = Eigen::Vector3d(0.0, 0.0, K);
      std::mt19937_64 rng(seed);
      const auto a = disc::AnalyzeImuStream(
          disc::FromSimulatedStream(sim::SimulateImuStream(Short(), e, rng)));
      const auto& c = Cand(a, "gyro_bias");
      ++runs;
      if (!c.significant) continue;
      ++found;
      EXPECT_EQ(c.axes, std::vector<std::string>{"z"}) << "K " << K << " seed " << seed;
      // Named unless its extension loses against the truth (issue 17). The fitted random-walk
      // extension does lose here (seed 11, K 2e-4: total 0.27° → 0.58°): detected, not named.
      EXPECT_EQ(Causes(a), c.loses_to_truth ? std::vector<std::string>{}
                                            : std::vector<std::string>{"gyro_bias"});
    }
  }
  EXPECT_EQ(found, runs) << "a 2e-4..3e-4 rad/s/√s walk on z is near but above the floor";
}

TEST(ImuAnalysis, GyroBiasGainIsPositiveAndCloseToTheTrueModel) {
  // A walk that the constant-bias filter cannot follow through a motion segment. (Near the
  // detection floor, 2e-4..5e-4, letting the filter's bias walk costs as much as it gains: the
  // true model itself does not beat the base filter there, so no gain is asserted.)
  for (std::uint64_t seed : {21u, 22u}) {
    sim::ImuStreamEffects e;
    e.gyro_bias_random_walk = Eigen::Vector3d(0.0, 0.0, 1e-3);
    std::mt19937_64 rng(seed);
    const auto d = disc::FromSimulatedStream(sim::SimulateImuStream(Short(), e, rng));
    const auto a = disc::AnalyzeImuStream(d);
    ASSERT_EQ(Causes(a), std::vector<std::string>{"gyro_bias"});
    EXPECT_LT(a.extended_score.total.value(), 0.9 * a.base_score.total.value()) << seed;
    // The true model: the same filter told the true walk.
    disc::ImuAnalysisSettings s;
    auto f = s.filter;
    f.reject_mag = f.reject_accel = false;
    f.gyro_bias_random_walk = 1e-3;
    const auto truth = disc::ScoreAgainstTruth(d, disc::RunOrientationFilter(d, f));
    EXPECT_LT(a.extended_score.total.value(), 1.3 * truth.total.value()) << seed;
  }
}

TEST(ImuAnalysis, FindsAMagneticDisturbanceAndGainsHeading) {
  int found = 0, runs = 0;
  for (double uT : {8.0, 15.0}) {
    for (std::uint64_t seed : {31u, 32u}) {
      sim::ImuStreamEffects e;
      e.mag_disturbance = true;
      e.mag_disturbance_start_s = 20.0;  // inside the first motion segment (15–30 s)
      e.mag_disturbance_end_s = 28.0;
      e.mag_disturbance_uT = Eigen::Vector3d(uT, 0.0, 0.0);
      std::mt19937_64 rng(seed);
      const auto stream = sim::SimulateImuStream(Short(), e, rng);
      const auto d = disc::FromSimulatedStream(stream);
      const auto a = disc::AnalyzeImuStream(d);
      ++runs;
      const auto& c = Cand(a, "magnetic_disturbance");
      if (!c.significant) continue;
      ++found;
      EXPECT_EQ(Causes(a), std::vector<std::string>{"magnetic_disturbance"}) << uT << " " << seed;
      EXPECT_EQ(c.axes, std::vector<std::string>{"magnetometer"});
      EXPECT_EQ(a.gain_metric, "heading");
      EXPECT_LT(c.after.heading.value(), c.before.heading.value()) << uT << " " << seed;
      // The true model: the same stream without the disturbance, base filter.
      std::mt19937_64 rng2(seed);
      const auto clean = disc::FromSimulatedStream(sim::SimulateImuStream(Short(), {}, rng2));
      const auto ideal = disc::AnalyzeImuStream(clean);
      EXPECT_LT(c.after.heading.value(), 2.0 * ideal.base_score.heading.value() + 2e-3)
          << uT << " " << seed;
    }
  }
  EXPECT_EQ(found, runs);
}

TEST(ImuAnalysis, FindsLinearAccelerationTheAccelModelIgnores) {
  for (double acc : {1.0, 3.0}) {
    sim::ImuStreamEffects e;
    e.linear_accel = acc;
    std::mt19937_64 rng(41);
    const auto a =
        disc::AnalyzeImuStream(disc::FromSimulatedStream(sim::SimulateImuStream(Short(), e, rng)));
    const auto& c = Cand(a, "accel_motion");
    EXPECT_TRUE(c.significant) << acc;
    EXPECT_EQ(c.axes, std::vector<std::string>{"accelerometer"});
    EXPECT_FALSE(Cand(a, "magnetic_disturbance").significant) << acc;
    EXPECT_FALSE(Cand(a, "time_offset").significant) << acc;
    // The gain of gating the accelerometer is measured against truth (not assumed positive).
    EXPECT_TRUE(std::isfinite(c.after.total.value()));
  }
}

TEST(ImuAnalysis, FindsATimeOffsetAndItsValue) {
  for (double tau : {0.01, 0.025, -0.015}) {
    sim::ImuStreamEffects e;
    e.time_offset_s = tau;
    std::mt19937_64 rng(51);
    const auto a =
        disc::AnalyzeImuStream(disc::FromSimulatedStream(sim::SimulateImuStream(Short(), e, rng)));
    const auto& c = Cand(a, "time_offset");
    ASSERT_TRUE(c.significant) << tau;
    // The whole IMU late is its accelerometer late too, behind the truth's attitude (positions
    // here: the IMU turns about itself): accel_lag reads the same τ.
    const auto& lag = Cand(a, "accel_lag");
    const std::vector<std::string> both{"time_offset", "accel_lag"};
    EXPECT_EQ(Causes(a), lag.named() ? both : std::vector<std::string>{"time_offset"}) << tau;
    if (lag.tested) {
      EXPECT_NEAR(lag.values[0].value, tau, 1e-3) << tau;
    }
    const double est = c.values[0].value, sigma = c.values[0].sigma;
    EXPECT_NEAR(est, tau, std::max(4.0 * sigma, 1e-3)) << "σ " << sigma;
    EXPECT_LT(sigma, 2e-3);
    // The gain of re-timing is measured against truth and must be positive from one sample on
    // (the simulated gyro is the rate over each interval, as the filter integrates it, so the
    // filter without the offset is late by the whole offset).
    std::printf("time offset %.0f ms: total %.4f -> %.4f rad\n", 1e3 * tau,
                a.base_score.total.value(), a.extended_score.total.value());
    EXPECT_LT(a.extended_score.total.value(), 0.5 * a.base_score.total.value()) << tau;
  }
}

// Whether an offset matters is judged by the attitude error it causes against the filter's own:
// the same small offset is named on a stream the base filter follows to a tenth of a degree, where
// re-timing gains, and not where 6 m/s² of linear acceleration tilts the filter by far more, where
// re-timing cannot gain. The measured cross-fitted gain (against the truth) must agree with the
// judgement either way.
TEST(ImuAnalysis, ASmallOffsetIsNamedWhereReTimingGainsAndNotWhereItCannot) {
  for (std::uint64_t seed : {52u, 53u}) {
    for (double linear_accel : {0.0, 6.0}) {
      sim::ImuStreamEffects e;
      e.time_offset_s = 0.002;
      e.linear_accel = linear_accel;
      std::mt19937_64 rng(seed);
      const auto a = disc::AnalyzeImuStream(
          disc::FromSimulatedStream(sim::SimulateImuStream(Short(), e, rng)));
      const auto& c = Cand(a, "time_offset");
      const double gain = 1.0 - c.after.total.value() / c.before.total.value();
      std::printf(
          "seed %d, linear accel %.0f m/s²: offset %.3f ms (z %.1f), base %.3f deg, "
          "expected gain %.3f, measured %.3f\n",
          static_cast<int>(seed), linear_accel, 1e3 * c.values[0].value, c.statistic,
          c.before.total.value() * 180.0 / std::numbers::pi, c.values.back().value, gain);
      EXPECT_NEAR(c.values[0].value, 0.002, 3e-4) << seed;
      // The quadrature rule predicts the measured gain.
      EXPECT_NEAR(c.values.back().value, gain, 0.05) << seed;
      EXPECT_GT(c.statistic, c.critical) << "measurable in both, seed " << seed;
      if (linear_accel == 0.0) {
        EXPECT_TRUE(c.named()) << seed << " " << c.note;
        EXPECT_GT(gain, 0.1) << seed;
      } else {
        EXPECT_FALSE(c.significant) << seed;
        EXPECT_NE(c.note.find("expected to gain"), std::string::npos) << c.note;
        EXPECT_LT(gain, 0.1) << seed;
      }
    }
  }
}

// The accelerometer reading late behind the positions (accel_lag): hidden in streams with linear
// acceleration whose positions an optical-grade tracker reads (0.1 mm), it is named with its size
// and the position KF with it is closer to the truth on the half of the stream it was not fitted
// on; without it nothing is named; without positions it is not tested.
disc::ImuStreamData Translating(double accel_delay, std::uint64_t seed) {
  sim::ImuStreamEffects e;
  e.linear_accel = 6.0;
  e.accel_delay_s = accel_delay;
  std::mt19937_64 rng(seed);
  auto d = disc::FromSimulatedStream(sim::SimulateImuStream(Short(), e, rng));
  std::normal_distribution<double> tracker(0.0, 1e-4);
  for (auto& p : d.p_W) p += Eigen::Vector3d(tracker(rng), tracker(rng), tracker(rng));
  return d;
}

TEST(ImuAnalysis, FindsTheAccelerometersLagBehindThePositions) {
  for (std::uint64_t seed : {31u, 32u, 33u}) {
    const auto a = disc::AnalyzeImuStream(Translating(0.005, seed));
    ASSERT_TRUE(a.has_positions);
    const auto& c = Cand(a, "accel_lag");
    ASSERT_TRUE(c.tested) << c.note;
    EXPECT_TRUE(c.named()) << "seed " << seed << " z " << c.statistic << " " << c.note;
    EXPECT_EQ(c.values[0].name, "accel_lag_s");
    const double est = c.values[0].value, sigma = c.values[0].sigma;
    EXPECT_NEAR(est, 0.005, std::max(4.0 * sigma, 2e-4)) << "seed " << seed << " σ " << sigma;
    EXPECT_LT(sigma, 2e-4);
    EXPECT_LT(c.position_after_m, 0.9 * c.position_before_m)
        << c.position_before_m << " → " << c.position_after_m;
    EXPECT_EQ(c.gain_metric(), "position");
    for (const auto& cause : Causes(a))
      EXPECT_TRUE(cause == "accel_lag" || cause == "accel_motion") << cause;
  }
}

TEST(ImuAnalysis, NoAccelerometerLagIsNotNamedAndNoPositionsNotTested) {
  for (std::uint64_t seed : {31u, 32u, 33u}) {
    auto d = Translating(0.0, seed);
    const auto a = disc::AnalyzeImuStream(d);
    const auto& c = Cand(a, "accel_lag");
    ASSERT_TRUE(c.tested) << c.note;
    EXPECT_FALSE(c.significant) << "seed " << seed << " z " << c.statistic << " lag "
                                << c.values[0].value;
    EXPECT_LT(std::abs(c.values[0].value), 2e-4) << "seed " << seed;
    d.p_W.clear();
    const auto b = disc::AnalyzeImuStream(d);
    EXPECT_FALSE(b.has_positions);
    EXPECT_FALSE(Cand(b, "accel_lag").tested);
    EXPECT_NE(Cand(b, "accel_lag").note.find("no positions"), std::string::npos);
    // Without positions the other four are tested at α/4 as before, with them at α/5.
    EXPECT_LT(Cand(b, "accel_motion").critical, Cand(a, "accel_motion").critical);
  }
}

TEST(ImuAnalysis, NoTruthMeansNoGainAndNoTimeOffset) {
  std::mt19937_64 rng(61);
  auto d = disc::FromSimulatedStream(sim::SimulateImuStream(Short(), {}, rng));
  d.q_truth.clear();
  const auto a = disc::AnalyzeImuStream(d);
  EXPECT_FALSE(a.has_truth);
  EXPECT_FALSE(Cand(a, "time_offset").tested);
  EXPECT_EQ(a.base_score.total.n, 0);
}

TEST(ImuAnalysis, BadInputNamesTheRow) {
  std::mt19937_64 rng(71);
  auto d = disc::FromSimulatedStream(sim::SimulateImuStream(Short(), {}, rng));
  d.mag_uT[41].y() = std::nan("");
  try {
    disc::AnalyzeImuStream(d);
    FAIL() << "NaN accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("mag_x..mag_z not finite at row 42"), std::string::npos)
        << e.what();
  }
  // A position may be occluded (all NaN), never infinite or half there.
  auto q = disc::FromSimulatedStream(sim::SimulateImuStream(Short(), {}, rng));
  q.p_W[9] = Eigen::Vector3d(std::nan(""), 0.0, 0.0);
  q.p_W[10].setConstant(std::nan(""));
  try {
    disc::AnalyzeImuStream(q);
    FAIL() << "a half-NaN position accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("pos_x..pos_z neither finite nor all NaN at row 10"),
              std::string::npos)
        << e.what();
  }
  q.p_W[9].setConstant(std::nan(""));
  q.p_W[20].x() = std::numeric_limits<double>::infinity();
  EXPECT_THROW(disc::AnalyzeImuStream(q), std::invalid_argument);
  q.p_W.pop_back();
  EXPECT_THROW(disc::AnalyzeImuStream(q), std::invalid_argument);  // one row short
}

// Real data: BROAD trial 30 (a magnet near the path). Parsed here without rcal_io.
disc::ImuStreamData LoadBroad(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  disc::ImuStreamData d;
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::vector<double> v;
    std::string cell;
    while (std::getline(ss, cell, ',')) v.push_back(cell == "nan" ? std::nan("") : std::stod(cell));
    if (v.size() < 18) continue;
    d.t.push_back(v[0]);
    d.gyro.emplace_back(v[1], v[2], v[3]);
    d.accel.emplace_back(v[4], v[5], v[6]);
    d.mag_uT.emplace_back(v[7], v[8], v[9]);
    d.q_truth.emplace_back(v[10], v[11], v[12], v[13]);
    d.p_W.emplace_back(v[14], v[15], v[16]);
    d.movement.push_back(static_cast<int>(v[17]));
  }
  return d;
}

TEST(ImuAnalysis, BroadTrial30NamesTheMagneticDisturbanceAndGatingGainsHeading) {
  const auto d = LoadBroad(std::string(RCAL_SHARED_DIR) + "/data/broad/broad_30_100hz.csv");
  ASSERT_GT(d.t.size(), 10000u);
  const auto a = disc::AnalyzeImuStream(d);
  const auto& c = Cand(a, "magnetic_disturbance");
  EXPECT_TRUE(c.significant) << Join(Causes(a));
  EXPECT_LT(c.after.heading.value(), c.before.heading.value());
  EXPECT_EQ(a.gain_metric, "heading");
  EXPECT_LT(a.extended_score.heading.value(), a.base_score.heading.value());
}

// BROAD: the accelerometer reads 2.1–2.8 ms behind the optical truth on every trial (README).
// Trial 07 (fast rotation): named, and the position KF with it is closer on held-out halves.
// Trial 16 (fast translation): named too. Until the position KF reinstated the accelerometer
// samples its gate refused (stop 53), 5 s of violent shaking (55–62 s, |f| up to 97 m/s²) made
// the extension lose there (50–60 s: 2.0 → 12 mm; closer everywhere else): it was not named.
// Now it gains (1.30 → 1.25 mm), and a significant lag whose extension loses is the hand-set case
// of AnEffectWhoseExtensionLosesAgainstTheTruthIsNotNamed.
TEST(ImuAnalysis, BroadNamesTheAccelerometersLagWhereTakingItOutGains) {
  const std::string dir = std::string(RCAL_SHARED_DIR) + "/data/broad/";
  const auto a07 = disc::AnalyzeImuStream(LoadBroad(dir + "broad_07_100hz.csv"));
  const auto& c07 = Cand(a07, "accel_lag");
  EXPECT_TRUE(c07.named()) << c07.note;
  EXPECT_NEAR(c07.values[0].value, 2.5e-3, 0.5e-3);
  EXPECT_LT(c07.position_after_m, 0.8 * c07.position_before_m)
      << c07.position_before_m << " → " << c07.position_after_m;
  const auto a16 = disc::AnalyzeImuStream(LoadBroad(dir + "broad_16_100hz.csv"));
  const auto& c16 = Cand(a16, "accel_lag");
  EXPECT_TRUE(c16.significant);
  EXPECT_NEAR(c16.values[0].value, 2.5e-3, 0.5e-3);
  EXPECT_TRUE(c16.named()) << c16.note;
  EXPECT_LT(c16.position_after_m, c16.position_before_m)
      << c16.position_before_m << " → " << c16.position_after_m;
}

}  // namespace

// Issue 17, item 4: a significant candidate whose extension raises the error it acts on against
// the truth by more than 10 % is not named (BROAD trial 35: magnetic_disturbance named while its
// gate doubled the heading error). The RMSE are set by hand: heading 1° → 2° for the magnet,
// total 2° → 2.1° (within 10 %: gains nothing) for the gyro bias, and the position between the
// tracker's samples 1.2 → 1.5 mm for the accelerometer's lag (what its extension acts on).
TEST(ImuAnalysis, AnEffectWhoseExtensionLosesAgainstTheTruthIsNotNamed) {
  const double deg = std::numbers::pi / 180.0;
  auto score = [&](double total, double heading) {
    disc::OrientationScore s;
    s.Add({total * deg, heading * deg, 0.5 * deg});
    return s;
  };
  disc::ImuAnalysis a;
  a.candidates.resize(4);
  disc::ImuCandidate &mag = a.candidates[0], &bias = a.candidates[1], &untested = a.candidates[2],
                     &lag = a.candidates[3];
  mag.cause = "magnetic_disturbance";
  mag.tested = mag.significant = true;
  mag.before = score(1.5, 1.0);
  mag.after = score(1.4, 2.0);  // total better, heading (what the gate acts on) worse
  bias.cause = "gyro_bias";
  bias.tested = bias.significant = true;
  bias.before = score(2.0, 1.0);
  bias.after = score(2.1, 1.2);  // total 5 % worse: gains nothing, no loss: named
  untested.cause = "time_offset";
  lag.cause = "accel_lag";
  lag.tested = lag.significant = true;
  lag.before = lag.after = score(1.5, 1.0);  // it changes no orientation
  lag.position_before_m = 1.2e-3;
  lag.position_after_m = 1.5e-3;
  disc::MarkLosingExtensions(a.candidates);
  EXPECT_TRUE(mag.loses_to_truth);
  EXPECT_FALSE(mag.named());
  EXPECT_NE(mag.note.find("from 1.00 to 2.00 deg"), std::string::npos) << mag.note;
  EXPECT_FALSE(bias.loses_to_truth);
  EXPECT_TRUE(bias.named());
  EXPECT_FALSE(untested.loses_to_truth);
  EXPECT_TRUE(lag.loses_to_truth);
  EXPECT_FALSE(lag.named());
  EXPECT_NE(lag.note.find("position RMSE against the truth from 1.20 to 1.50 mm"),
            std::string::npos)
      << lag.note;
  ASSERT_EQ(a.effects().size(), 1u);
  EXPECT_EQ(a.effects()[0]->cause, "gyro_bias");
}
