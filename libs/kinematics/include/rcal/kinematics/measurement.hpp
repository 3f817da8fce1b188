// A still-pose measurement and its residual against the model.
//
// Residual convention (matches KinematicModel::IdentificationJacobian):
//   r = [ p_WM_W,meas − p_WM_W(q, x) ;  Log(R_EI,meas · R_EI(q, x)ᵀ) ]   [m ; rad, earth frame]
// so that r(x + dx) ≈ r(x) − J(q, x)·dx.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "rcal/kinematics/model.hpp"

namespace rcal::kinematics {

struct PoseMeasurement {
  Eigen::VectorXd q;                                 ///< joints as read [rad | m]
  Eigen::Vector3d p_WM_W = Eigen::Vector3d::Zero();  ///< measured marker position, world [m]
  /// Which marker was measured: a slot of model.markers() (0: the first; not the dataset's id,
  /// see KinematicModel::MarkerSlot). The model's view KinematicModel::ForMarker(marker) predicts
  /// it.
  int marker = 0;
  bool has_orientation = false;
  Eigen::Matrix3d R_EI = Eigen::Matrix3d::Identity();  ///< measured IMU orientation, imu → earth
  /// Covariance of the residual: 3×3 [m²] when position only, 6×6 [m², m·rad, rad²] otherwise.
  Eigen::MatrixXd covariance;

  int dimension() const { return has_orientation ? 6 : 3; }
};

/// r = z − h(q, x) in the convention above (h of model.ForMarker(m.marker)); size 3 or 6 after
/// `m.dimension()`.
Eigen::VectorXd Residual(const KinematicModel& model, const PoseMeasurement& m,
                         const Eigen::VectorXd& x);

/// Residual and the Jacobian of h (not of r) restricted to the columns `identified`.
void ResidualAndJacobian(const KinematicModel& model, const PoseMeasurement& m,
                         const Eigen::VectorXd& x, const std::vector<int>& identified,
                         Eigen::VectorXd& r, Eigen::MatrixXd& H);

/// Checks a measurement against a model: joint count, finite values, covariance size and
/// positive definiteness. Returns an empty string when valid, else a reason naming the field.
std::string Validate(const KinematicModel& model, const PoseMeasurement& m);

}  // namespace rcal::kinematics
