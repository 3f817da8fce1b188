// The EKF identifier on an extended model (state [x_identified; e]): against a simulated truth
// robot with hidden non-geometric effects, against the batch extended fit (FitExtended), and
// against the geometric identifier on the same data; the shared measurement function against
// finite differences; checkpoints with contexts; bad contexts rejected naming the field.
#include <gtest/gtest.h>

#include <cmath>

#include "identification_fixture.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/identification/extended_lm.hpp"
#include "rcal/identification/extended_measurement.hpp"
#include "rcal/sim/effects.hpp"

namespace rcal::identification {
namespace {

using kinematics::Effect;
using kinematics::EffectCause;
using kinematics::testing::UrLikeUrdf;

struct ExtScenario {
  kinematics::KinematicModel model;
  std::vector<int> identified;
  Eigen::VectorXd x_true;  ///< zero where not identified: the truth is on the base set
  sim::EffectTruth truth;  ///< hidden effects (maybe none) and their values
  std::vector<kinematics::PoseMeasurement> cal, test;
  std::vector<kinematics::EffectContext> cal_ctx, test_ctx;
  std::vector<Eigen::VectorXd> test_q;
};

// `effects` exist in the truth when `hidden`, each displacing the marker by `rms_over_noise`
// position σ beyond what geometry can absorb (sim::EffectOfSize).
ExtScenario MakeExtScenario(const kinematics::KinematicModel& model,
                            const std::vector<Effect>& effects, bool hidden, double rms_over_noise,
                            unsigned seed, int num_cal = 100) {
  ExtScenario s;
  s.model = model;
  sim::Rng rng(seed);
  const auto report =
      kinematics::AnalyzeIdentifiability(model, sim::SampleJoints(model, 80, rng), model.Nominal(),
                                         kinematics::MeasurementKind::kFullPose);
  s.identified = report.identifiable;
  s.x_true = Eigen::VectorXd::Zero(model.num_params());
  const Eigen::VectorXd x_random = sim::RandomErrors(model, rng, 1e-3, 1e-3);
  for (int i : s.identified) s.x_true(i) = x_random(i);
  const auto qs = sim::SampleJoints(model, num_cal, rng);
  s.cal_ctx = sim::SampleSession(model.num_joints(), num_cal, {}, rng);
  const sim::PoseNoise noise;
  std::vector<sim::TruthEffect> truth;
  if (hidden)
    for (const Effect& f : effects)
      truth.push_back(sim::EffectOfSize(model, f, qs, s.cal_ctx, s.x_true,
                                        rms_over_noise * noise.position_sigma, rng, {}, true));
  s.truth = sim::MakeEffectTruth(model, truth);
  s.cal = sim::MeasurePosesWithEffects(s.truth, s.x_true, qs, s.cal_ctx, noise, rng);
  s.test_q = sim::SampleJoints(model, 100, rng);
  s.test_ctx = sim::SampleSession(model.num_joints(), 100, {}, rng);
  s.test = sim::MeasurePosesWithEffects(s.truth, s.x_true, s.test_q, s.test_ctx, noise, rng);
  return s;
}

// RMS distance [m] between the held-out measured marker positions and a prediction.
template <typename Predict>
double HeldOutRms(const ExtScenario& s, Predict predict) {
  double ss = 0;
  for (size_t i = 0; i < s.test.size(); ++i)
    ss += (s.test[i].p_WM_W - predict(s.test_q[i], s.test_ctx[i])).squaredNorm();
  return std::sqrt(ss / s.test.size());
}

EkfIdentifier RunExtendedEkf(const ExtScenario& s, const kinematics::ExtendedModel& ext) {
  EkfIdentifier ekf(ext, s.identified);
  for (size_t k = 0; k < s.cal.size(); ++k)
    EXPECT_TRUE(ekf.Update(s.cal[k], s.cal_ctx[k]).accepted);
  return ekf;
}

const std::vector<Effect> kEffects = {
    {EffectCause::kJointCompliance, 1},   // shoulder_lift
    {EffectCause::kJointPeriodic, 2, 1},  // elbow, 1st harmonic
};

TEST(ExtendedEkf, MeasurementJacobianMatchesFiniteDifferences) {
  const auto model = UrLikeUrdf();
  const kinematics::ExtendedModel ext(
      model, {kEffects[0], kEffects[1], {EffectCause::kBacklash, 3}, {EffectCause::kThermal}});
  sim::Rng rng(5);
  const Eigen::VectorXd x = sim::RandomErrors(model, rng, 1e-3, 1e-3);
  Eigen::VectorXd e(ext.num_effect_params());
  e << 3e-6, 2e-4, -1e-4, 5e-5, 1e-5;
  auto ctx = sim::SampleSession(model.num_joints(), 3, {}, rng);
  const auto qs = sim::SampleJoints(model, 3, rng);
  const std::vector<int> identified = {0, 3, 7, 12, 20};
  for (int i = 0; i < 3; ++i) {
    // The exact pose of the extended model: r = 0, where −∂r/∂θ is H (away from r = 0 the
    // rotation residual's Log adds terms of the residual's size).
    kinematics::PoseMeasurement z;
    z.q = qs[i];
    const kinematics::ToolPose pose = ext.Forward(qs[i], ctx[i], x, e);
    z.p_WM_W = pose.p_WM_W;
    z.R_EI = pose.R_EI;
    z.has_orientation = true;
    z.covariance = Eigen::MatrixXd::Identity(6, 6);
    Eigen::VectorXd r;
    Eigen::MatrixXd H;
    ExtendedResidualAndJacobian(ext, z, ctx[i], x, e, identified, r, &H);
    ASSERT_EQ(H.rows(), 6);
    ASSERT_EQ(H.cols(), 5 + ext.num_effect_params());
    for (int c = 0; c < H.cols(); ++c) {
      const bool geo = c < 5;
      const double h = geo ? 1e-7 : std::max(1e-9, 1e-3 * std::abs(e(c - 5)));
      Eigen::VectorXd xp = x, xm = x, ep = e, em = e, rp, rm;
      if (geo) {
        xp(identified[c]) += h;
        xm(identified[c]) -= h;
      } else {
        ep(c - 5) += h;
        em(c - 5) -= h;
      }
      ExtendedResidualAndJacobian(ext, z, ctx[i], xp, ep, identified, rp, nullptr);
      ExtendedResidualAndJacobian(ext, z, ctx[i], xm, em, identified, rm, nullptr);
      const Eigen::VectorXd fd = -(rp - rm) / (2 * h);  // H = ∂h/∂θ = −∂r/∂θ
      EXPECT_LT((fd - H.col(c)).norm(), 1e-6 * std::max(1.0, fd.norm())) << "column " << c;
    }
  }
}

TEST(ExtendedEkf, RecoversHiddenEffectsAgreesWithBatchFitAndBeatsGeometry) {
  unsigned seed = 600;
  for (int round = 0; round < 3; ++round) {
    const ExtScenario s = MakeExtScenario(UrLikeUrdf(), kEffects, true, 6.0, seed++);
    const kinematics::ExtendedModel ext(s.model, kEffects);
    const EkfIdentifier ekf = RunExtendedEkf(s, ext);
    const Eigen::VectorXd e = ekf.e(), sigma_e = ekf.sigma_e();
    ASSERT_EQ(e.size(), 3);
    // Recovered within 3σ of the truth.
    for (int k = 0; k < e.size(); ++k) {
      const double z = (e(k) - s.truth.e(k)) / sigma_e(k);
      EXPECT_LT(std::abs(z), 3.0) << "seed " << seed - 1 << " e[" << k << "] " << e(k) << " truth "
                                  << s.truth.e(k) << " σ " << sigma_e(k);
      std::printf("seed %u: e[%d] = %.4g ± %.2g (truth %.4g, z %+.2f)\n", seed - 1, k, e(k),
                  sigma_e(k), s.truth.e(k), z);
    }
    // A real detection: each effect is many σ away from zero.
    for (size_t f = 0; f < kEffects.size(); ++f) {
      const int o = ext.effect_offset(f), np = kEffects[f].num_params();
      EXPECT_GT(s.truth.e.segment(o, np).norm(), 10 * sigma_e.segment(o, np).maxCoeff()) << f;
    }
    // Agrees with the batch extended fit (same weights, no noise re-estimation).
    const ExtendedFit lm = FitExtended(ext, s.identified, s.cal, s.cal_ctx, s.model.Nominal(),
                                       ext.NoEffects(), /*estimate_noise=*/false);
    double worst = 0;
    for (int k = 0; k < e.size(); ++k) {
      EXPECT_NEAR(ekf.sigma_e()(k) / lm.sigma_e(k), 1.0, 0.05) << k;
      EXPECT_LT(std::abs(e(k) - lm.e(k)), 0.03 * lm.sigma_e(k)) << k;
      worst = std::max(worst, std::abs(e(k) - lm.e(k)) / lm.sigma_e(k));
    }
    std::printf("seed %u: |e_EKF - e_batch| at most %.2g σ\n", seed - 1, worst);
    const Eigen::VectorXd x = ekf.x();
    double worst_x = 0;
    for (int i : s.identified) {
      EXPECT_LT(std::abs(x(i) - lm.x(i)), 0.03 * ekf.sigma()(i)) << s.model.parameters()[i].name;
      worst_x = std::max(worst_x, std::abs(x(i) - lm.x(i)) / ekf.sigma()(i));
    }
    std::printf("seed %u: |x_EKF - x_batch| at most %.2g σ\n", seed - 1, worst_x);

    // Held-out: extended ≈ truth model (the noise), geometric EKF clearly worse.
    // The geometric EKF on the same poses, its gate off (the gate rejects most poses the
    // effects moved: the best the geometric model can do with all of them).
    EkfSettings no_gate;
    no_gate.gate_probability = 1.0;
    EkfIdentifier geo(s.model, s.identified, no_gate);
    for (const auto& m : s.cal) EXPECT_TRUE(geo.Update(m).accepted);
    const double rms_truth = HeldOutRms(s, [&](const auto& q, const auto& c) {
      return s.truth.model.Forward(q, c, s.x_true, s.truth.e).p_WM_W;
    });
    const double rms_ext =
        HeldOutRms(s, [&](const auto& q, const auto& c) { return ext.Forward(q, c, x, e).p_WM_W; });
    const Eigen::VectorXd x_geo = geo.x();
    const double rms_geo =
        HeldOutRms(s, [&](const auto& q, const auto&) { return s.model.Forward(q, x_geo).p_WM_W; });
    std::printf(
        "seed %u: held-out position RMS truth %.4f mm, extended %.4f mm, geometric %.4f mm"
        "\n",
        seed - 1, rms_truth * 1e3, rms_ext * 1e3, rms_geo * 1e3);
    EXPECT_LT(rms_ext, 1.1 * rms_truth);
    EXPECT_GT(rms_geo, 2.0 * rms_ext);
  }
}

TEST(ExtendedEkf, WithoutTheEffectTheEffectParametersStayAtZero) {
  unsigned seed = 700;
  double sum_z2 = 0;
  int count = 0;
  for (int round = 0; round < 4; ++round) {
    const ExtScenario s = MakeExtScenario(UrLikeUrdf(), kEffects, false, 0.0, seed++);
    ASSERT_EQ(s.truth.e.size(), 0);
    const kinematics::ExtendedModel ext(s.model, kEffects);
    const EkfIdentifier ekf = RunExtendedEkf(s, ext);
    for (int k = 0; k < ekf.e().size(); ++k) {
      const double z = ekf.e()(k) / ekf.sigma_e()(k);
      std::printf("seed %u: e[%d] = %.3g ± %.2g (z %+.2f)\n", seed - 1, k, ekf.e()(k),
                  ekf.sigma_e()(k), z);
      EXPECT_LT(std::abs(z), 3.0) << "seed " << seed - 1 << " e[" << k << "]";
      sum_z2 += z * z;
      ++count;
    }
    // The σ is the data's, not the prior's: far below the prior.
    const Eigen::VectorXd prior = DefaultEffectPriorSigma(ext);
    for (int k = 0; k < prior.size(); ++k) EXPECT_LT(ekf.sigma_e()(k), 0.05 * prior(k));
  }
  // On average within its σ of 0 (RMS z over 12 parameters).
  EXPECT_LT(std::sqrt(sum_z2 / count), 1.5);
}

TEST(ExtendedEkf, CheckpointWithContextsResumesExactlyAndBadInputIsRefused) {
  const ExtScenario s = MakeExtScenario(UrLikeUrdf(), kEffects, true, 6.0, 800, 30);
  const kinematics::ExtendedModel ext(s.model, kEffects);
  EkfIdentifier a(ext, s.identified), b(ext, s.identified);
  for (int k = 0; k < 15; ++k) ASSERT_TRUE(a.Update(s.cal[k], s.cal_ctx[k]).accepted);
  const EkfCheckpoint c = a.Checkpoint();
  ASSERT_EQ(c.contexts.size(), 15u);
  ASSERT_EQ(c.x.size(), static_cast<int>(s.identified.size()) + 3);
  b.Restore(c);
  for (int k = 15; k < 30; ++k) {
    a.Update(s.cal[k], s.cal_ctx[k]);
    b.Update(s.cal[k], s.cal_ctx[k]);
  }
  b.Refine(3);
  a.Refine(3);
  EXPECT_EQ(a.state(), b.state());
  EXPECT_EQ(a.P(), b.P());
  EXPECT_EQ(b.accepted(), 30);

  // A checkpoint of another shape, or with broken contexts, is refused naming the field.
  EkfCheckpoint bad = a.Checkpoint();
  bad.contexts.pop_back();
  try {
    b.Restore(bad);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("contexts"), std::string::npos) << e.what();
  }
  bad = a.Checkpoint();
  bad.contexts[3].dq_sign = Eigen::VectorXi::Constant(2, 1);
  try {
    b.Restore(bad);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("contexts[3].dq_sign"), std::string::npos) << e.what();
  }
  EkfIdentifier geometric(s.model, s.identified);
  EXPECT_THROW(geometric.Restore(a.Checkpoint()), std::invalid_argument);  // state size
  EXPECT_EQ(a.state(), b.state());

