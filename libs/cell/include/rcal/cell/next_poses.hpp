// The next stops a running identification should measure (issue 16, NEXT_POSES): candidates
// inside the joint limits and the cell's constraints (drawn once, seeded), scored under the
// filter's current covariance by identification::NextBestPoses — the decrease of the predicted
// position error over the cell's task region (over the whole workspace when it has none) per
// joint-space distance from where the arm stands.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/identification/pose_planning.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/kinematics/measurement.hpp"

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

  /// A pose the cell measured: the noise a suggested stop's measurement is expected to carry
  /// becomes the RMS per-axis σ of the covariances of the poses so far (position; orientation
  /// when they carry it), instead of the cell file's sensor σ. A still window averages hundreds
  /// of samples: its pose is far less noisy than one sample (the demo cell: 0.5 mm per sample,
  /// about 0.05 mm per window), and the gain of a stop depends on the ratio of position to
  /// orientation noise. Poses with a non-finite or non-positive covariance are ignored.
  void Measured(const kinematics::PoseMeasurement& z);

  /// The k best next stops under `ekf`'s estimate and covariance, from joints q_now;
  /// `settle_distance` [rad]: the cost of a stop (identification::NextBestPoses).
  NextPoseAdvice Suggest(const identification::EkfIdentifier& ekf, const Eigen::VectorXd& q_now,
                         int k, double settle_distance = identification::kDefaultStopCost) const;

  const std::vector<Eigen::VectorXd>& candidates() const { return candidates_; }
  const std::vector<Eigen::VectorXd>& task() const { return task_; }

 private:
  kinematics::KinematicModel model_;
  identification::PlanningSettings settings_;
  std::vector<Eigen::VectorXd> candidates_, task_;
  // Σ of the per-axis variances of the poses measured, and their counts (Measured).
  double position_var_sum_ = 0, orientation_var_sum_ = 0;
  int positions_ = 0, orientations_ = 0;
};

/// The stop a cell that follows NEXT_POSES goes to next (sensor_acquisition --follow-next-poses;
/// a real cell's program would do the same): the first suggestion, best first, farther than
/// `min_move` [rad | m, Euclidean] from every configuration in `measured_since` — the stops the arm
/// stood at after the pose the suggestions were computed for, which they cannot know (a still
/// window's pose is published when the arm leaves the stop, so a cell that does not wait for the
/// advice follows it one stop behind). nullopt when none qualifies.
std::optional<Eigen::VectorXd> NextStopToFollow(const std::vector<Eigen::VectorXd>& suggested,
                                                const std::vector<Eigen::VectorXd>& measured_since,
                                                double min_move = 0.05);

}  // namespace rcal::cell
