#include "rcal/identification/chi_square.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace rcal::identification {
namespace {

TEST(ChiSquare, QuantilesMatchPublishedTables) {
  // NIST/SEMATECH e-Handbook, table of the chi-square upper critical values.
  EXPECT_NEAR(ChiSquareQuantile(0.95, 3), 7.815, 1e-3);
  EXPECT_NEAR(ChiSquareQuantile(0.99, 6), 16.812, 1e-3);
  EXPECT_NEAR(ChiSquareQuantile(0.999, 1), 10.828, 1e-3);
  EXPECT_NEAR(ChiSquareQuantile(0.05, 10), 3.940, 1e-3);
  EXPECT_NEAR(ChiSquareQuantile(0.99, 100), 135.807, 1e-2);
}

TEST(ChiSquare, CdfHasClosedFormForTwoDof) {
  for (double x : {0.1, 1.0, 3.0, 10.0, 40.0})
    EXPECT_NEAR(ChiSquareCdf(x, 2), 1.0 - std::exp(-x / 2), 1e-13);
}

// The upper tail in log form, where 1 − ChiSquareCdf is 0 (below 1e-16) or the tail underflows
// (below 1e-308): rcal analyze's χ² of the residuals against a stated noise too small gave p = 0.
TEST(ChiSquare, LogUpperTailHoldsWhatADoubleCannot) {
  // Two dof: P(X > x) = exp(−x/2) exactly, so ln p = −x/2 (p = 1e-434 at x = 2000).
  for (double x : {0.5, 10.0, 100.0, 2000.0, 1e5})
    EXPECT_NEAR(ChiSquareLogUpper(x, 2), -x / 2, 1e-12 * x) << x;
  // Other dof against mpmath 1.3.0 (gammainc regularised, 40 digits): the χ² of
  // Discrepancy.NoiseTests' kind (22681 on 303 dof, p ≈ 1e-4579), a moderate tail on the series
  // branch's side (400 on 303) and the continued fraction's (600 on 303, 50 on 3).
  EXPECT_NEAR(ChiSquareLogUpper(22681, 303), -10542.92614125268, 1e-8);
  EXPECT_NEAR(ChiSquareLogUpper(600, 303), -48.41870995492499, 1e-10);
  EXPECT_NEAR(ChiSquareLogUpper(400, 303), -8.787271904444107, 1e-10);
  EXPECT_NEAR(ChiSquareLogUpper(50, 3), -23.25034799121721, 1e-10);
  EXPECT_EQ(ChiSquareLogUpper(0, 3), 0.0);
  // Agrees with the CDF where both are representable.
  for (double x : {1.0, 5.0, 20.0})
    EXPECT_NEAR(std::exp(ChiSquareLogUpper(x, 6)), 1.0 - ChiSquareCdf(x, 6), 1e-13);
}

TEST(ChiSquare, RejectsBadArguments) {
  EXPECT_THROW(ChiSquareQuantile(1.0, 3), std::invalid_argument);
  EXPECT_THROW(ChiSquareQuantile(0.5, 0), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::identification
