#include "rcal/sim/trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace rcal::sim {

JointTrajectory::JointTrajectory(std::vector<Eigen::VectorXd> waypoints,
                                 TrajectorySettings settings)
    : waypoints_(std::move(waypoints)), settings_(settings) {
  if (waypoints_.empty()) throw std::invalid_argument("waypoints: empty");
  for (const auto& w : waypoints_)
    if (w.size() != waypoints_[0].size() || !w.allFinite())
      throw std::invalid_argument("waypoints: sizes differ or values not finite");
  TimeFrom(0, 0.0);
}

void JointTrajectory::TimeFrom(int from, double t) {
  // Segment 2k is the still at waypoint k, 2k + 1 the move from k to k + 1.
  segments_.resize(2 * static_cast<size_t>(from));
  for (size_t k = from; k < waypoints_.size(); ++k) {
    segments_.push_back({t, t + settings_.still_time, static_cast<int>(k), static_cast<int>(k)});
    t += settings_.still_time;
    if (k + 1 == waypoints_.size()) break;
    const double dq = (waypoints_[k + 1] - waypoints_[k]).cwiseAbs().maxCoeff();
    const double T = std::max({settings_.min_move_time, 1.875 * dq / settings_.max_joint_speed,
                               std::sqrt(5.7735 * dq / settings_.max_joint_accel)});
    segments_.push_back({t, t + T, static_cast<int>(k), static_cast<int>(k + 1)});
    t += T;
  }
}

void JointTrajectory::Retarget(int k, const Eigen::VectorXd& q) {
  if (k < 1 || k >= num_waypoints())
    throw std::invalid_argument("Retarget: waypoint " + std::to_string(k) + " is not in 1.." +
                                std::to_string(num_waypoints() - 1));
  if (q.size() != waypoints_[0].size() || !q.allFinite())
    throw std::invalid_argument("Retarget: q has the wrong size or is not finite");
  waypoints_[k] = q;
  // From the still at k − 1 on: its start is unchanged, the move out of it is re-timed.
  TimeFrom(k - 1, segments_[2 * static_cast<size_t>(k - 1)].t_start);
}

void JointTrajectory::Sample(double t, Eigen::VectorXd& q, Eigen::VectorXd* qd,
                             Eigen::VectorXd* qdd) const {
  t = std::clamp(t, 0.0, duration());
  auto it = std::lower_bound(segments_.begin(), segments_.end(), t,
                             [](const Segment& s, double v) { return s.t_end < v; });
  if (it == segments_.end()) it = std::prev(segments_.end());
  const Segment& s = *it;
  const Eigen::VectorXd& a = waypoints_[s.from];
  if (s.from == s.to) {
    q = a;
    if (qd) qd->setZero(a.size());
    if (qdd) qdd->setZero(a.size());
    return;
  }
  const Eigen::VectorXd d = waypoints_[s.to] - a;
  const double T = s.t_end - s.t_start;
  const double tau = (t - s.t_start) / T;
  const double t2 = tau * tau, t3 = t2 * tau;
  q = a + d * (10 * t3 - 15 * t3 * tau + 6 * t3 * t2);
  if (qd) *qd = d * ((30 * t2 - 60 * t3 + 30 * t3 * tau) / T);
  if (qdd) *qdd = d * ((60 * tau - 180 * t2 + 120 * t3) / (T * T));
}

std::pair<double, double> JointTrajectory::StillInterval(int k) const {
  const Segment& s = segments_.at(2 * k);
  return {s.t_start, s.t_end};
}

int JointTrajectory::StillAt(double t) const {
  for (size_t i = 0; i < segments_.size(); i += 2)
    if (t >= segments_[i].t_start && t <= segments_[i].t_end) return segments_[i].from;
  return -1;
}

}  // namespace rcal::sim
