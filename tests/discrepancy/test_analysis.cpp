// Hidden effects: data simulated with one non-geometric effect (or none) near the noise floor;
// the analysis must name the right cause and joint, report nothing on clean data, and gain on
// held-out poses about what the true model structure gains.
#include "rcal/discrepancy/analysis.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
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
  Eigen::VectorXd truth_values;         ///< of the hidden effect [SI]
  std::vector<Eigen::Vector3d> p_true;  ///< noise-free marker position of each pose [m]
};

// `num_poses` poses of the UR-like arm (random geometric errors, base and marker frames), a
// session with temperature, payload, approach directions and time, position noise σ = 50 µm,
// and the hidden effects, each displacing the marker by its rms_over_noise·σ RMS.
Case MakeCaseWith(unsigned seed, const std::vector<std::pair<Effect, double>>& hidden,
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
  std::vector<double> values;
  for (const auto& [effect, rms_over_noise] : hidden) {
    effects.push_back(
        sim::EffectOfSize(c.model, effect, qs, ctx, x, rms_over_noise * noise.position_sigma, rng));
    c.truth.push_back(effect);
    for (int i = 0; i < effects.back().values.size(); ++i)
      values.push_back(effects.back().values(i));
  }
  c.truth_values = Eigen::Map<const Eigen::VectorXd>(values.data(), values.size());
  const sim::EffectTruth truth = sim::MakeEffectTruth(c.model, effects);
  c.data.measurements = sim::MeasurePosesWithEffects(truth, x, qs, ctx, noise, rng);
  c.data.contexts = ctx;
  for (int i = 0; i < num_poses; ++i)
    c.p_true.push_back(truth.model.Forward(qs[i], ctx[i], x, truth.e).p_WM_W);
  return c;
}

// One hidden effect (or none).
Case MakeCase(unsigned seed, std::optional<Effect> hidden, double rms_over_noise,
              int num_poses = 60, bool orientation = false) {
  std::vector<std::pair<Effect, double>> h;
  if (hidden) h.push_back({*hidden, rms_over_noise});
  return MakeCaseWith(seed, h, num_poses, orientation);
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
    // The base fit's noise estimate is the simulated one: σ̂² = SS/ν, ν = 3·60 position
    // equations − the identified parameters, so SE(σ̂) ≈ σ/√(2ν) (≈ 2.9 µm); band 3 SE
    // (two-sided false-alarm rate 0.27 %; was ± 15 µm).
    const double nu = 3.0 * c.data.measurements.size() - a.base_fit.identified.size();
    const double se = 5e-5 / std::sqrt(2 * nu);
    std::printf("seed %u: base-fit sigma %.2f um, nu %.0f, band 50 +- %.2f um\n", seed,
                a.base_fit.position_sigma_m * 1e6, nu, 3 * se * 1e6);
    EXPECT_NEAR(a.base_fit.position_sigma_m, 5e-5, 3 * se);
  }
}

