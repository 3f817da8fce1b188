// The hard-iron fit against a simulated magnetometer whose offset is known: a magnet fixed to a
// turning sensor is found and applied, one attached and taken off is followed, and what cannot be
// told from the magnetometer's own errors (at rest, below the floor) is never applied.
#include "rcal/estimation/mag_hard_iron.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include "rcal/geometry/so3.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::estimation {
namespace {

constexpr double kDt = 0.01;  // 100 Hz [s]

// A sensor turning smoothly (up to about 1.5 rad/s about changing axes) in the earth field m_E
// (45 µT, dip 60°), m_B = R_EBᵀ m_E + b_B(t) + n, n white with σ 0.5 µT per axis.
struct Turning {
  Eigen::Vector3d m_E = 45.0 * Eigen::Vector3d(0.0, std::cos(1.047), -std::sin(1.047));
  std::vector<double> t;
  std::vector<Eigen::Vector3d> m_B;

  template <class Offset>
  void Run(int n, std::uint64_t seed, Offset b_B, double rate_scale = 1.0,
           const Eigen::Matrix3d& soft_iron = Eigen::Matrix3d::Identity()) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> N(0.0, 1.0);
    const Eigen::Vector3d phase = sim::Draw3(N, rng);
    Eigen::Matrix3d R_EB = geometry::Exp(sim::Draw3(N, rng));
    for (int k = 0; k < n; ++k) {
      const double tk = k * kDt;
      const Eigen::Vector3d w_B(std::sin(0.7 * tk + phase(0)), 0.8 * std::sin(1.1 * tk + phase(1)),
                                0.6 * std::cos(0.5 * tk + phase(2)));
      R_EB = R_EB * geometry::Exp(rate_scale * w_B * kDt);
      t.push_back(tk);
      m_B.push_back(soft_iron * R_EB.transpose() * m_E + b_B(tk) + 0.5 * sim::Draw3(N, rng));
    }
  }
};

Eigen::Vector3d RandomOffset(std::uint64_t seed, double norm) {
  std::mt19937_64 rng(seed + 1000);
  std::normal_distribution<double> N(0.0, 1.0);
  return norm * sim::Draw3(N, rng).normalized();
}

// A magnet 0.6 of the field (BROAD's trial 33: 27 µT at 2 cm), fixed after the first 5 s, on a
// turning sensor: from 30 s on the fit is applied and within 4 % of the field (1.8 µT) of the
// offset simulated, within 3 % at the end. (Measured: at most 1.51 µT from 30 s, 0.06–0.92 µT at
// the end, over the eight seeds.)
TEST(MagHardIron, FindsAMagnetFixedToATurningSensor) {
  for (std::uint64_t seed = 1; seed <= 8; ++seed) {
    const Eigen::Vector3d b_true = RandomOffset(seed, 27.0);
    Turning sim;
    sim.Run(6000, seed, [&](double t) { return t >= 5.0 ? b_true : Eigen::Vector3d::Zero(); });
    MagHardIron fit;
    std::int64_t applied_late = 0;
    double worst_late = 0.0;
    for (size_t k = 0; k < sim.t.size(); ++k) {
      ASSERT_TRUE(fit.Update(sim.t[k], sim.m_B[k]).ok());
      if (sim.t[k] < 30.0) continue;
      applied_late += fit.applied();
      worst_late = std::max(worst_late, (fit.offset_B() - b_true).norm());
    }
    SCOPED_TRACE(seed);
    std::printf("seed %d: worst %.2f µT from 30 s, last %.2f µT, r %.2f µT\n",
                static_cast<int>(seed), worst_late, (fit.offset_B() - b_true).norm(), fit.r());
    EXPECT_EQ(applied_late, 3000);
    EXPECT_LT(worst_late, 0.04 * 45.0);
    EXPECT_LT((fit.offset_B() - b_true).norm(), 0.03 * 45.0);
    EXPECT_NEAR(fit.r(), 45.0, 0.02 * 45.0);
    EXPECT_LE(fit.counters().restarts, 2);
  }
}

