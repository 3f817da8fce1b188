#include "rcal/identification/tracking.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "identification_fixture.hpp"

namespace rcal::identification {
namespace {

using kinematics::testing::Grb3016;

// 400 poses of a GRB3016 whose joint 3 reads 1 mrad off from pose 302 on, every fifth pose a test
// pose: the test poses are never fitted, their prediction error is the truth's (small before the
// step, large right after it, small again after re-convergence), and the row that detects the
// change names joint 3's offset.
TEST(Tracking, TestRowsAreNeverFittedAndShowTheStepAndTheRecovery) {
  const auto model = Grb3016();
  sim::Rng rng(71);
  const testing::BaseSetTruth truth =
      testing::MakeBaseSetTruth(model, rng, kinematics::MeasurementKind::kFullPose);
  const Eigen::VectorXd& x_true = truth.x_true;
  std::vector<kinematics::PoseMeasurement> poses;
  std::vector<bool> is_test;
  for (int k = 0; k < 400; ++k) {
    const Eigen::VectorXd q = sim::SampleJoints(model, 1, rng)[0];
    Eigen::VectorXd q_arm = q;
    if (k >= 302) q_arm(2) += 1e-3;
    kinematics::PoseMeasurement m = sim::MeasurePose(model, x_true, q_arm, sim::PoseNoise{}, rng);
    m.q = q;
    poses.push_back(m);
    is_test.push_back(k % 5 == 4);
  }
  EkfIdentifier ekf(model, truth.identified);
  const std::vector<TrackRow> rows = Track(ekf, poses, is_test);
  ASSERT_EQ(rows.size(), poses.size());
  EXPECT_EQ(ekf.accepted() + ekf.rejected(), 320);  // the 80 test rows never reached the filter
  const auto median_error = [&](int from, int to) {
    std::vector<double> e;
    for (int k = from; k < to; ++k)
      if (rows[k].test) e.push_back(rows[k].prediction_error_m);
    std::sort(e.begin(), e.end());
    return e[e.size() / 2];
  };
  // Test rows: the measured noise (0.05 mm per axis, |·| ≈ 0.08 mm) before the step; the step
  // (~1 mm at the tool) until detected; back to the noise after re-convergence.
  EXPECT_LT(median_error(200, 300), 1.2e-4);
  EXPECT_GT(rows[304].prediction_error_m, 3e-4);
  EXPECT_LT(median_error(342, 400), 1.2 * median_error(200, 300));
  int detections = 0;
  for (size_t k = 0; k < rows.size(); ++k) {
    if (rows[k].test) {
      EXPECT_TRUE(std::isnan(rows[k].nis));
      EXPECT_TRUE(rows[k].changed.empty());
    } else {
      EXPECT_TRUE(std::isnan(rows[k].prediction_error_m));
    }
    if (!rows[k].changed.empty()) {
      ++detections;
      EXPECT_GE(k, 302u);
      EXPECT_LE(k, 308u);  // within 5 fitted poses (a test row every fifth)
      // θ3 is joint 3's offset: named as the parameter or as the joint.
      EXPECT_TRUE(rows[k].changed[0] == "theta3" || rows[k].changed[0] == "offset of joint j3")
          << rows[k].changed[0];
      EXPECT_NEAR(rows[k].steps[0], 1e-3, 2e-4);
      EXPECT_EQ(rows[k].status, TrackingStatus::kChangeDetected);
    }
  }
  EXPECT_EQ(detections, 1);
  EXPECT_THROW(Track(ekf, poses, std::vector<bool>(3)), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::identification
