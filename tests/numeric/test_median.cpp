// numeric/median.hpp against the definition: the sorted samples' middle element(s).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "rcal/numeric/median.hpp"

namespace {

using rcal::numeric::Median;
using rcal::numeric::UpperMedian;

TEST(Median, ClosedFormCases) {
  EXPECT_EQ(UpperMedian({3.0}), 3.0);
  EXPECT_EQ(Median({3.0}), 3.0);
  EXPECT_EQ(UpperMedian({5.0, 1.0, 3.0}), 3.0);
  EXPECT_EQ(Median({5.0, 1.0, 3.0}), 3.0);
  EXPECT_EQ(UpperMedian({4.0, 1.0, 2.0, 8.0}), 4.0);  // rank 2 of 1 2 4 8
  EXPECT_EQ(Median({4.0, 1.0, 2.0, 8.0}), 3.0);       // (2 + 4) / 2
  EXPECT_EQ(Median({2.0, 2.0, 2.0, 7.0}), 2.0);       // ties
  EXPECT_EQ(Median({-1.0, 1.0}), 0.0);
}

TEST(Median, IntegersTakeTheUpperMiddle) {
  EXPECT_EQ(UpperMedian(std::vector<long long>{40, 10, 30, 20}), 30);
  EXPECT_EQ(UpperMedian(std::vector<int>{-5}), -5);
}

TEST(Median, EmptyIsNaN) {
  EXPECT_TRUE(std::isnan(UpperMedian({})));
  EXPECT_TRUE(std::isnan(Median({})));
}

// Seeded random samples of every size 1..60, with ties, against sorting.
TEST(Median, AgreesWithSortingOnRandomSamples) {
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<int> value(-20, 20);
  for (int n = 1; n <= 60; ++n) {
    for (int rep = 0; rep < 20; ++rep) {
      std::vector<double> v(n);
      for (double& x : v) x = 0.5 * value(rng);
      std::vector<double> s = v;
      std::sort(s.begin(), s.end());
      const double upper = s[n / 2];
      const double median = n % 2 ? s[n / 2] : 0.5 * (s[n / 2 - 1] + s[n / 2]);
      ASSERT_EQ(UpperMedian(v), upper) << n;
      ASSERT_EQ(Median(v), median) << n;
    }
  }
}

}  // namespace