// A tracker measuring three reflectors at each stop (UR-like arm, markers 0, 2, 5): the rows of a
// stop share its context and its fold (the scheme says "by configuration"), clean data give
// nothing, and a periodic error of the elbow (3σ) is named, its offsets fitted per marker.
TEST(Discrepancy, SeveralMarkersPerStop) {
  for (const bool hidden : {false, true}) {
    const kinematics::KinematicModel model = kinematics::testing::UrLikeThreeMarkers();
    sim::Rng rng(hidden ? 41 : 40);
    sim::PoseNoise noise;
    noise.position_sigma = 5e-5;
    noise.orientation = false;
    const Eigen::VectorXd x = sim::RandomErrors(model, rng, 1e-3, 1e-3);
    const int stops = 40;
    const auto qs = sim::SampleJoints(model, stops, rng);
    const auto ctx = sim::SampleSession(model.num_joints(), stops, {}, rng);
    const Effect periodic{EffectCause::kJointPeriodic, 2, 1};
    std::vector<sim::TruthEffect> effects;
    if (hidden)
      effects.push_back(
          sim::EffectOfSize(model, periodic, qs, ctx, x, 3 * noise.position_sigma, rng));
    PoseData d;
    d.measurements =
        sim::MeasurePosesWithEffects(sim::MakeEffectTruth(model, effects), x, qs, ctx, noise, rng);
    ASSERT_EQ(d.measurements.size(), 3u * stops);
    for (size_t i = 0; i < d.measurements.size(); ++i) d.contexts.push_back(ctx[i / 3]);
    const Analysis a = Analyze(model, d);
    EXPECT_NE(a.gain.scheme.find("by configuration"), std::string::npos) << a.gain.scheme;
    if (!hidden) {
      EXPECT_NEAR(a.base_fit.position_sigma_m / noise.position_sigma, 1.0, 0.15);
      EXPECT_TRUE(a.effects.empty()) << a.effects.size() << " effect(s) on clean data";
      continue;
    }
    ASSERT_EQ(a.effects.size(), 1u);
    EXPECT_EQ(a.effects[0].effect.cause, EffectCause::kJointPeriodic);
    EXPECT_EQ(a.effects[0].effect.joint, 2);
    EXPECT_GT(a.gain.relative_gain, 0.1);
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
    if (a.effects.empty()) {
      for (const auto& r : a.rounds) {
        double zmax = 0;
        for (double z : r.z) zmax = std::max(zmax, z);
        std::printf("%s: round with largest z %.3f, critical %.3f\n", what.c_str(), zmax,
                    r.z_critical);
      }
    }
    ASSERT_FALSE(a.effects.empty()) << what << ": nothing found";
    EXPECT_TRUE(a.effects.front().effect.SameAs(h.effect)) << what << ": found " << Found(c, a);
    EXPECT_LE(a.effects.size(), 2u) << what << ": found " << Found(c, a);
    EXPECT_GT(a.gain.relative_gain, 0.0) << what;
    // The fitted values agree with the truth within their stated uncertainty.
    const FoundEffect& f = a.effects.front();
    for (int i = 0; i < f.values.size(); ++i)
      EXPECT_NEAR(f.values(i), c.truth_values(i), 4 * f.sigma(i) + 1e-12)
          << what << " " << f.parameters[i].name << " σ " << f.sigma(i);
    // The gain is nested-cross-validated: the selection is redone in each outer fold, so a
    // marginal detection (z near the critical value) that some outer folds miss honestly gains
    // less than the true model structure would. Judged pose by pose against the true structure
    // fitted on the same outer folds (repeats = 1 is Analyze's outer assignment): D_i = a_i² −
    // t_i², a and t the selected and the true model's held-out position error of pose i.
    // Clear detections (z ≥ 4): |mean D| ≤ 3.29 SE(D), SE = sd(D)/√n over the n = 60 held-out
    // poses (paired; two-sided false-alarm rate 1e-3), + 1e-9 of mean t² for rounding; D ≡ 0
    // when every outer fold selects the true effect (so here: after = truth to 1e-4 µm).
    // Marginal ones (z < 4) only one-sided: not better than the truth. Thermal (temperature),
    // seed 19, z 3.67 is marginal: after 102.5 µm against the true structure's 83.6 µm on the
    // same folds (gain 1.8 % vs 19.9 %, mean D 3.5 SE); the outer folds, with 4/5 of
    // the poses (z ≈ 3.67 √0.8 = 3.3), mostly miss it. Measured, not asserted. (Was |after −
    // truth| ≤ 10 % / 25 % of the truth on other folds: the marginal case passed with no gain.)
    EXPECT_EQ(a.gain.scheme, "nested 5-fold (selection redone in each outer fold)");
    AnalysisSettings outer;
    outer.repeats = 1;
    const std::vector<double> t = HeldOutPositionErrors(c.model, c.data, c.truth, outer);
    const std::vector<double>& af = a.gain.position_after_m;
    ASSERT_EQ(t.size(), af.size());
    const double n = static_cast<double>(t.size());
    double mean_d = 0, mean_t2 = 0, var_d = 0;
    for (size_t i = 0; i < t.size(); ++i) {
      mean_d += (af[i] * af[i] - t[i] * t[i]) / n;
      mean_t2 += t[i] * t[i] / n;
    }
    for (size_t i = 0; i < t.size(); ++i)
      var_d += std::pow(af[i] * af[i] - t[i] * t[i] - mean_d, 2) / (n - 1);
    const double se_d = std::sqrt(var_d / n), tol = 3.29 * se_d + 1e-9 * mean_t2;
    std::printf(
        "%-32s found %-40s gain %.3f; held-out rms %.2f µm, true model %.2f µm (same folds), "
        "mean D %.3g (SE %.2g), z %.1f\n",
        what.c_str(), Found(c, a).c_str(), a.gain.relative_gain, a.gain.heldout_rms_after_m * 1e6,
        std::sqrt(mean_t2) * 1e6, mean_d, se_d, f.z);
    if (f.z >= 4.0)
      EXPECT_LE(std::abs(mean_d), tol) << what;
    else
      EXPECT_GE(mean_d, -tol) << what;
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

// Held-out position RMS on the `set` test poses of geometry + `effects` fitted on the cal poses
// by the batch nonlinear fits of identification (Calibrate, then FitExtended from it): the
// independent truth of whether an extension gains on poses it did not fit, without the
// analysis' linearisation around its base fit.
double SplitRmsByFullFits(const Case& c, const std::vector<Effect>& effects) {
  std::vector<kinematics::PoseMeasurement> cal;
  std::vector<kinematics::EffectContext> cal_ctx;
  for (size_t i = 0; i < c.data.measurements.size(); ++i)
    if (!c.data.is_test[i]) {
      cal.push_back(c.data.measurements[i]);
      cal_ctx.push_back(c.data.contexts[i]);
    }
  const identification::CalibrationFit fit = identification::Calibrate(c.model, cal);
  std::vector<Effect> fx = effects;
  for (Effect& f : fx)
    if (f.cause == EffectCause::kThermal) f.reference = 25.0;
  const kinematics::ExtendedModel ext(c.model, fx);
  const identification::ExtendedFit ef =
      identification::FitExtended(ext, fit.identified, cal, cal_ctx, fit.x, ext.NoEffects());
  double ss = 0;
  int n = 0;
  for (size_t i = 0; i < c.data.measurements.size(); ++i)
    if (c.data.is_test[i]) {
      const auto& m = c.data.measurements[i];
      ss += (m.p_WM_W - ext.Forward(m.q, c.data.contexts[i], ef.x, ef.e).p_WM_W).squaredNorm();
      ++n;
    }
  return std::sqrt(ss / n);
}

// Issue 12, item 5: an effect is reported only when the selected model gains on poses it did not
// fit and the effect itself earns its place there. Seeds where the greedy selection (k-fold on
// the fit poses, z above its critical value) chose an effect that then lost on held-out poses;
// the old code reported each of them, with a gain of 0 % or below.
TEST(Discrepancy, NeverReportsAnEffectThatLosesOnHeldOutPoses) {
  const Effect periodic{EffectCause::kJointPeriodic, 2, 1};  // elbow, 1st harmonic
  {
    // No split, 1σ: selected at z 3.4 on all 60 poses, chosen by none of the 5 outer folds (48
    // poses each), so the nested gain is 0: old code "joint_periodic elbow h1, gain 0.0 %".
    const Case c = MakeCase(112, periodic, 1.0);
    const Analysis a = Analyze(c.model, c.data);
    EXPECT_TRUE(a.effects.empty()) << Found(c, a);
    ASSERT_EQ(a.rejected.size(), 1u);
    EXPECT_TRUE(a.rejected[0].effect.SameAs(periodic));
    EXPECT_EQ(a.rejected[0].outer_folds_selecting, 0);
    EXPECT_GE(a.rejected[0].heldout_rms_with_m, a.rejected[0].heldout_rms_without_m);
    EXPECT_NE(a.rejected[0].reason.find("loses on held-out poses"), std::string::npos);
    EXPECT_EQ(a.gain.relative_gain, 0.0);
    EXPECT_FALSE(a.gain.nested);
    EXPECT_EQ(a.e.size(), 0);
  }
  {
    // Split (every 6th of 80 poses a test pose), 1.5σ: selected on the 66 cal poses, worse on
    // the 14 test poses by the nonlinear fits too (old code: "gain −7.3 %").
    Case c = MakeCase(110, periodic, 1.5, 80);
    for (int i = 0; i < 80; ++i) c.data.is_test.push_back(i % 6 == 0);
    const double geo = SplitRmsByFullFits(c, {}), ext = SplitRmsByFullFits(c, {periodic});
    std::printf("split seed 110: test RMS by full fits %.2f µm geometric, %.2f µm with %s\n",
                geo * 1e6, ext * 1e6, Describe(c.model, periodic).c_str());
    ASSERT_GT(ext, geo);  // the truth: the extension loses on the test poses
    const Analysis a = Analyze(c.model, c.data);
    EXPECT_TRUE(a.effects.empty()) << Found(c, a);
    ASSERT_EQ(a.rejected.size(), 1u);
    EXPECT_TRUE(a.rejected[0].effect.SameAs(periodic));
    // The analysis' linearised figures agree with the full fits (2 %, the linearisation).
    EXPECT_NEAR(a.rejected[0].heldout_rms_with_m, ext, 0.02 * ext);
    EXPECT_NEAR(a.rejected[0].heldout_rms_without_m, geo, 0.02 * geo);
    EXPECT_EQ(a.gain.relative_gain, 0.0);
  }
  {
    // Split, two hidden effects at 1.5σ: both selected on the cal poses, the joint scale loses on
    // the test poses beside the periodic error (old code reported both): the periodic error is
    // kept, the scale rejected.
    const Effect scale{EffectCause::kJointScale, 1};  // shoulder_lift
    Case c = MakeCaseWith(226, {{periodic, 1.5}, {scale, 1.5}}, 80);
    for (int i = 0; i < 80; ++i) c.data.is_test.push_back(i % 6 == 0);
    const double geo = SplitRmsByFullFits(c, {}), one = SplitRmsByFullFits(c, {periodic}),
                 only_scale = SplitRmsByFullFits(c, {scale}),
                 both = SplitRmsByFullFits(c, {periodic, scale});
    std::printf(
        "split seed 226: test RMS by full fits %.2f µm geometric, %.2f with the periodic "
        "error, %.2f with the scale, %.2f with both\n",
        geo * 1e6, one * 1e6, only_scale * 1e6, both * 1e6);
    ASSERT_LT(one, geo);
    ASSERT_GT(both, one);
    ASSERT_LT(both, only_scale);
    const Analysis a = Analyze(c.model, c.data);
    ASSERT_EQ(a.effects.size(), 1u) << Found(c, a);
    EXPECT_TRUE(a.effects[0].effect.SameAs(periodic));
    EXPECT_NEAR(a.effects[0].heldout_rms_without_m, only_scale, 0.02 * only_scale);
    ASSERT_EQ(a.rejected.size(), 1u);
    EXPECT_TRUE(a.rejected[0].effect.SameAs(scale));
    EXPECT_NE(a.rejected[0].reason.find("does not earn its place"), std::string::npos);
    EXPECT_NEAR(a.rejected[0].heldout_rms_with_m, both, 0.02 * both);
    EXPECT_NEAR(a.rejected[0].heldout_rms_without_m, one, 0.02 * one);
    // The gain is that of the selection as made (both effects), never recomputed after the
    // rejection, which looked at the same test poses: it does not flatter the kept model.
    EXPECT_NEAR(a.gain.heldout_rms_after_m, both, 0.02 * both);
    EXPECT_EQ(a.e.size(), 2);  // the periodic error's sin and cos only
  }
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
  const double sigma = 5e-5;
  Case c = MakeCase(24, std::nullopt, 0, 40);
  sim::Rng rng(7);
  std::normal_distribution<double> n(0.0, sigma);
  const int repeats = 40;
  for (int i = 0; i < repeats; ++i) {  // re-measure every pose: the truth plus fresh noise
    kinematics::PoseMeasurement m = c.data.measurements[i];
    // One draw a statement: the order of draws inside one call's arguments is the compiler's.
    const double nz = n(rng), ny = n(rng), nx = n(rng);
    m.p_WM_W = c.p_true[i] + Eigen::Vector3d(nx, ny, nz);
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
  // The pooled within-pair σ̂ from ν = 3 (axes) × 40 (pairs) × (2 − 1) = 120 dof; ν σ̂²/σ² ~
  // χ²(ν), so SE(σ̂) ≈ σ/√(2ν) = 3.2 µm. Band: 3 SE (two-sided false-alarm rate 0.27 %),
  // 50 ± 9.7 µm; an estimator 35 % low (32.5 µm) fails. (Was 50 ± 20 µm on 20 pairs built
  // from the noisy pose plus fresh noise, whose spread is σ/√2: it read 32.8 µm and passed.)
  const double nu = 3.0 * repeats, se = sigma / std::sqrt(2 * nu);
  std::printf("repeated-pose sigma %.2f um, band %.1f +- %.2f um\n",
              a.noise_tests[1].position_sigma_m * 1e6, sigma * 1e6, 3 * se * 1e6);
  EXPECT_NEAR(a.noise_tests[1].position_sigma_m, sigma, 3 * se);
  s.stated_position_sigma_m = 2e-5;
  a = Analyze(c.model, c.data, s);
  EXPECT_LT(a.noise_tests[0].p_value, 1e-6);
}

// A step of the geometry inside the data (the elbow's link 0.5 mm longer from pose 40 on, ten
// times the noise), on an arm that bends at the shoulder (3σ RMS). Told of the step
// (PoseData::steps), the analysis fits a piecewise geometry: it names the compliance, gives the
// step's amplitude back, and the noise test sees what the step leaves (the compliance), not the
// step. Not told, one geometry cannot fit both halves and the step's residual hides the effect.
TEST(Discrepancy, AKnownGeometryStepIsPartOfTheGeometry) {
  const Effect bends{EffectCause::kJointCompliance, 1};
  for (unsigned seed : {31u, 32u, 33u}) {
    Case c = MakeCaseWith(seed, {{bends, 3.0}}, 80);
    identification::GeometryStep step{40, Eigen::MatrixXd::Zero(c.model.num_params(), 1)};
    int elbow_dx = -1;
    for (int i = 0; i < c.model.num_params(); ++i)
      if (c.model.parameters()[i].name == "elbow_dx") elbow_dx = i;
    ASSERT_GE(elbow_dx, 0);
    step.directions(elbow_dx, 0) = 1.0;
    const double a_true = 5e-4;
    // The noise-free displacement the step makes, added to each later measurement.
    for (size_t i = 40; i < c.data.measurements.size(); ++i) {
      auto& m = c.data.measurements[i];
      const Eigen::VectorXd x0 = Eigen::VectorXd::Zero(c.model.num_params());
      Eigen::VectorXd x1 = x0;
      x1(elbow_dx) = a_true;
      m.p_WM_W += c.model.Forward(m.q, x1).p_WM_W - c.model.Forward(m.q, x0).p_WM_W;
    }
    AnalysisSettings s;
    s.stated_position_sigma_m = 5e-5;
    const Analysis without = Analyze(c.model, c.data, s);
    c.data.steps = {step};
    const Analysis with = Analyze(c.model, c.data, s);
    std::printf(
        "seed %u: told of the step: %s (chi2/dof %.2f), step %.4f +- %.4f mm; not told: %s "
        "(chi2/dof %.2f)\n",
        seed, Found(c, with).c_str(), with.noise_tests[0].chi2 / with.noise_tests[0].dof,
        with.step_amplitudes[0](0) * 1e3, with.step_sigma[0](0) * 1e3, Found(c, without).c_str(),
        without.noise_tests[0].chi2 / without.noise_tests[0].dof);
    EXPECT_EQ(Found(c, with), Describe(c.model, bends) + "; ") << seed;
    EXPECT_NE(Found(c, without), Describe(c.model, bends) + "; ") << seed;
    ASSERT_EQ(with.step_amplitudes.size(), 1u);
    EXPECT_NEAR(with.step_amplitudes[0](0), a_true, 4 * with.step_sigma[0](0)) << seed;
    EXPECT_LT(with.noise_tests[0].chi2, 0.5 * without.noise_tests[0].chi2) << seed;
  }
}

TEST(Discrepancy, RejectsInconsistentInput) {
  Case c = MakeCase(25, std::nullopt, 0, 20);
  const auto message = [&](const PoseData& d) -> std::string {
    try {
      Analyze(c.model, d);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "<no error>";
  };
  const int nx = c.model.num_params();
  for (const int first : {0, 20}) {  // no pose before it; no pose from it
    PoseData d = c.data;
    d.steps = {{first, Eigen::MatrixXd::Identity(nx, 1)}};
    EXPECT_NE(message(d).find("steps[0].first_pose"), std::string::npos) << first;
  }
  PoseData d = c.data;
  d.steps = {{10, Eigen::MatrixXd::Identity(nx - 1, 1)}};
  EXPECT_NE(message(d).find("steps[0].directions"), std::string::npos);
  c.data.contexts.pop_back();
  EXPECT_THROW(Analyze(c.model, c.data), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::discrepancy
