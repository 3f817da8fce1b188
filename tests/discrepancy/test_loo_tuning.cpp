#include "rcal/discrepancy/loo_tuning.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

namespace rcal::discrepancy {
namespace {

TEST(LooTuning, EachFoldChoosesWithoutItsTrial) {
  // Candidate 0 is best on average only because of trial 2; without trial 2 candidate 1 wins.
  // Means by hand: all (0: 1.0, 1: 1.333, 2: 2.0); without t0 (0: 1.0, 1: 1.5, 2: 2.0);
  // without t1 (0: 1.0, 1: 1.5, 2: 2.0); without t2 (0: 1.5, 1: 1.0, 2: 2.0).
  Eigen::MatrixXd cost(3, 3);
  cost << 1.5, 1.5, 0.0,  //
      1.0, 1.0, 2.0,      //
      2.0, 2.0, 2.0;
  const LeaveOneOutChoice r = LeaveOneOutSelect(cost);
  EXPECT_EQ(r.in_sample, 0);
  ASSERT_EQ(r.held_out.size(), 3u);
  EXPECT_EQ(r.held_out[0], 0);
  EXPECT_EQ(r.held_out[1], 0);
  EXPECT_EQ(r.held_out[2], 1);
  EXPECT_DOUBLE_EQ(r.in_sample_mean, 1.0);
  // Held out: trial 0 with candidate 0 (1.5), trial 1 with 0 (1.5), trial 2 with 1 (2.0).
  EXPECT_DOUBLE_EQ(r.held_out_mean, 5.0 / 3.0);
  EXPECT_GE(r.held_out_mean, r.in_sample_mean);
}

TEST(LooTuning, FailedCandidateIsNeverChosenOnAFoldWithItsTrial) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Eigen::MatrixXd cost(2, 3);
  cost << 0.1, 0.1, nan,  //
      1.0, 1.0, 1.0;
  const LeaveOneOutChoice r = LeaveOneOutSelect(cost);
  EXPECT_EQ(r.in_sample, 1);
  EXPECT_EQ(r.held_out[0], 1);
  EXPECT_EQ(r.held_out[1], 1);
  EXPECT_EQ(r.held_out[2], 0);               // the fold without the failed trial
  EXPECT_TRUE(std::isnan(r.held_out_mean));  // and trial 2 is then scored with its NaN
}

TEST(LooTuning, TiesGoToTheLowerIndex) {
  Eigen::MatrixXd cost = Eigen::MatrixXd::Constant(3, 4, 0.5);
  const LeaveOneOutChoice r = LeaveOneOutSelect(cost);
  EXPECT_EQ(r.in_sample, 0);
  for (int c : r.held_out) EXPECT_EQ(c, 0);
}

TEST(LooTuning, RefusesWhatCannotBeCrossValidated) {
  EXPECT_THROW(LeaveOneOutSelect(Eigen::MatrixXd(0, 3)), std::invalid_argument);
  EXPECT_THROW(LeaveOneOutSelect(Eigen::MatrixXd::Ones(2, 1)), std::invalid_argument);
  Eigen::MatrixXd neg = Eigen::MatrixXd::Ones(2, 3);
  neg(1, 2) = -1.0;
  EXPECT_THROW(LeaveOneOutSelect(neg), std::invalid_argument);
  Eigen::MatrixXd all_failed = Eigen::MatrixXd::Ones(2, 3);
  all_failed(0, 0) = all_failed(1, 1) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(LeaveOneOutSelect(all_failed), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::discrepancy
