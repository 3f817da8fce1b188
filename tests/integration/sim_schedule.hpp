// Shared by the integration tests that check a live run against the simulator's own schedule:
// which stop a pose was measured at, and where a grasp at the stop made a window see two payloads.
#pragma once

#include <set>

#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/sim/trajectory.hpp"

namespace rcal::integration {

/// The stop a pose stamped at `t_sim` [s of sim time] was measured at: the last waypoint whose
/// still interval began before it (a window's pose is stamped as the arm leaves; the next move
/// takes seconds). −1 when none, or when t_sim is 3 s or more past that stop's still interval.
inline int StopAt(const sim::JointTrajectory& trajectory, double t_sim) {
  int stop = -1;
  for (int k = 0; k < trajectory.num_waypoints(); ++k)
    if (trajectory.StillInterval(k).first < t_sim) stop = k;
  if (stop < 0 || t_sim - trajectory.StillInterval(stop).second >= 3.0) return -1;
  return stop;
}

/// The stops 1..`stops` whose payload changed while the arm stood there (`conditions` set with
/// SimArmConditions::PayloadChangeAt::kAtStop): the windows measured under two loads.
inline std::set<int> GraspedStops(const cell::SimArmConditions& conditions, int stops) {
  std::set<int> grasped;
  for (int k = 1; k <= stops; ++k)
    if (conditions.PayloadAt(k) != conditions.PayloadAt(k - 1)) grasped.insert(k);
  return grasped;
}

}  // namespace rcal::integration
