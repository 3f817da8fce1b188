// Hidden effects: data simulated with one non-geometric effect (or none) near the noise floor;
// the analysis must name the right cause and joint, report nothing on clean data, and gain on
// held-out poses about what the true model structure gains.
#include "rcal/discrepancy/analysis.hpp"

#include <gtest/gtest.h>

#include <optional>

#include "rcal/identification/calibration.hpp"

#include "../kinematics/test_robots.hpp"
#include "rcal/sim/effects.hpp"

namespace rcal::discrepancy {
namespace {

using kinematics::Effect;
using kinematics::EffectCause;

struct Case {
  kinematics::KinematicModel model;
  PoseData data;
  std::vector<Effect> truth;
  Eigen::VectorXd truth_values;  ///< of the hidden effect [SI]
};

// `num_poses` poses of the UR-like arm (random geometric errors, base and marker frames), a
// session with temperature, payload, approach directions and time, position noise σ = 50 µm,
// and optionally one hidden effect displacing the marker by `rms_over_noise`·σ RMS.
Case MakeCase(unsigned seed, std::optional<Effect> hidden, double rms_over_noise,
              int num_poses = 60, bool orientation = false) {
  Case c;
  c.model = kinematics::testing::UrLikeUrdf();
  sim::Rng rng(seed);
  sim::PoseNoise noise;
  noise.position_sigma = 5e-5;
  noise.orientation_sigma = 1.745e-4;
  noise.orientation = orientation;
  const Eigen::VectorXd x = sim::RandomErrors(c.model, rng, 1e-3, 1e-3);
  const auto qs = sim::SampleJoints(c.model, num_poses, rng);
  const auto ctx = sim::SampleSession(c.model.num_joints(), num_poses, {}, rng);
  std::vector<sim::TruthEffect> effects;
  if (hidden) {
    effects.push_back(sim::EffectOfSize(c.model, *hidden, qs, ctx, x,
                                        rms_over_noise * noise.position_sigma, rng));
    c.truth.push_back(*hidden);
    c.truth_values = effects.back().values;
  }
  const sim::EffectTruth truth = sim::MakeEffectTruth(c.model, effects);
  c.data.measurements = sim::MeasurePosesWithEffects(truth, x, qs, ctx, noise, rng);
  c.data.contexts = ctx;
  return c;
}

std::string Found(const Case& c, const Analysis& a) {
  std::string s;
  for (const auto& f : a.effects) s += Describe(c.model, f.effect) + "; ";
  return s.empty() ? "nothing" : s;
}

TEST(Discrepancy, CleanDataHasNoEffect) {
  for (unsigned seed : {1u, 2u, 3u}) {
    const Case c = MakeCase(seed, std::nullopt, 0);
    const Analysis a = Analyze(c.model, c.data);
    EXPECT_TRUE(a.effects.empty()) << "seed " << seed << ": " << Found(c, a);
    EXPECT_NEAR(a.gain.relative_gain, 0.0, 1e-12);
    EXPECT_FALSE(a.candidates.empty());
    // The base fit's noise estimate is the simulated one.
    EXPECT_NEAR(a.base_fit.position_sigma_m, 5e-5, 1.5e-5);
  }
}

TEST(Discrepancy, NamesTheHiddenCauseAndJoint) {
  struct Hidden {
    Effect effect;
    double rms_over_noise;
    unsigned seed;
  };
  Effect thermal_t{EffectCause::kThermal};
  Effect thermal_time{EffectCause::kThermal};
  thermal_time.thermal_source = Effect::ThermalSource::kTime;
  thermal_time.reference = 0.0;
  const std::vector<Hidden> cases = {
      {{EffectCause::kJointCompliance, 1}, 3.0, 11},
      {{EffectCause::kJointCompliance, 2}, 3.0, 12},
      {{EffectCause::kJointPeriodic, 0, 1}, 3.0, 13},
      {{EffectCause::kJointPeriodic, 3, 2}, 3.0, 14},
      {{EffectCause::kJointScale, 1}, 3.0, 15},
      {{EffectCause::kJointScale, 4}, 3.0, 16},
      {{EffectCause::kBacklash, 2}, 3.0, 17},
      {{EffectCause::kBacklash, 0}, 3.0, 18},
      {thermal_t, 3.0, 19},
      {thermal_time, 3.0, 20},
  };
  for (const Hidden& h : cases) {
    const Case c = MakeCase(h.seed, h.effect, h.rms_over_noise);
    const Analysis a = Analyze(c.model, c.data);
    const std::string what = Describe(c.model, h.effect) + " seed " + std::to_string(h.seed);
    ASSERT_FALSE(a.effects.empty()) << what << ": nothing found";
    EXPECT_TRUE(a.effects.front().effect.SameAs(h.effect)) << what << ": found " << Found(c, a);
    EXPECT_LE(a.effects.size(), 2u) << what << ": found " << Found(c, a);
    EXPECT_GT(a.gain.relative_gain, 0.0) << what;
    // The fitted values agree with the truth within their stated uncertainty.
    const FoundEffect& f = a.effects.front();
    for (int i = 0; i < f.values.size(); ++i)
      EXPECT_NEAR(f.values(i), c.truth_values(i), 4 * f.sigma(i) + 1e-12)
          << what << " " << f.parameters[i].name << " σ " << f.sigma(i);
    std::printf("%-32s found %-40s gain %.3f (true model: rms %.2f µm vs %.2f µm), z %.1f\n",
                what.c_str(), Found(c, a).c_str(), a.gain.relative_gain,
                a.gain.heldout_rms_after_m * 1e6, HeldOutRms(c.model, c.data, c.truth) * 1e6, f.z);
    // The gain is nested-cross-validated: the selection is redone in each outer fold, so a
    // marginal detection (z near the critical value) that some outer folds miss honestly gains
    // less than the true model structure would. Clear detections gain what the truth gains.
    const double rms_true = HeldOutRms(c.model, c.data, c.truth);
    EXPECT_EQ(a.gain.scheme, "nested 5-fold (selection redone in each outer fold)");
    EXPECT_NEAR(a.gain.heldout_rms_after_m, rms_true, (f.z >= 4.0 ? 0.1 : 0.25) * rms_true)
        << what;
  }
}

TEST(Discrepancy, SplitAndOrientation) {
  // Position and orientation measured; a `set` column: selection sees only the cal poses, the
  // gain is judged on the test poses.
  const Effect hidden{EffectCause::kJointPeriodic, 4, 1};
  Case c = MakeCase(21, hidden, 3.0, 100, true);
  for (size_t i = 0; i < c.data.measurements.size(); ++i) c.data.is_test.push_back(i % 3 == 0);
  const Analysis a = Analyze(c.model, c.data);
  EXPECT_EQ(a.num_test_poses, 34);
  EXPECT_EQ(a.gain.scheme, "cal/test split");
  ASSERT_EQ(a.effects.size(), 1u) << Found(c, a);
  EXPECT_TRUE(a.effects.front().effect.SameAs(hidden)) << Found(c, a);
  EXPECT_GT(a.gain.relative_gain, 0.1);
  EXPECT_EQ(a.gain.position_before_m.size(), 34u);
  // Clean data with the same layout: nothing.
  Case clean = MakeCase(22, std::nullopt, 0, 100, true);
  clean.data.is_test = c.data.is_test;
  EXPECT_TRUE(Analyze(clean.model, clean.data).effects.empty());
}

TEST(Discrepancy, LinearisedCrossValidationMatchesFullRecalibration) {
  // The k-fold held-out RMS of the geometric model, linearised around the base fit, against
  // identification::HeldOut, which recalibrates every fold from scratch (same fold assignment).
  const Case c = MakeCase(23, std::nullopt, 0, 60);
  AnalysisSettings s;
  s.repeats = 1;
  const double lin = HeldOutRms(c.model, c.data, {}, s);
  std::vector<kinematics::PoseMeasurement> ms = c.data.measurements;
  identification::CalibrationSettings cs;
  cs.folds = s.folds;
  cs.seed = s.seed;
  const auto fit = identification::Calibrate(c.model, ms, cs);
  const auto held = identification::HeldOut(c.model, ms, {}, fit, cs);
  EXPECT_NEAR(lin, held.calibrated.rms_position_m, 0.005 * held.calibrated.rms_position_m);
}

TEST(Discrepancy, NoiseTests) {
  // Stated noise right: χ² consistent; stated noise too small: rejected. Repeated poses give
  // the noise without the model.
  Case c = MakeCase(24, std::nullopt, 0, 40);
  sim::Rng rng(7);
  std::normal_distribution<double> n(0.0, 5e-5);
  for (int i = 0; i < 20; ++i) {  // re-measure 20 poses
    kinematics::PoseMeasurement m = c.data.measurements[i];
    const Eigen::VectorXd r0 =
        Eigen::Vector3d(n(rng), n(rng), n(rng));  // fresh noise around the same pose
    m.p_WM_W += r0;
    c.data.measurements.push_back(m);
    c.data.contexts.push_back(c.data.contexts[i]);
  }
  AnalysisSettings s;
  s.stated_position_sigma_m = 5e-5;
  Analysis a = Analyze(c.model, c.data, s);
  ASSERT_EQ(a.noise_tests.size(), 2u);
  EXPECT_EQ(a.noise_tests[0].against, "stated noise");
  EXPECT_GT(a.noise_tests[0].p_value, 0.001);
  EXPECT_EQ(a.noise_tests[1].against, "repeated poses");
  // Re-measured poses differ by two noise draws (σ√2 per axis) and the pair mean removes half.
  EXPECT_NEAR(a.noise_tests[1].position_sigma_m, 5e-5, 2e-5);
  s.stated_position_sigma_m = 2e-5;
  a = Analyze(c.model, c.data, s);
  EXPECT_LT(a.noise_tests[0].p_value, 1e-6);
}

TEST(Discrepancy, RejectsInconsistentInput) {
  Case c = MakeCase(25, std::nullopt, 0, 20);
  c.data.contexts.pop_back();
  EXPECT_THROW(Analyze(c.model, c.data), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::discrepancy
