#include "rcal/discrepancy/imu_scoring.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "rcal/geometry/so3.hpp"

namespace rcal::discrepancy {

AngleErrors BroadErrors(const Eigen::Vector4d& q_est, const Eigen::Vector4d& q_truth) {
  // A non-finite (or zero) quaternion has no error angle: NaN, never the 0 that std::min(1, NaN)
  // and acos would make of it, so a failed filter cannot score as perfect.
  const double n_est = q_est.norm(), n_truth = q_truth.norm();
  if (!std::isfinite(n_est) || !std::isfinite(n_truth) || n_est == 0.0 || n_truth == 0.0) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    return {nan, nan, nan};
  }
  const Eigen::Vector4d e =
      geometry::QuatMultiply(q_est.normalized(), geometry::QuatConjugate(q_truth.normalized()));
  const double w = std::abs(e(0));
  AngleErrors a;
  a.total = 2.0 * std::acos(std::min(1.0, w));
  // atan2: a half turn about a horizontal axis has e_w = e_z = 0 (heading 0, not 0/0).
  a.heading = 2.0 * std::atan2(std::abs(e(3)), w);
  a.inclination = 2.0 * std::acos(std::min(1.0, std::sqrt(e(0) * e(0) + e(3) * e(3))));
  return a;
}

}  // namespace rcal::discrepancy
