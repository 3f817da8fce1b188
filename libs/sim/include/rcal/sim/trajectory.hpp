// A robot program for the simulator: stand still at each waypoint, then move to the next with a
// quintic (minimum-jerk) joint profile, all joints starting and stopping together:
//
//   q(t) = q_k + (q_{k+1} − q_k)·s(τ),  s(τ) = 10τ³ − 15τ⁴ + 6τ⁵,  τ = (t − t_start)/T
//
// so velocity and acceleration are zero at both ends of every move (the arm settles exactly at
// each stop; no jump in the accelerometer). The move time T is the shortest that keeps every
// joint within its speed (peak 1.875·Δq/T) and acceleration (peak 5.7735·Δq/T²) limits.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace rcal::sim {

struct TrajectorySettings {
  double still_time = 1.5;       ///< [s] standing at each waypoint
  double max_joint_speed = 1.0;  ///< [rad/s] (or m/s for prismatic joints)
  double max_joint_accel = 2.0;  ///< [rad/s²]
  double min_move_time = 0.5;    ///< [s]
};

class JointTrajectory {
 public:
  /// Starts standing at waypoints[0] at t = 0. Throws std::invalid_argument on an empty list or
  /// joint vectors of different sizes.
  JointTrajectory(std::vector<Eigen::VectorXd> waypoints, TrajectorySettings settings = {});

  double duration() const { return segments_.empty() ? 0.0 : segments_.back().t_end; }
  int num_waypoints() const { return static_cast<int>(waypoints_.size()); }
  const Eigen::VectorXd& waypoint(int k) const { return waypoints_[k]; }

  /// Joint position [rad], velocity [rad/s] and acceleration [rad/s²] at time t [s] (clamped to
  /// [0, duration]). qd, qdd may be null.
  void Sample(double t, Eigen::VectorXd& q, Eigen::VectorXd* qd = nullptr,
              Eigen::VectorXd* qdd = nullptr) const;

  /// The still interval [start, end] [s] at waypoint k.
  std::pair<double, double> StillInterval(int k) const;
  /// Index of the waypoint the arm stands at at time t, or −1 while moving.
  int StillAt(double t) const;

  /// Replaces waypoint k (1 ≤ k < num_waypoints()) by q [rad | m], as a robot program that picks
  /// its next stop while it works (issue 16: a cell following NEXT_POSES): the moves into and out
  /// of k are re-timed by the same limits, every later segment shifts by the change in duration,
  /// every earlier one is unchanged. Call it before the move into k begins (t < start of that
  /// move) for a motion without jumps. Throws std::invalid_argument naming the bad argument (k
  /// out of range, q of the wrong size or not finite).
  void Retarget(int k, const Eigen::VectorXd& q);

 private:
  struct Segment {
    double t_start, t_end;
    int from, to;  // to == from: standing still
  };
  // Segments from the still at waypoint `from` on, starting at t [s].
  void TimeFrom(int from, double t);
  std::vector<Eigen::VectorXd> waypoints_;
  std::vector<Segment> segments_;
  TrajectorySettings settings_;
};

}  // namespace rcal::sim
