#include "rcal/identification/metrics.hpp"

#include <gtest/gtest.h>

#include "identification_fixture.hpp"
#include "rcal/sim/effects.hpp"

namespace rcal::identification {
namespace {

TEST(Metrics, SummaryOfKnownErrors) {
  const PoseErrorStats s = Summarize({0.001, 0.003, 0.002}, {0.01, 0.03});
  EXPECT_DOUBLE_EQ(s.mean_position_m, 0.002);
  EXPECT_DOUBLE_EQ(s.max_position_m, 0.003);
  EXPECT_NEAR(s.rms_position_m, std::sqrt((1 + 9 + 4) / 3.0) * 1e-3, 1e-15);
  EXPECT_DOUBLE_EQ(s.mean_orientation_rad, 0.02);
}

TEST(Metrics, ErrorsAgainstTruthAndMeasurementsAgreeWithoutNoise) {
  const auto model = kinematics::testing::Grb3016();
  sim::Rng rng(5);
  const Eigen::VectorXd x_true = sim::Table3Errors(model);
  const auto qs = sim::SampleJoints(model, 20, rng);
  sim::PoseNoise exact;
  exact.position_sigma = exact.orientation_sigma = 0;
  std::vector<kinematics::PoseMeasurement> ms;
  for (const auto& q : qs) {
    auto m = sim::MeasurePose(model, x_true, q, exact, rng);
    m.covariance = Eigen::MatrixXd::Identity(6, 6);
    ms.push_back(m);
  }
  const auto a = ErrorsAgainstTruth(model, model.Nominal(), x_true, qs);
  const auto b = ErrorsAgainstMeasurements(model, model.Nominal(), ms);
  EXPECT_NEAR(a.mean_position_m, b.mean_position_m, 1e-15);
  EXPECT_NEAR(a.max_orientation_rad, b.max_orientation_rad, 1e-12);
  EXPECT_GT(a.mean_position_m, 0.01);  // Table 3 moves the tool by centimetres
}

// The extended model against noise-free measurements of an arm that bends (joint 2 compliance,
// payloads 0–10 kg): 0 at the true effect, under each pose's context; the geometric part alone
// (effect 0) misses by the deflection. A context list of the wrong size is refused.
TEST(Metrics, ErrorsOfAnExtendedModelUnderEachContext) {
  const auto model = kinematics::testing::Grb3016();
  sim::Rng rng(6);
  const Eigen::VectorXd x_true = sim::Table3Errors(model);
  const sim::TruthEffect t = sim::ParseEffectSpec("joint_compliance:j2=5e-6", model);
  const sim::EffectTruth truth = sim::MakeEffectTruth(model, {t});
  const auto qs = sim::SampleJoints(model, 20, rng);
  const auto contexts = sim::SampleSession(model.num_joints(), 20, sim::SessionSettings{}, rng);
  sim::PoseNoise exact;
  exact.position_sigma = exact.orientation_sigma = 0;
  const auto ms = sim::MeasurePosesWithEffects(truth, x_true, qs, contexts, exact, rng);
  const auto at_truth = ErrorsAgainstMeasurements(truth.model, x_true, truth.e, ms, contexts);
  EXPECT_LT(at_truth.max_position_m, 1e-12);
  EXPECT_LT(at_truth.max_orientation_rad, 1e-12);
  const auto without =
      ErrorsAgainstMeasurements(truth.model, x_true, truth.model.NoEffects(), ms, contexts);
  EXPECT_GT(without.mean_position_m, 1e-4);  // 5e-6 rad/(N·m) · ~100 N·m · ~1 m
  EXPECT_THROW(ErrorsAgainstMeasurements(truth.model, x_true, truth.e, ms, {contexts[0]}),
               std::invalid_argument);
}

// A joint that reads 1 mrad less than where it stands: the model with that joint's offset 1 mrad
// larger, at the readings, is the truth (θ2 of a D–H arm is the offset of joint 2); the model
// without it misses.
TEST(Metrics, ErrorsAgainstTruthWhereTheReadingsAreOff) {
  const auto model = kinematics::testing::Grb3016();
  sim::Rng rng(6);
  const Eigen::VectorXd x_true = sim::Table3Errors(model);
  const auto qs = sim::SampleJoints(model, 20, rng);
  std::vector<Eigen::VectorXd> qs_true;
  for (const auto& q : qs) qs_true.push_back(q + 1e-3 * Eigen::VectorXd::Unit(q.size(), 1));
  Eigen::VectorXd x_shifted = x_true;
  x_shifted(model.FindParameter("theta2")) += 1e-3;
  const auto shifted = ErrorsAgainstTruth(model, x_shifted, x_true, qs, qs_true);
  EXPECT_LT(shifted.max_position_m, 1e-12);
  EXPECT_LT(shifted.max_orientation_rad, 1e-12);
  const auto unshifted = ErrorsAgainstTruth(model, x_true, x_true, qs, qs_true);
  EXPECT_GT(unshifted.mean_position_m, 3e-4);  // 1 mrad at the arm's reach
  EXPECT_NEAR(unshifted.mean_orientation_rad, 1e-3, 1e-9);
  EXPECT_THROW(ErrorsAgainstTruth(model, x_true, x_true, qs, {qs.front()}), std::invalid_argument);
}

TEST(Metrics, PredictionMatchesAnalyticMeanForIsotropicCase) {
  // One parameter moving the marker along x with σ = 1 mm: E|δp| = σ·sqrt(2/π).
  kinematics::ModelBuilder b("slide");
  b.MarkerOffset({0.1, 0.0, 0.0});
  const auto model = b.Build();
  const Eigen::MatrixXd C = Eigen::MatrixXd::Identity(1, 1) * 1e-6;
  const std::vector<Eigen::VectorXd> qs(10, Eigen::VectorXd(0));
  const auto [p, o] = PredictedMeanErrors(model, {0}, C, model.Nominal(), qs, 3, 2000);
  EXPECT_NEAR(p / (1e-3 * std::sqrt(2 / M_PI)), 1.0, 0.02);
  EXPECT_EQ(o, 0.0);
}

TEST(Metrics, QuantileOfOneCalibrationsMeanErrorMatchesTheHalfNormal) {
  // One parameter, every pose moved alike: one calibration's mean error over the poses is σ|z|,
  // so its p-quantile is σ Φ⁻¹((1 + p)/2): 0.6745 σ at p = 0.5, 1.6449 σ at 0.9, 3.2905 σ at 0.999.
  // (Drawn per pose instead, as PredictedMeanErrors does, the mean over 10 poses would be near
  // E|z| = 0.80 σ at every p: the spread of one calibration is what this gives and that hides.)
  kinematics::ModelBuilder b("slide");
  b.MarkerOffset({0.1, 0.0, 0.0});
  const auto model = b.Build();
  const Eigen::MatrixXd C = Eigen::MatrixXd::Identity(1, 1) * 1e-6;
  const std::vector<Eigen::VectorXd> qs(10, Eigen::VectorXd(0));
  for (const auto& [p, k] : {std::pair{0.5, 0.6745}, {0.9, 1.6449}, {0.999, 3.2905}}) {
    const double q = MeanPositionErrorQuantile(model, {0}, C, model.Nominal(), qs, p, 3, 200000);
    EXPECT_NEAR(q / (1e-3 * k), 1.0, p > 0.99 ? 0.05 : 0.01) << "p = " << p;
  }
  EXPECT_THROW(MeanPositionErrorQuantile(model, {0}, C, model.Nominal(), qs, 1.0),
               std::invalid_argument);
  EXPECT_THROW(MeanPositionErrorQuantile(model, {0}, C, model.Nominal(), qs, 0.5, 1, 0),
               std::invalid_argument);
  EXPECT_THROW(MeanPositionErrorQuantile(model, {0}, Eigen::MatrixXd::Identity(2, 2),
                                         model.Nominal(), qs, 0.5),
               std::invalid_argument);
}

}  // namespace
}  // namespace rcal::identification
