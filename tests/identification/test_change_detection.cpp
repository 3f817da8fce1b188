#include "rcal/identification/change_detection.hpp"

#include <gtest/gtest.h>

#include <random>

#include "rcal/identification/chi_square.hpp"

namespace rcal::identification {
namespace {

TEST(ChangeDetection, UpperQuantileFromLogAgreesWithTheQuantile) {
  for (double dof : {1.0, 3.0, 12.0})
    for (double p : {0.9, 0.999, 0.9999999})
      EXPECT_NEAR(ChiSquareUpperQuantileLog(std::log1p(-p), dof) / ChiSquareQuantile(p, dof), 1.0,
                  1e-6);
  // Far beyond what 1 − p holds: the χ²(1) tail of z = 8 is 1.2e-15 (closed form 2Φ(−8)).
  EXPECT_NEAR(ChiSquareUpperQuantileLog(std::log(std::erfc(8 / std::sqrt(2.0))), 1), 64, 1e-3);
}

// Poses of `dims` whitened rows each with random Jacobians over `n` parameters.
struct Synthetic {
  std::vector<Eigen::VectorXd> e;
  std::vector<Eigen::MatrixXd> A;
};
Synthetic Make(int poses, int dims, int n, unsigned seed, int onset, int column, double step) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 1);
  Synthetic s;
  for (int k = 0; k < poses; ++k) {
    Eigen::MatrixXd A(dims, n);
    for (int i = 0; i < A.size(); ++i) A(i) = g(rng);
    Eigen::VectorXd e(dims);
    for (int i = 0; i < dims; ++i) e(i) = g(rng);
    if (k >= onset) e += A.col(column) * step;
    s.e.push_back(e);
    s.A.push_back(A);
  }
  return s;
}

TEST(ChangeDetection, FindsTheStepItsParameterOnsetAndSize) {
  // A step of 4 (in σ of one pose's sensitivity) in column 7 from pose 6 of 10.
  const Synthetic s = Make(10, 6, 20, 1, 6, 7, 4.0);
  const StepTestResult r = TestForStep(s.e, s.A, {});
  ASSERT_TRUE(r.detected);
  EXPECT_EQ(r.columns, std::vector<int>{7});
  EXPECT_EQ(r.onset, 6);
  EXPECT_NEAR(r.step(0), 4.0, 3 * r.step_sigma(0));
  EXPECT_GT(r.glr, r.threshold);
}

TEST(ChangeDetection, WhiteNoiseRaisesNothingAtTheSetRate) {
  // 2000 windows of white noise at a false-alarm rate of 1e-3: Bonferroni keeps the rate of the
  // maximum at or below it (expected ≤ 2 alarms; more than 8 has probability < 1e-4).
  StepTestSettings set;
  set.false_alarm = 1e-3;
  int alarms = 0;
  for (unsigned seed = 0; seed < 2000; ++seed)
    alarms += TestForStep(Make(10, 6, 20, 100 + seed, 99, 0, 0).e,
                          Make(10, 6, 20, 100 + seed, 99, 0, 0).A, set)
                  .detected;
  EXPECT_LE(alarms, 8);
}

TEST(ChangeDetection, AnOutlierPoseIsNotAStep) {
  Synthetic s = Make(10, 6, 20, 3, 99, 0, 0);
  s.e[7](2) += 30;  // one 30σ outlier
  const StepTestResult r = TestForStep(s.e, s.A, {});
  EXPECT_FALSE(r.detected);
  EXPECT_GT(r.post_fit_chi2, 100);
}

TEST(ChangeDetection, TwoParametersAreNamedWhenOneDoesNotExplainTheStep) {
  Synthetic s = Make(10, 6, 20, 4, 5, 3, 5.0);
  for (size_t k = 5; k < s.e.size(); ++k) s.e[k] += s.A[k].col(11) * -5.0;
  const StepTestResult r = TestForStep(s.e, s.A, {});
  ASSERT_TRUE(r.detected);
  ASSERT_EQ(r.columns.size(), 2u);
  EXPECT_EQ(std::min(r.columns[0], r.columns[1]), 3);
  EXPECT_EQ(std::max(r.columns[0], r.columns[1]), 11);
}

TEST(ChangeDetection, MismatchedSizesAreRefusedNamingThem) {
  Synthetic s = Make(4, 6, 5, 5, 99, 0, 0);
  s.A[2] = Eigen::MatrixXd::Zero(3, 5);
  EXPECT_THROW(TestForStep(s.e, s.A, {}), std::invalid_argument);
  s.e.pop_back();
  EXPECT_THROW(TestForStep(s.e, s.A, {}), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::identification
