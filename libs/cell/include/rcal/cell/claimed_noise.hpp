// The noise a pose measurement claims: the mean per-axis variance of its covariance's position
// block [m²] and orientation block [rad²]. What NextPoseAdvisor learns the cell's noise from and
// what the discrepancy watch tests the geometric fit's residuals against.
#pragma once

#include <cmath>
#include <limits>

#include "rcal/kinematics/measurement.hpp"

namespace rcal::cell {

struct ClaimedVariance {
  double position = std::numeric_limits<double>::quiet_NaN();     ///< [m²] per axis
  double orientation = std::numeric_limits<double>::quiet_NaN();  ///< [rad²]; NaN: not measured
};

/// trace/3 of each block; NaN where the covariance is unusable (not square, smaller than 3 × 3,
/// not finite) or the block is not measured.
inline ClaimedVariance PerAxisVariance(const kinematics::PoseMeasurement& z) {
  ClaimedVariance v;
  const Eigen::MatrixXd& C = z.covariance;
  if (C.rows() < 3 || C.rows() != C.cols() || !C.allFinite()) return v;
  v.position = C.topLeftCorner(3, 3).trace() / 3;
  if (z.has_orientation && C.rows() == 6) v.orientation = C.bottomRightCorner(3, 3).trace() / 3;
  return v;
}

}  // namespace rcal::cell
