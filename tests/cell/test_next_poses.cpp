// NEXT_POSES' advisor (libs/cell next_poses): inside the cell's constraints, ranked as
// identification::NextBestPoses ranks them, and an EKF that follows the advice predicts — and
// reaches, against a simulated truth — a smaller task-region error than one fed random stops.
#include "rcal/cell/next_poses.hpp"

#include <gtest/gtest.h>

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

TEST(NextPoses, FollowingTheAdviceShrinksTheTaskErrorFasterThanRandomStops) {
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
  const auto random_q =
      identification::SampleCandidates(cell.model, cell.model.Nominal(), c, 15, rng);
  identification::EkfIdentifier followed(cell.model, base, cell.ekf),
      random(cell.model, base, cell.ekf);
  Eigen::VectorXd q_now = c.home;
  double last_score = 0;
  for (int k = 0; k < 15; ++k) {
    const NextPoseAdvice a = advisor.Suggest(followed, q_now, 4);
    ASSERT_EQ(a.poses.size(), 4u);
    for (size_t i = 1; i < a.poses.size(); ++i) EXPECT_GE(a.poses[i - 1].score, a.poses[i].score);
    EXPECT_NEAR(a.poses[0].distance, (a.q[0] - q_now).norm(), 1e-12);
    last_score = a.poses[0].score;
    q_now = a.q[0];
    followed.Update(sim::MeasurePose(cell.model, x_true, q_now, noise, rng));
    random.Update(sim::MeasurePose(cell.model, x_true, random_q[k], noise, rng));
  }
  EXPECT_GT(last_score, 0.0);
  const double predicted_followed = advisor.Suggest(followed, q_now, 1).predicted_rms_m;
  const double predicted_random = advisor.Suggest(random, q_now, 1).predicted_rms_m;
  EXPECT_LT(predicted_followed, 0.8 * predicted_random);
  // Against the truth, over the task region.
  const double e_followed =
      identification::ErrorsAgainstTruth(cell.model, followed.x(), x_true, advisor.task())
          .mean_position_m;
  const double e_random =
      identification::ErrorsAgainstTruth(cell.model, random.x(), x_true, advisor.task())
          .mean_position_m;
  EXPECT_LT(e_followed, e_random);
}

}  // namespace
}  // namespace rcal::cell
