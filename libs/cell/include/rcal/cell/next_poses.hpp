// The next stops a running identification should measure (issue 16, NEXT_POSES): candidates
// inside the joint limits and the cell's constraints (drawn once, seeded), scored under the
// filter's current covariance by identification::NextBestPoses — the decrease of the predicted
// position error over the cell's task region (over the whole workspace when it has none) per
// joint-space distance from where the arm stands.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/identification/pose_planning.hpp"
#include "rcal/io/cell_yaml.hpp"

namespace rcal::cell {

struct NextPoseAdvice {
  std::vector<identification::NextPose> poses;  ///< best first
  std::vector<Eigen::VectorXd> q;               ///< their joints [rad | m]
  double predicted_rms_m = 0;  ///< predicted RMS task-region position error now [m]
};

class NextPoseAdvisor {
 public:
  /// Draws `candidates` configurations satisfying the cell's constraints from `seed`; the task
  /// configurations are those in constraints.task_region, else an even spread of ≤ 300
  /// candidates. Throws std::runtime_error (naming the constraint) when the constraints leave
  /// too few configurations or none in the task region.
  explicit NextPoseAdvisor(const io::BuiltCell& cell, int candidates = 2000, unsigned seed = 1);

  /// The k best next stops under `ekf`'s estimate and covariance, from joints q_now;
  /// `settle_distance` [rad]: the cost of a stop (identification::NextBestPoses).
  NextPoseAdvice Suggest(const identification::EkfIdentifier& ekf, const Eigen::VectorXd& q_now,
                         int k, double settle_distance = 2.0) const;

  const std::vector<Eigen::VectorXd>& candidates() const { return candidates_; }
  const std::vector<Eigen::VectorXd>& task() const { return task_; }

 private:
  kinematics::KinematicModel model_;
  identification::PlanningSettings settings_;
  std::vector<Eigen::VectorXd> candidates_, task_;
};

}  // namespace rcal::cell
