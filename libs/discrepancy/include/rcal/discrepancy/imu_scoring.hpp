// Orientation errors as the BROAD benchmark scores them (../shared/data/broad/README.md), shared
// by `rcal fuse` and the IMU-stream analysis (imu_analysis.hpp):
//   e = q_est ⊗ q_truth⁻¹ (both IMU → ENU, normalised, [w,x,y,z]),
//   total = 2 acos|e_w|,  heading = 2 atan|e_z / e_w|,  inclination = 2 acos √(e_w² + e_z²)  [rad];
//   RMSE of each over the scored samples (movement = 1 and finite truth).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <limits>

namespace rcal::discrepancy {

/// BROAD error angles [rad] of an estimate against truth; all NaN when either quaternion is
/// non-finite or zero (so an RMSE over them is NaN, never a perfect 0).
struct AngleErrors {
  double total = 0.0, heading = 0.0, inclination = 0.0;
};
AngleErrors BroadErrors(const Eigen::Vector4d& q_est, const Eigen::Vector4d& q_truth);

/// Root mean square of the values added.
struct Rms {
  double sum = 0.0;
  long n = 0;
  void Add(double v) {
    sum += v * v;
    ++n;
  }
  double value() const {
    return n > 0 ? std::sqrt(sum / n) : std::numeric_limits<double>::quiet_NaN();
  }
};

/// Total, heading and inclination RMSE [rad] over the samples added.
struct OrientationScore {
  Rms total, heading, inclination;
  void Add(const AngleErrors& e) {
    total.Add(e.total);
    heading.Add(e.heading);
    inclination.Add(e.inclination);
  }
};

}  // namespace rcal::discrepancy
