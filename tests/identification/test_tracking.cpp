#include "rcal/identification/tracking.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

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

// The second look's rename is on its row (TrackRow::renamed): d5 of a GRB3016 (positions only)
// grows by 0.5 mm at pose 300; the detection names alternatives, α5 the likeliest, each with its
// probability, and the row that completes 30 poses since the onset renames the change d5 alone
// (the case of EkfIdentifier.ARestartBeforeTheSecondLookEndsAsAnUninterruptedRun).
TEST(Tracking, TheSecondLooksRenameIsOnItsRow) {
  const auto model = Grb3016();
  sim::Rng rng(65);
  testing::BaseSetTruth truth =
      testing::MakeBaseSetTruth(model, rng, kinematics::MeasurementKind::kPositionOnly);
  sim::SampleJoints(model, 50, rng);  // the test joints of that test's arm, not used here
  sim::PoseNoise noise;
  noise.orientation = false;
  std::vector<kinematics::PoseMeasurement> poses;
  for (int k = 0; k < 340; ++k) {
    if (k == 300) truth.x_true(model.FindParameter("d5")) += 5e-4;
    poses.push_back(
        sim::MeasurePose(model, truth.x_true, sim::SampleJoints(model, 1, rng)[0], noise, rng));
  }
  EkfIdentifier ekf(model, truth.identified);
  const std::vector<TrackRow> rows = Track(ekf, poses);
  int detected = -1, renamed = -1;
  for (size_t k = 0; k < rows.size(); ++k) {
    if (!rows[k].changed.empty() && detected < 0) detected = static_cast<int>(k);
    if (!rows[k].renamed.empty()) {
      EXPECT_LT(renamed, 0) << "renamed twice";
      renamed = static_cast<int>(k);
    }
  }
  ASSERT_GE(detected, 300);
  ASSERT_GE(renamed, 0);
  std::printf("detected at row %d as %s, renamed at row %d: %s\n", detected,
              rows[detected].changed[0].c_str(), renamed, rows[renamed].renamed[0].c_str());
  EXPECT_EQ(rows[detected].changed[0], "alpha5");
  ASSERT_EQ(rows[detected].probability.size(), rows[detected].changed.size());
  EXPECT_GT(rows[detected].changed.size(), 1u);
  EXPECT_NE(std::find(rows[detected].changed.begin(), rows[detected].changed.end(), "d5"),
            rows[detected].changed.end());
  ASSERT_EQ(rows[renamed].renamed, std::vector<std::string>{"d5"});
  EXPECT_TRUE(rows[renamed].renamed_probability.empty());  // one step along d5
  EXPECT_NEAR(rows[renamed].renamed_steps[0], 5e-4, 1e-4);
  EXPECT_EQ(renamed, 300 + 29);  // the onset (pose 300) and 29 poses after it
  EXPECT_EQ(ekf.changes().back().parameters[0], model.FindParameter("d5"));
}

}  // namespace
}  // namespace rcal::identification
