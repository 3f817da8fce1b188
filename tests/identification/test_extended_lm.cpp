// The batch extended fit (identification/extended_lm.hpp) against a simulated ground truth built
// here by hand (ExtendedModel::Forward at known x and e, Gaussian noise of known σ): exact data
// give back the truth and the parameters it was not asked to fit untouched; the covariance is
// (JᵀR⁻¹J)⁻¹ with J by central finite differences; over seeded noisy runs the errors are
// N(0, σ_e²) (z-score RMS near 1) and the a-posteriori noise near the true noise; geometry steps
// at known poses are fitted with the rest, their amplitudes as exact and as calibrated.
#include "rcal/identification/extended_lm.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <cmath>
#include <random>
#include <stdexcept>

#include "../kinematics/test_robots.hpp"
#include "rcal/identification/extended_measurement.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/sim/draw.hpp"
#include "rcal/sim/effects.hpp"

namespace rcal::identification {
namespace {

using kinematics::Effect;
using kinematics::EffectCause;
using kinematics::EffectContext;
using kinematics::ExtendedModel;
using kinematics::PoseMeasurement;

constexpr double kSigmaP = 1e-4, kSigmaR = 1e-3;  // [m], [rad] per axis

struct Problem {
  kinematics::KinematicModel model = kinematics::testing::UrLikeUrdf();
  ExtendedModel ext;
  std::vector<int> identified;
  Eigen::VectorXd x_true, e_true;
  std::vector<Eigen::VectorXd> qs;
  std::vector<EffectContext> ctx;
};

Problem MakeProblem(unsigned seed, int poses, bool orientation = true) {
  Problem p;
  Effect thermal{EffectCause::kThermal};
  thermal.reference = 20.0;
  p.ext = ExtendedModel(p.model, {{EffectCause::kJointCompliance, 1},
                                  {EffectCause::kJointPeriodic, 2, 1},
                                  {EffectCause::kJointScale, 3},
                                  {EffectCause::kBacklash, 4},
                                  thermal});
  std::mt19937 rng(seed);
  for (int k = 0; k < poses; ++k) p.qs.push_back(kinematics::testing::RandomJoints(p.model, rng));
  sim::Rng srng(seed);
  p.ctx = sim::SampleSession(p.model.num_joints(), poses, {}, srng);
  p.identified =
      kinematics::AnalyzeIdentifiability(p.model, p.qs, p.model.Nominal(),
                                         orientation ? kinematics::MeasurementKind::kFullPose
                                                     : kinematics::MeasurementKind::kPositionOnly)
          .identifiable;
  // Truth: random errors everywhere (the parameters not identified keep theirs, given in x0).
  p.x_true = kinematics::testing::RandomErrors(p.model, rng, 1e-3, 1e-3);
  p.e_true.resize(p.ext.num_effect_params());
  p.e_true << 3e-6, 1e-3, -5e-4, 2e-3, 5e-4, 2e-5;
  return p;
}

// Measurements of the truth with noise of σ = (kSigmaP, kSigmaR) times `noise` (0: exact), the
// covariances stating (kSigmaP, kSigmaR).
// With `steps`, pose k is measured at GeometryAt(x_true, steps, amplitudes, k).
std::vector<PoseMeasurement> Measure(const Problem& p, double noise, unsigned seed,
                                     bool orientation = true,
                                     const std::vector<GeometryStep>& steps = {},
                                     const std::vector<Eigen::VectorXd>& amplitudes = {}) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<PoseMeasurement> ms;
  for (size_t k = 0; k < p.qs.size(); ++k) {
    const Eigen::VectorXd x_k = GeometryAt(p.x_true, steps, amplitudes, static_cast<int>(k));
    const kinematics::ToolPose pose = p.ext.Forward(p.qs[k], p.ctx[k], x_k, p.e_true);
    PoseMeasurement z;
    z.q = p.qs[k];
    z.p_WM_W = pose.p_WM_W + noise * kSigmaP * sim::Draw3(n, rng);
    const Eigen::Vector3d w = noise * kSigmaR * sim::Draw3(n, rng);
    z.R_EI = (w.norm() > 0 ? Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix()
                           : Eigen::Matrix3d::Identity()) *
             pose.R_EI;
    z.has_orientation = orientation;
    Eigen::VectorXd var(6);
    var << kSigmaP * kSigmaP, kSigmaP * kSigmaP, kSigmaP * kSigmaP, kSigmaR * kSigmaR,
        kSigmaR * kSigmaR, kSigmaR * kSigmaR;
    z.covariance = var.head(z.dimension()).asDiagonal();
    ms.push_back(z);
  }
  return ms;
}

// x0: the truth where not identified, zero where identified.
Eigen::VectorXd StartX(const Problem& p) {
  Eigen::VectorXd x0 = p.x_true;
  for (int i : p.identified) x0(i) = 0.0;
  return x0;
}

TEST(ExtendedLm, ExactDataGiveBackTheTruth) {
  const Problem p = MakeProblem(11, 60);
  const auto ms = Measure(p, 0.0, 1);
  const Eigen::VectorXd x0 = StartX(p);
  const ExtendedFit f = FitExtended(p.ext, p.identified, ms, p.ctx, x0, p.ext.NoEffects());
  for (int i = 0; i < p.model.num_params(); ++i)
    EXPECT_NEAR(f.x(i), p.x_true(i), 1e-9) << p.model.parameters()[i].name;
  for (int k = 0; k < p.e_true.size(); ++k)
    EXPECT_NEAR(f.e(k), p.e_true(k), 1e-6 * std::abs(p.e_true(k))) << k;
  // Not asked to fit: exactly as given.
  std::vector<bool> fitted(p.model.num_params(), false);
  for (int i : p.identified) fitted[i] = true;
  for (int i = 0; i < p.model.num_params(); ++i) {
    if (!fitted[i]) {
      EXPECT_EQ(f.x(i), x0(i)) << p.model.parameters()[i].name;
    }
  }
  EXPECT_LT(f.position_sigma_m, 1e-9);
}

TEST(ExtendedLm, CovarianceIsTheInverseInformationOfTheFiniteDifferenceJacobian) {
  // Position only: there H is the exact derivative of the residual even where r ≠ 0, so the
  // optimum's gradient can be checked too.
  const Problem p = MakeProblem(12, 50, false);
  const auto ms = Measure(p, 1.0, 2, false);
  const ExtendedFit f =
      FitExtended(p.ext, p.identified, ms, p.ctx, StartX(p), p.ext.NoEffects(), false);
  // Whitened Jacobian of the stacked residuals at the optimum, by central differences.
  const int ng = p.identified.size(), ne = p.ext.num_effect_params(), np = ng + ne;
  const int rows = 3 * static_cast<int>(ms.size());
  const auto stacked = [&](const Eigen::VectorXd& x, const Eigen::VectorXd& e) {
    Eigen::VectorXd b(rows), r;
    for (size_t i = 0; i < ms.size(); ++i) {
      ExtendedResidualAndJacobian(p.ext, ms[i], p.ctx[i], x, e, {}, r, nullptr);
      b.segment<3>(3 * i) = r / kSigmaP;
    }
    return b;
  };
  Eigen::MatrixXd J(rows, np);
  for (int c = 0; c < np; ++c) {
    Eigen::VectorXd xp = f.x, xm = f.x, ep = f.e, em = f.e;
    const double h = c < ng ? 1e-7 : 1e-4 * std::max(std::abs(p.e_true(c - ng)), 1e-6);
    if (c < ng) {
      xp(p.identified[c]) += h;
      xm(p.identified[c]) -= h;
    } else {
      ep(c - ng) += h;
      em(c - ng) -= h;
    }
    J.col(c) = -(stacked(xp, ep) - stacked(xm, em)) / (2 * h);
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(J);
  ASSERT_GT(svd.singularValues().minCoeff(), 1e-8 * svd.singularValues().maxCoeff());
  const Eigen::MatrixXd C = (J.transpose() * J).inverse();
  for (int k = 0; k < ne; ++k)
    EXPECT_NEAR(f.sigma_e(k) / std::sqrt(C(ng + k, ng + k)), 1.0, 1e-3) << k;
  // The gradient vanishes at the optimum (first-order optimality): Jᵀb ≈ 0 against |J||b|.
  const Eigen::VectorXd b = stacked(f.x, f.e);
  for (int c = 0; c < np; ++c)
    EXPECT_LT(std::abs(J.col(c).dot(b)), 1e-6 * J.col(c).norm() * b.norm()) << c;
}

TEST(ExtendedLm, OverSeededNoiseTheErrorsMatchSigmaAndTheNoiseIsReestimated) {
  const Problem p = MakeProblem(13, 60);
  const int runs = 40, ne = p.ext.num_effect_params();
  Eigen::VectorXd z2 = Eigen::VectorXd::Zero(ne);
  double noise_ratio = 0, position_ratio = 0;
  for (int run = 0; run < runs; ++run) {
    // Noise twice what the covariances say: estimate_noise must find the factor 2.
    std::vector<PoseMeasurement> ms = Measure(p, 2.0, 100 + run);
    const ExtendedFit given =
        FitExtended(p.ext, p.identified, ms, p.ctx, StartX(p), p.ext.NoEffects(), false);
    const ExtendedFit f =
        FitExtended(p.ext, p.identified, ms, p.ctx, StartX(p), p.ext.NoEffects(), true);
    for (int k = 0; k < ne; ++k) {
      EXPECT_NEAR(f.e(k), given.e(k), 1e-9 * std::max(1.0, std::abs(given.e(k)))) << k;
      const double z = (f.e(k) - p.e_true(k)) / f.sigma_e(k);
      z2(k) += z * z / runs;
    }
    noise_ratio += f.sigma_e(0) / given.sigma_e(0) / runs;
    position_ratio += f.position_sigma_m / kSigmaP / runs;
  }
  // E[z²] = 1 with the re-estimated σ; 40 runs: ±0.45 holds at well over 3σ of the χ² spread.
  for (int k = 0; k < ne; ++k) {
    EXPECT_GT(z2(k), 0.55) << "e[" << k << "] z² mean " << z2(k);
    EXPECT_LT(z2(k), 1.45) << "e[" << k << "] z² mean " << z2(k);
  }
  EXPECT_NEAR(noise_ratio, 2.0, 0.1);
  EXPECT_NEAR(position_ratio, 2.0, 0.2);
}

// Two steps of the geometry (an encoder re-mastered at pose 20: one identified parameter; a
// knock at pose 40: two others together) fitted with the rest: exact data give back the
// amplitudes, and over seeded noise their errors are N(0, σ²) as the effects' are.
std::vector<GeometryStep> TwoSteps(const Problem& p) {
  const int nx = p.model.num_params();
  GeometryStep a{20, Eigen::MatrixXd::Zero(nx, 1)}, b{40, Eigen::MatrixXd::Zero(nx, 2)};
  a.directions(p.identified[2], 0) = 1.0;
  b.directions(p.identified[5], 0) = b.directions(p.identified[7], 0) = std::sqrt(0.5);
  b.directions(p.identified[9], 1) = 1.0;
  return {a, b};
}

TEST(ExtendedLm, GeometryStepsAreFittedWithTheRest) {
  const Problem p = MakeProblem(15, 60);
  const std::vector<GeometryStep> steps = TwoSteps(p);
  const std::vector<Eigen::VectorXd> truth = {Eigen::VectorXd::Constant(1, 1e-3),
                                              Eigen::Vector2d(-5e-4, 3e-4)};
  const auto exact = Measure(p, 0.0, 4, true, steps, truth);
  const ExtendedFit f =
      FitExtended(p.ext, p.identified, exact, p.ctx, StartX(p), p.ext.NoEffects(), true, steps);
  ASSERT_EQ(f.step_amplitudes.size(), 2u);
  for (size_t s = 0; s < steps.size(); ++s)
    for (int k = 0; k < truth[s].size(); ++k)
      EXPECT_NEAR(f.step_amplitudes[s](k), truth[s](k), 1e-9) << s << "," << k;
  for (int i : p.identified) EXPECT_NEAR(f.x(i), p.x_true(i), 1e-9);
  // Without the steps the same data cannot be fitted.
  const ExtendedFit one =
      FitExtended(p.ext, p.identified, exact, p.ctx, StartX(p), p.ext.NoEffects(), true);
  EXPECT_GT(one.position_sigma_m, 1e-5);

  const int runs = 60;
  Eigen::Vector3d z2 = Eigen::Vector3d::Zero();
  for (int run = 0; run < runs; ++run) {
    const auto ms = Measure(p, 1.0, 300 + run, true, steps, truth);
    const ExtendedFit g =
        FitExtended(p.ext, p.identified, ms, p.ctx, StartX(p), p.ext.NoEffects(), false, steps);
    const Eigen::Vector3d a(g.step_amplitudes[0](0), g.step_amplitudes[1](0),
                            g.step_amplitudes[1](1));
    const Eigen::Vector3d sa(g.step_sigma[0](0), g.step_sigma[1](0), g.step_sigma[1](1));
    const Eigen::Vector3d t(1e-3, -5e-4, 3e-4);
    z2 += ((a - t).array() / sa.array()).square().matrix() / runs;
  }
  // E[z²] = 1; 60 runs: ±0.55 holds at 3σ of the χ² spread (200 runs: 0.92, 1.03, 1.19).
  for (int k = 0; k < 3; ++k) {
    EXPECT_GT(z2(k), 0.45) << k;
    EXPECT_LT(z2(k), 1.55) << k;
  }
}

TEST(ExtendedLm, InconsistentSizesAreRefusedNamingTheArgument) {
  const Problem p = MakeProblem(14, 10);
  const auto ms = Measure(p, 0.0, 3);
  const auto message = [&](auto call) -> std::string {
    try {
      call();
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "<no error>";
  };
  const Eigen::VectorXd x0 = p.model.Nominal(), e0 = p.ext.NoEffects();
  auto fewer = p.ctx;
  fewer.pop_back();
  EXPECT_NE(message([&] { FitExtended(p.ext, p.identified, ms, fewer, x0, e0); }).find("context"),
            std::string::npos);
  EXPECT_NE(message([&] {
              FitExtended(p.ext, p.identified, ms, p.ctx, Eigen::VectorXd::Zero(3), e0);
            }).find("x0"),
            std::string::npos);
  EXPECT_NE(message([&] {
              FitExtended(p.ext, p.identified, ms, p.ctx, x0, Eigen::VectorXd::Zero(2));
            }).find("e0"),
            std::string::npos);
  const int nx = p.model.num_params();
  for (const GeometryStep& bad : {GeometryStep{0, Eigen::MatrixXd::Identity(nx, 1)},
                                  GeometryStep{10, Eigen::MatrixXd::Identity(nx, 1)}})
    EXPECT_NE(message([&] {
                FitExtended(p.ext, p.identified, ms, p.ctx, x0, e0, true, {bad});
              }).find("steps[0].first_pose"),
              std::string::npos);
  Eigen::MatrixXd nan = Eigen::MatrixXd::Identity(nx, 1);
  nan(0, 0) = std::nan("");
  for (const GeometryStep& bad :
       {GeometryStep{5, Eigen::MatrixXd::Identity(3, 1)}, GeometryStep{5, nan}})
    EXPECT_NE(message([&] {
                FitExtended(p.ext, p.identified, ms, p.ctx, x0, e0, true, {bad});
              }).find("steps[0].directions"),
              std::string::npos);
}

}  // namespace
}  // namespace rcal::identification
