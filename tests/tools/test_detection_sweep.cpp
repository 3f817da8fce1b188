// How `rcal detection-sweep` scores an analysis and seeds its cells (tools/rcal/detection_sweep).
#include "detection_sweep.hpp"

#include <gtest/gtest.h>

#include <set>

namespace {

using rcal::kinematics::Effect;
using rcal::kinematics::EffectCause;
using rcal::tool::DetectionCellSeed;
using rcal::tool::DetectionSubSeed;
using rcal::tool::ScoreDetection;

Effect Thermal(Effect::ThermalSource s) {
  Effect e{EffectCause::kThermal};
  e.thermal_source = s;
  return e;
}
Effect OnJoint(EffectCause c, int joint, int harmonic = 1) {
  Effect e{c};
  e.joint = joint;
  e.harmonic = harmonic;
  return e;
}

// A thermal effect found with the other source (time for temperature, or the reverse) is a wrong
// cause, counted as wrong and, apart, as a wrong source; not a detection.
TEST(DetectionSweep, ThermalWithTheWrongSourceIsAWrongCause) {
  for (const auto& [hidden, found] :
       {std::pair{Effect::ThermalSource::kTemperature, Effect::ThermalSource::kTime},
        std::pair{Effect::ThermalSource::kTime, Effect::ThermalSource::kTemperature}}) {
    const auto r = ScoreDetection(Thermal(hidden), {Thermal(found)});
    EXPECT_FALSE(r.detected);
    EXPECT_FALSE(r.exact);
    EXPECT_TRUE(r.wrong);
    EXPECT_TRUE(r.wrong_source);
    EXPECT_FALSE(r.extra);
    const auto right = ScoreDetection(Thermal(hidden), {Thermal(hidden)});
    EXPECT_TRUE(right.detected);
    EXPECT_TRUE(right.exact);
    EXPECT_FALSE(right.wrong);
    EXPECT_FALSE(right.wrong_source);
  }
  // Both sources reported: the hidden one is detected, the other is an extra effect.
  const auto both = ScoreDetection(
      Thermal(Effect::ThermalSource::kTime),
      {Thermal(Effect::ThermalSource::kTemperature), Thermal(Effect::ThermalSource::kTime)});
  EXPECT_TRUE(both.detected);
  EXPECT_FALSE(both.wrong);
  EXPECT_FALSE(both.wrong_source);
  EXPECT_TRUE(both.extra);
}

TEST(DetectionSweep, JointEffectsScoreByCauseAndJoint) {
  const Effect h1 = OnJoint(EffectCause::kJointPeriodic, 2, 1);
  // The other harmonic on the right joint: detected (cause and joint), not exact.
  auto r = ScoreDetection(h1, {OnJoint(EffectCause::kJointPeriodic, 2, 2)});
  EXPECT_TRUE(r.detected);
  EXPECT_FALSE(r.exact);
  EXPECT_FALSE(r.wrong);
  // The right cause on another joint, or another cause: wrong, and not a thermal source.
  r = ScoreDetection(h1, {OnJoint(EffectCause::kJointPeriodic, 3, 1)});
  EXPECT_FALSE(r.detected);
  EXPECT_TRUE(r.wrong);
  EXPECT_FALSE(r.wrong_source);
  r = ScoreDetection(OnJoint(EffectCause::kBacklash, 1),
                     {Thermal(Effect::ThermalSource::kTemperature)});
  EXPECT_TRUE(r.wrong);
  EXPECT_FALSE(r.wrong_source);
  // Nothing found: a miss, not a wrong cause.
  r = ScoreDetection(h1, {});
  EXPECT_FALSE(r.detected);
  EXPECT_FALSE(r.wrong);
  // Found with something else: detected, extra.
  r = ScoreDetection(h1, {h1, OnJoint(EffectCause::kJointScale, 0)});
  EXPECT_TRUE(r.detected);
  EXPECT_TRUE(r.exact);
  EXPECT_TRUE(r.extra);
}

// A cell's seed is a function of (effect, magnitude, seed index) alone, and distinct cells get
// distinct seeds (and distinct joint and dataset streams).
TEST(DetectionSweep, EveryCellHasItsOwnSeed) {
  EXPECT_EQ(DetectionCellSeed("backlash", 2.0, 1000), DetectionCellSeed("backlash", 2.0, 1000));
  std::set<std::uint64_t> seeds;
  int n = 0;
  for (const char* id : {"joint_compliance", "joint_periodic_h1", "joint_periodic_h2",
                         "joint_scale", "backlash", "thermal_temperature", "thermal_time", "clean"})
    for (double k : {0.0, 1.0, 1.5, 2.0, 3.0, 5.0})
      for (unsigned s = 1000; s < 1200; ++s) {
        const std::uint64_t c = DetectionCellSeed(id, k, s);
        seeds.insert(c);
        seeds.insert(DetectionSubSeed(c, 1));
        seeds.insert(DetectionSubSeed(c, 2));
        n += 3;
      }
  EXPECT_EQ(static_cast<int>(seeds.size()), n);
}

}  // namespace
