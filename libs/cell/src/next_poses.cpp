#include "rcal/cell/next_poses.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "rcal/cell/claimed_noise.hpp"

namespace rcal::cell {

NextPoseAdvisor::NextPoseAdvisor(const io::BuiltCell& cell, int candidates, unsigned seed)
    : model_(cell.model) {
  const auto& c = cell.spec.constraints;
  std::mt19937_64 rng(seed);
  candidates_ = identification::SampleCandidates(model_, model_.Nominal(), c, candidates, rng);
  task_ = identification::InTaskRegion(model_, model_.Nominal(), candidates_, c);
  if (c.task_region && task_.empty())
    throw std::runtime_error(cell.spec.source +
                             ": constraints.task_region: no candidate configuration puts the "
                             "marker inside");
  if (!c.task_region) {
    const size_t step = std::max<size_t>(1, candidates_.size() / 300);
    for (size_t i = 0; i < candidates_.size(); i += step) task_.push_back(candidates_[i]);
  }
  settings_.kind = cell.spec.measures_orientation() ? kinematics::MeasurementKind::kFullPose
                                                    : kinematics::MeasurementKind::kPositionOnly;
  settings_.position_sigma_m = cell.spec.position.sigma.maxCoeff();
  if (cell.spec.position.orientation)
    settings_.orientation_sigma_rad = cell.spec.position.orientation_sigma;
}

void NextPoseAdvisor::Measured(const kinematics::PoseMeasurement& z) {
  const ClaimedVariance v = PerAxisVariance(z);
  if (!(v.position > 0)) return;
  position_var_sum_ += v.position;
  settings_.position_sigma_m = std::sqrt(position_var_sum_ / ++positions_);
  if (!(v.orientation > 0)) return;
  orientation_var_sum_ += v.orientation;
  settings_.orientation_sigma_rad = std::sqrt(orientation_var_sum_ / ++orientations_);
}

NextPoseAdvice NextPoseAdvisor::Suggest(const identification::EkfIdentifier& ekf,
                                        const Eigen::VectorXd& q_now, int k,
                                        double settle_distance) const {
  NextPoseAdvice a;
  const Eigen::VectorXd& x = ekf.x();
  const std::vector<int>& id = ekf.identified();
  const Eigen::MatrixXd P = ekf.P().topLeftCorner(id.size(), id.size());
  a.poses = identification::NextBestPoses(model_, x, id, P, candidates_, task_, q_now, k, settings_,
                                          settle_distance);
  for (const auto& p : a.poses) a.q.push_back(candidates_[p.candidate]);
  a.predicted_rms_m = std::sqrt(identification::PredictedTaskMeanSquared(model_, x, id, P, task_));
  return a;
}

std::optional<Eigen::VectorXd> NextStopToFollow(const std::vector<Eigen::VectorXd>& suggested,
                                                const std::vector<Eigen::VectorXd>& measured_since,
                                                double min_move) {
  for (const Eigen::VectorXd& q : suggested) {
    bool measured = false;
    for (const Eigen::VectorXd& m : measured_since)
      measured = measured || (m.size() == q.size() && (m - q).norm() <= min_move);
    if (!measured) return q;
  }
  return std::nullopt;
}

}  // namespace rcal::cell
