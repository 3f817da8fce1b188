// Random serial arms for figures that must hold beyond the arms a method was tuned on: revolute
// standard D–H arms drawn from a seed, with a world ← base frame and a flange → marker offset to
// identify, as a cell measures them.
#pragma once

#include <cstdint>

#include "rcal/kinematics/model.hpp"

namespace rcal::sim {

struct RandomArmSettings {
  int joints = 6;
  double max_a = 0.5;      ///< link length a ~ U(0.05, max_a) [m], or 0 (30 %)
  double max_d = 0.4;      ///< offset d ~ U(0.05, max_d) [m], or 0 (40 %)
  double min_range = 2.0;  ///< joint limits ±U(min_range, max_range) [rad]
  double max_range = 3.0;
  double parallel_share = 0.25;  ///< chance that a twist α is 0 (axes i, i+1 parallel)
  /// A flange → IMU rotation to identify (zero nominal), for full-pose measurements. Drawing
  /// the arm does not depend on it: the same seed gives the same geometry either way.
  bool imu_frame = false;
};

/// A revolute D–H arm "random_dh_SEED": twists α ∈ {−π/2, π/2} (or 0 with parallel_share; never
/// for link 1, so the arm is not planar at the shoulder), lengths as the settings say, θ nominal 0,
/// a link whose next axis is parallel in Hayati form (β replaces d, d = 0); a world ← base frame at
/// the origin and marker 0 at p_FM = (0.05, 0, 0.1) m, both identified. Joints j1 … jN. The same
/// seed gives the same arm.
kinematics::KinematicModel RandomDhArm(std::uint64_t seed, const RandomArmSettings& settings = {});

}  // namespace rcal::sim