  // A bad context is rejected, counted, and leaves the state alone.
  const Eigen::VectorXd before = b.state();
  kinematics::EffectContext ctx = s.test_ctx[0];
  ctx.dq_sign(1) = 2;
  EkfUpdateResult r = b.Update(s.test[0], ctx);
  EXPECT_FALSE(r.accepted);
  EXPECT_NE(r.reason.find("dq_sign"), std::string::npos) << r.reason;
  ctx = s.test_ctx[0];
  ctx.temperature_c = INFINITY;
  r = b.Update(s.test[0], ctx);
  EXPECT_NE(r.reason.find("temperature_c"), std::string::npos) << r.reason;
  EXPECT_EQ(b.rejected(), 2);
  EXPECT_EQ(b.state(), before);

  // Settings of the wrong size are refused naming the setting.
  EkfSettings settings;
  settings.prior_sigma_effects = Eigen::VectorXd::Ones(2);
  try {
    EkfIdentifier bad_settings(ext, s.identified, settings);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("prior_sigma_effects"), std::string::npos) << e.what();
  }
}

TEST(ExtendedEkf, HeldOutExtendedJudgesOnTheFoldsOfHeldOut) {
  // k-fold over the calibration poses: the geometric figures are HeldOut's, bit for bit; the
  // extended model's held-out error is at the noise, the geometric one well above.
  const ExtScenario s = MakeExtScenario(UrLikeUrdf(), kEffects, true, 6.0, 610, 80);
  const kinematics::ExtendedModel ext(s.model, kEffects);
  CalibrationSettings settings;
  const CalibrationFit fit = Calibrate(s.model, s.cal, settings);
  const HeldOutErrors held = HeldOut(s.model, s.cal, {}, fit, settings);
  const ExtendedHeldOutErrors xh =
      HeldOutExtended(ext, s.cal, s.cal_ctx, {}, fit, ext.NoEffects(), settings);
  EXPECT_EQ(xh.scheme, held.scheme);
  EXPECT_EQ(xh.nominal.position_m, held.nominal.position_m);
  EXPECT_EQ(xh.geometric.position_m, held.calibrated.position_m);
  ASSERT_EQ(xh.extended.position_m.size(), s.cal.size());
  const double noise_rms = std::sqrt(3.0) * sim::PoseNoise{}.position_sigma;
  std::printf("k-fold held-out RMS: geometric %.4f mm, extended %.4f mm (noise %.4f mm)\n",
              xh.geometric.rms_position_m * 1e3, xh.extended.rms_position_m * 1e3, noise_rms * 1e3);
  EXPECT_LT(xh.extended.rms_position_m, 1.25 * noise_rms);
  EXPECT_GT(xh.geometric.rms_position_m, 2.0 * xh.extended.rms_position_m);
  EXPECT_THROW(HeldOutExtended(ext, s.cal, {}, {}, fit, ext.NoEffects()), std::invalid_argument);
}

TEST(ExtendedEkf, WithoutEffectsItIsTheGeometricFilter) {
  // Built on an ExtendedModel with no effects, the filter is bit for bit the geometric one.
  const testing::Scenario s = testing::MakeScenario(UrLikeUrdf(), sim::PoseNoise{}, 900, 30);
  EkfIdentifier geo(s.model, s.identified),
      ext(kinematics::ExtendedModel(s.model, {}), s.identified);
  kinematics::EffectContext ctx;
  ctx.temperature_c = 30;
  for (const auto& m : s.cal) {
    geo.Update(m);
    ext.Update(m, ctx);
  }
  EXPECT_EQ(geo.state(), ext.state());
  EXPECT_EQ(geo.P(), ext.P());
  EXPECT_EQ(ext.e().size(), 0);
}

}  // namespace
}  // namespace rcal::identification
