// NEXT_POSES' advisor (libs/cell next_poses): inside the cell's constraints, ranked as
// identification::NextBestPoses ranks them, and an EKF that follows the advice predicts — and
// reaches, against a simulated truth — a smaller task-region error than one fed random stops.
#include "rcal/cell/next_poses.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "rcal/cell/online_identification.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::cell {
namespace {

io::BuiltCell Ur10CellWithConstraints() {
  std::string text = io::ReadFile(RCAL_SOURCE_DIR "/config/cells/ur10.yaml");
  text += R"(constraints:
  min_base_distance: 0.5
  home: {joints: [0, -1.57, 1.57, -1.57, -1.57, 0], tolerance: 2.5}
  task_region: {min: [0.3, -0.6, -0.2], max: [1.0, 0.6, 0.5]}
)";
  io::CellSpec spec = io::ParseCellYaml(text, "ur10.yaml");
  spec.robot.file = RCAL_SOURCE_DIR "/config/robots/ur10.urdf";
  return io::BuildCell(spec);
}

// Following the advice: each stop lowers the predicted task-region error; ranked by gain per
// distance the path is much shorter than random stops'; ranked by gain alone (a stop costing far
// more than any move) the EKF is more accurate than with random stops, predicted and against a
// simulated truth.
TEST(NextPoses, FollowingTheAdviceShrinksTheTaskErrorAndShortensThePath) {
  const io::BuiltCell cell = Ur10CellWithConstraints();
  const NextPoseAdvisor advisor(cell, 1500, 4);
  const auto& c = cell.spec.constraints;
  for (const auto& q : advisor.candidates())
    EXPECT_TRUE(identification::SatisfiesConstraints(cell.model, cell.model.Nominal(), q, c));
  for (const auto& q : advisor.task())
    EXPECT_TRUE(
        c.task_region->Contains(identification::MarkerInBase(cell.model, cell.model.Nominal(), q)));
  ASSERT_GE(advisor.task().size(), 20u);

  const std::vector<int> base = CellBaseSet(cell);
  sim::Rng rng(9);
  // The truth: 0.5 mm / 1 mrad on every parameter (set-up frames near the start, as after the
  // set-up guess).
  const Eigen::VectorXd x_true = sim::RandomErrors(cell.model, rng, 5e-4, 1e-3);
  sim::PoseNoise noise;
  noise.orientation = false;
  noise.position_sigma = 1e-4;
  const int stops = 15;
  const auto random_q =
      identification::SampleCandidates(cell.model, cell.model.Nominal(), c, stops, rng);
  const auto follow = [&](double settle_distance, double* path) {
    identification::EkfIdentifier ekf(cell.model, base, cell.ekf);
    Eigen::VectorXd q_now = c.home;
    double before = advisor.Suggest(ekf, q_now, 1).predicted_rms_m;
    *path = 0;
    for (int k = 0; k < stops; ++k) {
      const NextPoseAdvice a = advisor.Suggest(ekf, q_now, 4, settle_distance);
      EXPECT_LT(a.predicted_rms_m, before + 1e-15);
      before = a.predicted_rms_m;
      EXPECT_EQ(a.poses.size(), 4u);
      for (size_t i = 1; i < a.poses.size(); ++i) EXPECT_GE(a.poses[i - 1].score, a.poses[i].score);
      EXPECT_NEAR(a.poses[0].distance, (a.q[0] - q_now).norm(), 1e-12);
      *path += a.poses[0].distance;
      q_now = a.q[0];
      ekf.Update(sim::MeasurePose(cell.model, x_true, q_now, noise, rng));
    }
    return ekf;
  };
  double path_near = 0, path_greedy = 0, path_random = 0;
  follow(2.0, &path_near);
  const identification::EkfIdentifier greedy = follow(1e6, &path_greedy);
  identification::EkfIdentifier random(cell.model, base, cell.ekf);
  Eigen::VectorXd at = c.home;
  for (const auto& q : random_q) {
    path_random += (q - at).norm();
    at = q;
    random.Update(sim::MeasurePose(cell.model, x_true, q, noise, rng));
  }
  EXPECT_LT(path_near, 0.5 * path_random);
  EXPECT_LT(advisor.Suggest(greedy, at, 1).predicted_rms_m,
            0.8 * advisor.Suggest(random, at, 1).predicted_rms_m);
  const auto task_error = [&](const identification::EkfIdentifier& ekf) {
    return identification::ErrorsAgainstTruth(cell.model, ekf.x(), x_true, advisor.task())
        .mean_position_m;
  };
  EXPECT_LT(task_error(greedy), task_error(random));
}

