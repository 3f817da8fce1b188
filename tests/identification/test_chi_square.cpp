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

TEST(ChiSquare, RejectsBadArguments) {
  EXPECT_THROW(ChiSquareQuantile(1.0, 3), std::invalid_argument);
  EXPECT_THROW(ChiSquareQuantile(0.5, 0), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::identification
