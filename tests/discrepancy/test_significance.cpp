// z and p beyond what a double holds (significance.hpp), against mpmath 1.3.0 at 40 digits:
// ln P(Z > z) = ln(erfc(z/√2)/2).
#include "rcal/discrepancy/significance.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>

namespace rcal::discrepancy {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(Significance, LogNormalUpperTailBeyondDoubleRange) {
  // Within double range: the standard library's erfc is the independent truth.
  for (double z : {-7.0, -2.0, 0.0, 1.5, 5.0, 12.0, 25.0, 35.0})
    EXPECT_NEAR(LogNormalUpper(z), std::log(0.5 * std::erfc(z / std::sqrt(2.0))),
                1e-12 * std::max(1.0, 0.5 * z * z))
        << z;
  // Near p = 1 (z ≪ 0) in log1p form: ln(1 − Φ̄(8)) = −6.22e-16.
  EXPECT_NEAR(LogNormalUpper(-8.0), -6.220960574271785e-16, 1e-28);
  // Beyond it (p < 1e-308), mpmath.
  EXPECT_NEAR(LogNormalUpper(30.0), -454.3212439563432, 1e-9);
  EXPECT_NEAR(LogNormalUpper(38.5), -745.6952702904111, 1e-9);
  EXPECT_NEAR(LogNormalUpper(50.0), -1254.831361139420, 1e-9);
  EXPECT_NEAR(LogNormalUpper(100.0), -5005.524208694205, 1e-8);
  EXPECT_NEAR(LogNormalUpper(289.0), -41767.08537719400, 1e-7);
  EXPECT_EQ(LogNormalUpper(kInf), -kInf);
}

TEST(Significance, ZFromLogPIsExactWherePUnderflows) {
  // The IMU analysis used z = Φ̄⁻¹(max(p, 1e-300)) = 37.05 for every p below 1e-300.
  EXPECT_NEAR(NormalUpperQuantileLog(-1000.0), 44.61574773196940, 1e-9);
  EXPECT_NEAR(NormalUpperQuantileLog(-41750.0), 288.9408757078318, 1e-8);
  EXPECT_NEAR(NormalUpperQuantileLog(std::log(1e-300)), 37.04709629936120, 1e-9);
  for (double z : {-5.0, 0.0, 2.0, 3.3, 8.0, 37.0, 60.0})
    EXPECT_NEAR(NormalUpperQuantileLog(LogNormalUpper(z)), z, 1e-9 * std::max(1.0, z)) << z;
  EXPECT_EQ(NormalUpperQuantileLog(0.0), -kInf);   // p = 1
  EXPECT_EQ(NormalUpperQuantileLog(-kInf), kInf);  // p = 0
}

TEST(Significance, StudentTTailAgainstItsClosedForms) {
  // ν = 1 (Cauchy): P(T > t) = atan(1/t)/π for t > 0, exact far into the tail.
  for (double t : {0.3, 1.0, 12.0, 1e3, 1e8, 1e200})
    EXPECT_NEAR(LogStudentTUpper(t, 1.0), std::log(std::atan(1.0 / t) / std::numbers::pi), 1e-11)
        << t;
  // ν = 2: P(T > t) = 1 / (√(2 + t²) (√(2 + t²) + t)).
  for (double t : {0.1, 2.0, 30.0, 1e6}) {
    const double r = std::sqrt(2.0 + t * t);
    EXPECT_NEAR(LogStudentTUpper(t, 2.0), -std::log(r * (r + t)), 1e-11) << t;
  }
  // ν = 7 (eight jackknife blocks), Abramowitz & Stegun 26.7.3 for odd ν: P(|T| < t) =
  // (2/π)(θ + sin θ (cos θ + ⅔ cos³θ + 8/15 cos⁵θ)), θ = atan(t/√7); and the tables' 0.999
  // quantile 4.785 and 0.975 quantile 2.365.
  for (double t : {0.5, 2.365, 4.785, 9.0}) {
    const double th = std::atan(t / std::sqrt(7.0)), c = std::cos(th);
    const double A =
        2.0 / std::numbers::pi *
        (th + std::sin(th) * (c + 2.0 / 3.0 * std::pow(c, 3) + 8.0 / 15.0 * std::pow(c, 5)));
    EXPECT_NEAR(LogStudentTUpper(t, 7.0), std::log(0.5 * (1.0 - A)), 1e-9) << t;
  }
  EXPECT_NEAR(std::exp(LogStudentTUpper(4.785, 7.0)), 1e-3, 2e-6);
  EXPECT_NEAR(std::exp(LogStudentTUpper(2.365, 7.0)), 0.025, 5e-5);
  // Symmetry, t = 0, and the normal limit.
  EXPECT_NEAR(std::exp(LogStudentTUpper(-2.365, 7.0)), 0.975, 5e-5);
  EXPECT_DOUBLE_EQ(LogStudentTUpper(0.0, 3.0), std::log(0.5));
  EXPECT_NEAR(LogStudentTUpper(3.0, 1e7), LogNormalUpper(3.0), 1e-5);
  // The t of a jackknife is far less significant than the same ratio read as a z.
  EXPECT_GT(LogStudentTUpper(4.0, 7.0), LogNormalUpper(4.0) + 4.0);
  EXPECT_TRUE(std::isnan(LogStudentTUpper(std::nan(""), 7.0)));
  EXPECT_TRUE(std::isnan(LogStudentTUpper(1.0, 0.0)));
  EXPECT_EQ(LogStudentTUpper(kInf, 7.0), -kInf);
}

TEST(Significance, InfiniteZAndTinyPAreWrittenAsBounds) {
  // z within what a double p can express as they are; beyond, the bound (a z of 95 from a ratio
  // |τ|/σ has p = e^−4500, no double: issue 17).
  EXPECT_EQ(WriteZ(37.0).value, 37.0);
  EXPECT_EQ(WriteZ(37.0).bound, "");
  EXPECT_EQ(WriteZ(-8.0).bound, "");
  EXPECT_NEAR(WriteZ(288.9).value, 38.46740561714435, 1e-9);
  EXPECT_EQ(WriteZ(288.9).bound, ">");
  EXPECT_EQ(ZText(95.0), "> 38.47");
  EXPECT_EQ(ZText(-9.0), "< -8.21");
  EXPECT_EQ(ZText(3.67, 1), "3.7");
  // ±∞: the z of the extreme doubles p = 4.9e-324 and 1 − 2⁻⁵³ (mpmath), with the direction.
  EXPECT_NEAR(WriteZ(kInf).value, 38.46740561714435, 1e-9);
  EXPECT_EQ(WriteZ(kInf).bound, ">");
  EXPECT_NEAR(WriteZ(-kInf).value, -8.209536151601387, 1e-9);
  EXPECT_EQ(WriteZ(-kInf).bound, "<");
  EXPECT_EQ(ZText(kInf), "> 38.47");
  EXPECT_EQ(ZText(-kInf), "< -8.21");
  // p: as a number down to 1e-300, below it the bound.
  EXPECT_EQ(PText(std::log(0.0123)), "0.0123");
  EXPECT_EQ(PText(std::log(3.4e-12)), "3.4e-12");
  EXPECT_EQ(PText(std::log(2e-300)), "2e-300");
  EXPECT_EQ(PText(std::log(1e-301)), "< 1e-300");
  EXPECT_EQ(PText(-41767.0), "< 1e-300");
  EXPECT_EQ(PText(-kInf), "< 1e-300");
  EXPECT_EQ(PText(0.0), "1");
}

}  // namespace
}  // namespace rcal::discrepancy