// A cell one stop behind the advice skips the suggestions it has already measured (within
// min_move) and takes the best of the rest; with nothing left it has no advice to follow.
TEST(NextPoses, AFollowerSkipsWhatItMeasuredSinceTheAdvice) {
  const Eigen::VectorXd a = Eigen::VectorXd::Constant(6, 0.1),
                        b = Eigen::VectorXd::Constant(6, -0.4),
                        c = Eigen::VectorXd::Constant(6, 1.0);
  EXPECT_EQ(NextStopToFollow({a, b, c}, {}), a);
  Eigen::VectorXd near_a = a;
  near_a(3) += 0.04;  // within 0.05 of a: measured already
  EXPECT_EQ(NextStopToFollow({a, b, c}, {near_a}), b);
  EXPECT_EQ(NextStopToFollow({a, b, c}, {near_a, b}), c);
  near_a(3) += 0.02;  // 0.06 away: a different stop
  EXPECT_EQ(NextStopToFollow({a, b, c}, {near_a}), a);
  EXPECT_EQ(NextStopToFollow({a, b}, {a, b}), std::nullopt);
  EXPECT_EQ(NextStopToFollow({}, {}), std::nullopt);
  EXPECT_EQ(NextStopToFollow({a, b}, {a}, 0.0), b);  // exactly there is measured
}

// The advice weighs a stop by the noise the cell's poses actually carry (Measured), not the cell
// file's per-sample σ: an advisor of a 0.2 mm-per-axis cell told of poses with 0.03 mm suggests
// exactly what an advisor of a 0.03 mm cell suggests (the RMS σ of the poses it was told of), and
// its predicted error differs from the untold one's.
TEST(NextPoses, TheAdviceUsesTheNoiseOfThePosesMeasured) {
  const io::BuiltCell coarse_cell = Ur10CellWithConstraints();
  io::BuiltCell fine_cell = coarse_cell;
  fine_cell.spec.position.sigma = Eigen::Vector3d::Constant(3e-5);
  NextPoseAdvisor told(coarse_cell, 800, 4), untold(coarse_cell, 800, 4);
  const NextPoseAdvisor fine(fine_cell, 800, 4);
  const std::vector<int> base = CellBaseSet(coarse_cell);
  identification::EkfIdentifier ekf(coarse_cell.model, base, coarse_cell.ekf);
  sim::Rng rng(3);
  const Eigen::VectorXd x_true = sim::RandomErrors(coarse_cell.model, rng, 5e-4, 1e-3);
  sim::PoseNoise noise;
  noise.orientation = false;
  noise.position_sigma = 3e-5;
  const auto qs = identification::SampleCandidates(coarse_cell.model, coarse_cell.model.Nominal(),
                                                   coarse_cell.spec.constraints, 12, rng);
  for (size_t k = 0; k < qs.size(); ++k) {
    auto z = sim::MeasurePose(coarse_cell.model, x_true, qs[k], noise, rng);
    // Window covariances vary about their RMS: (2.5e-5)² and (3.4e-5)² average to (3e-5)².
    const double s = k % 2 == 0 ? 2.5e-5 : std::sqrt(2 * 9e-10 - 6.25e-10);
    z.covariance = s * s * Eigen::Matrix3d::Identity();
    told.Measured(z);
    ekf.Update(z);
  }
  kinematics::PoseMeasurement bad;
  bad.covariance = Eigen::Matrix3d::Constant(std::nan(""));
  told.Measured(bad);  // ignored
  const Eigen::VectorXd q_now = qs.back();
  const NextPoseAdvice a = told.Suggest(ekf, q_now, 5), b = fine.Suggest(ekf, q_now, 5),
                       c = untold.Suggest(ekf, q_now, 5);
  ASSERT_EQ(a.poses.size(), 5u);
  for (size_t i = 0; i < a.poses.size(); ++i) {
    EXPECT_EQ(a.poses[i].candidate, b.poses[i].candidate);
    EXPECT_NEAR(a.poses[i].gain_m2, b.poses[i].gain_m2, 1e-9 * b.poses[i].gain_m2);
  }
  // A less noisy measurement removes more: the untold advisor under-rates every stop.
  EXPECT_GT(a.poses[0].gain_m2, 1.5 * c.poses[0].gain_m2);
}

}  // namespace
}  // namespace rcal::cell
