// The checks the filters make on a frame they are told (R_WE and the covariance of its error),
// one definition for PositionKf and AidedIns (internal to the library's sources).
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>

namespace rcal::estimation::detail {

/// A finite proper rotation: R Rᵀ = I within 1e-6, det R > 0.
inline bool IsRotation(const Eigen::Matrix3d& R) {
  return R.allFinite() && (R * R.transpose() - Eigen::Matrix3d::Identity()).norm() <= 1e-6 &&
         R.determinant() > 0.0;
}

/// A finite covariance: symmetric within 1e-9 of its size, non-negative variances.
inline bool IsCovariance(const Eigen::Matrix3d& C) {
  return C.allFinite() && (C - C.transpose()).norm() <= 1e-9 * std::max(1.0, C.norm()) &&
         C.diagonal().minCoeff() >= 0.0;
}

}  // namespace rcal::estimation::detail
