#include "rcal/discrepancy/imu_scoring.hpp"

#include <algorithm>

#include "rcal/geometry/so3.hpp"

namespace rcal::discrepancy {

AngleErrors BroadErrors(const Eigen::Vector4d& q_est, const Eigen::Vector4d& q_truth) {
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