// A magnet attached at 20 s and taken off at 60 s (trial 33's, 27 µT): the fit starts again after
// each (its norm innovations fail the gate for restart_time), applies the magnet for at least 40 %
// of the time it is there (the restart and settle_time take the first seconds), within 4 % of the
// field while applied on most seeds and at the end on every seed, and nothing after it is gone.
// Measured: applied 1919–3057 of 4000 samples; worst while applied 0.13–0.84 µT on seven seeds,
// 7.3 µT on seed 8 (at 29.4 s, 2 s after it was first applied: the one fit that converged late).
TEST(MagHardIron, FollowsAMagnetAttachedAndTakenOff) {
  std::vector<double> worsts;
  for (std::uint64_t seed = 1; seed <= 8; ++seed) {
    const Eigen::Vector3d b_true = RandomOffset(seed, 27.0);
    auto attached = [](double t) { return t >= 20.0 && t < 60.0; };
    Turning sim;
    sim.Run(9000, seed, [&](double t) { return attached(t) ? b_true : Eigen::Vector3d::Zero(); });
    MagHardIron fit;
    double worst_on = 0.0, worst_off = 0.0, error_at_end = 0.0;
    int applied_on = 0;
    double worst_t = 0;
    for (size_t k = 0; k < sim.t.size(); ++k) {
      ASSERT_TRUE(fit.Update(sim.t[k], sim.m_B[k]).ok());
      const double t = sim.t[k];
      const Eigen::Vector3d b = attached(t) ? b_true : Eigen::Vector3d::Zero();
      if (t >= 20.0 && t < 60.0 && fit.applied()) {
        ++applied_on;
        if ((fit.offset_B() - b).norm() > worst_on) worst_t = t;
        worst_on = std::max(worst_on, (fit.offset_B() - b).norm());
      }
      if (k + 1 < sim.t.size() && attached(t) && !attached(sim.t[k + 1]))
        error_at_end = (fit.offset_B() - b).norm();
      if (t >= 75.0 || t < 20.0) worst_off = std::max(worst_off, fit.offset_B().norm());
    }
    SCOPED_TRACE(seed);
    EXPECT_GT(applied_on, 1600);  // of 4000 samples
    EXPECT_LT(error_at_end, 0.04 * 45.0);
    EXPECT_EQ(worst_off, 0.0);
    worsts.push_back(worst_on);
    std::printf(
        "seed %d: applied %d of 4000 samples with the magnet, worst %.2f µT at %.2f s, restarts "
        "%lld\n",
        static_cast<int>(seed), applied_on, worst_on, worst_t,
        static_cast<long long>(fit.counters().restarts));
    EXPECT_GE(fit.counters().restarts, 2);
  }
  std::sort(worsts.begin(), worsts.end());
  EXPECT_LT(worsts[worsts.size() / 2], 0.04 * 45.0);  // the median seed
  EXPECT_LT(worsts.back(), 0.2 * 45.0);               // the worst: 7.3 µT, 16 % of the field
}

// What the norm cannot tell from the magnetometer's own errors is not applied: a 2 µT offset (4 %
// of the field, below the floor of 20 %) with 3 % scale errors per axis, and a sensor at rest,
// where only the offset's component along the field is observable.
TEST(MagHardIron, WhatCannotBeToldFromTheSensorsOwnErrorsIsNotApplied) {
  for (std::uint64_t seed = 1; seed <= 4; ++seed) {
    const Eigen::Vector3d b_small = RandomOffset(seed, 2.0);
    Turning sim;
    sim.Run(
        6000, seed, [&](double) { return b_small; }, 1.0,
        Eigen::Vector3d(1.03, 0.97, 1.0).asDiagonal());
    MagHardIron fit;
    for (size_t k = 0; k < sim.t.size(); ++k) ASSERT_TRUE(fit.Update(sim.t[k], sim.m_B[k]).ok());
    EXPECT_EQ(fit.counters().applied, 0) << "seed " << seed;

    // At rest with a magnet of 0.6 of the field: never known in every direction.
    const Eigen::Vector3d b_big = RandomOffset(seed, 27.0);
    Turning still;
    still.Run(
        3000, seed, [&](double) { return b_big; }, 0.0);
    MagHardIron at_rest;
    for (size_t k = 0; k < still.t.size(); ++k)
      ASSERT_TRUE(at_rest.Update(still.t[k], still.m_B[k]).ok());
    EXPECT_EQ(at_rest.counters().applied, 0) << "seed " << seed;
    // Known along the field only (measured √tr P_bb 1.0–3.6 µT): above the 0.45 µT it needs.
    EXPECT_GT(at_rest.b_sigma(), MagHardIronSettings{}.confident_sigma * 45.0);
  }
}

TEST(MagHardIron, RefusesBadInputAndSettingsNamingThem) {
  MagHardIron fit;
  const Eigen::Vector3d m(1.0, 20.0, -40.0);
  ASSERT_TRUE(fit.Update(1.0, m).ok());
  const Eigen::Vector3d b = fit.b_B();
  const double r = fit.r();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(fit.Update(2.0, Eigen::Vector3d(nan, 0, 0)).error().find("m_B"), std::string::npos);
  EXPECT_NE(fit.Update(2.0, Eigen::Vector3d::Zero()).error().find("m_B"), std::string::npos);
  EXPECT_NE(fit.Update(0.5, m).error().find("goes back"), std::string::npos);
  EXPECT_NE(fit.Update(nan, m).error().find("t ="), std::string::npos);
  EXPECT_EQ(fit.b_B(), b);
  EXPECT_EQ(fit.r(), r);
  EXPECT_EQ(fit.counters().samples, 1);

  MagHardIronSettings s;
  s.noise = 0.0;
  EXPECT_NE(CheckMagHardIronSettings(s).error().find("mag_hard_iron.noise"), std::string::npos);
  s = {};
  s.apply_floor = -1.0;
  EXPECT_NE(CheckMagHardIronSettings(s).error().find("apply_floor"), std::string::npos);
  s = {};
  s.restart_time = nan;
  MagHardIron refused(s);
  EXPECT_NE(refused.Update(1.0, m).error().find("restart_time"), std::string::npos);
  EXPECT_TRUE(CheckMagHardIronSettings({}).ok());
}

}  // namespace
}  // namespace rcal::estimation
