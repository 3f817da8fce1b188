#include "rcal/identification/change_detection.hpp"

#include <gtest/gtest.h>

#include <algorithm>
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

TEST(ChangeDetection, AlternativesAreTheLikeliestColumnsUpToTheProbability) {
  // Closed form: unit N, so g_j = b_j² and p_j = exp(g_j/2) / Σ exp(g_i/2). Column 4 repeats
  // column 0 (one hypothesis, counted once).
  Eigen::MatrixXd N = Eigen::MatrixXd::Identity(5, 5);
  N(0, 4) = N(4, 0) = 1;
  const Eigen::VectorXd b = (Eigen::VectorXd(5) << 3.0, 2.8, 0.0, 1.0, 3.0).finished();
  const double w[4] = {std::exp(4.5), std::exp(3.92), 1.0, std::exp(0.5)},
               sum = w[0] + w[1] + w[2] + w[3];
  std::vector<double> p;
  Eigen::VectorXd step, sigma;
  // p_0 = 0.629, p_1 = 0.352, p_3 = 0.0115, p_2 = 0.0070.
  EXPECT_EQ(StepAlternatives(N, b, {}, 0.99, 3, &p, &step, &sigma), (std::vector<int>{0, 1, 3}));
  ASSERT_EQ(p.size(), 3u);
  EXPECT_NEAR(p[0], w[0] / sum, 1e-12);
  EXPECT_NEAR(p[1], w[1] / sum, 1e-12);
  EXPECT_NEAR(p[2], w[3] / sum, 1e-12);
  EXPECT_NEAR(step(1), 2.8, 1e-12);
  EXPECT_NEAR(sigma(1), 1.0, 1e-12);
  EXPECT_EQ(StepAlternatives(N, b, {}, 0.95, 3), (std::vector<int>{0, 1}));  // 0.981 ≥ 0.95
  EXPECT_EQ(StepAlternatives(N, b, {}, 0.99, 2), (std::vector<int>{0, 1}));  // at most 2
  EXPECT_EQ(StepAlternatives(N, b, {}, 0.5, 3), (std::vector<int>{0}));
  // Scaled columns: g_j = b_j² / N_jj, the step b_j / N_jj, its σ 1/√N_jj.
  N(1, 1) = 4;
  EXPECT_EQ(StepAlternatives(N, 2 * b, {}, 0.5, 3, &p, &step, &sigma), (std::vector<int>{0}));
  EXPECT_NEAR(p[0], std::exp(18) / (std::exp(18) + std::exp(3.92) + 1 + std::exp(2)), 1e-12);
  EXPECT_THROW(StepAlternatives(N, b.head(3), {}, 0.9, 3), std::invalid_argument);
  EXPECT_THROW(StepAlternatives(N, b, {0, 1}, 0.9, 3), std::invalid_argument);
  // One change under two names (labelled alike): columns 0 and 1 count once; 0 and 4, exactly
  // parallel only in N above, are two here (equal g, p 0.493 each).
  EXPECT_EQ(StepAlternatives(Eigen::MatrixXd::Identity(5, 5), b, {7, 7, -1, -1, -1}, 0.95, 3),
            (std::vector<int>{0, 4}));
}

TEST(ChangeDetection, NearTwinColumnsAreAlternativesThatHoldTheStepAtTheirProbability) {
  // Columns 0 and 1 move the poses almost alike (cos 0.99 per pose); the step is along one of
  // them (every other seed). Three poses after it, the most likely column alone is the one in
  // too few seeds; the alternatives hold it in about `naming_probability` of them.
  StepTestSettings set;
  set.naming_probability = 0.95;
  int detected = 0, top_right = 0, held = 0, alternatives = 0;
  for (unsigned seed = 0; seed < 400; ++seed) {
    const int column = static_cast<int>(seed % 2);
    Synthetic s = Make(8, 6, 12, 7000 + seed, 5, column, 0.0);
    std::mt19937_64 rng(9000 + seed);
    std::normal_distribution<double> g(0, 1);
    for (size_t k = 0; k < s.A.size(); ++k) {
      for (int i = 0; i < s.A[k].rows(); ++i)
        s.A[k](i, 1) = 0.99 * s.A[k](i, 0) + std::sqrt(1 - 0.99 * 0.99) * g(rng);
      if (k >= 5) s.e[k] += s.A[k].col(column) * 3.5;
    }
    const StepTestResult r = TestForStep(s.e, s.A, set);
    if (!r.detected || r.columns.size() != 1) continue;
    // Labelled one change under two names, the twins are never alternatives of each other.
    StepTestSettings labelled = set;
    labelled.same_change.assign(12, -1);
    labelled.same_change[0] = labelled.same_change[1] = 3;
    const StepTestResult l = TestForStep(s.e, s.A, labelled);
    EXPECT_FALSE(std::count(l.alternatives.begin(), l.alternatives.end(), 0) &&
                 std::count(l.alternatives.begin(), l.alternatives.end(), 1))
        << seed;
    ++detected;
    top_right += r.columns[0] == column;
    if (r.alternatives.empty()) {
      held += r.columns[0] == column;
      continue;
    }
    ++alternatives;
    EXPECT_EQ(r.alternatives[0], r.columns[0]);
    double mass = 0;
    for (double p : r.alternative_probability) mass += p;
    EXPECT_GE(mass, 0.95 - 1e-12);
    EXPECT_LT(mass - r.alternative_probability.back(), 0.95);  // the fewest
    held += std::find(r.alternatives.begin(), r.alternatives.end(), column) != r.alternatives.end();
  }
  std::printf("detected %d; the likeliest column right %d; alternatives %d; the step held %d\n",
              detected, top_right, alternatives, held);
  ASSERT_GE(detected, 300);
  EXPECT_LT(top_right, 0.9 * detected);
  EXPECT_GE(held, 0.93 * detected);
  EXPECT_GT(alternatives, detected / 10);
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
