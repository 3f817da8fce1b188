// Rotations: SO(3) exponential and logarithm, quaternions, roll-pitch-yaw.
//
// Conventions (used everywhere in rcal):
// - Quaternions are Hamilton, stored and printed w, x, y, z. `q_AB` rotates vectors from frame B
//   into frame A: v_A = q_AB ⊗ v_B ⊗ q_AB*; `R_AB` is the same rotation as a matrix.
// - Small rotation errors are rotation vectors [rad] on the left: R_meas = Exp(δθ) · R_model,
//   δθ expressed in the frame the rotation maps into.
// - Roll-pitch-yaw: R = Rz(yaw) · Ry(pitch) · Rx(roll), as URDF and FIGAROH use.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace rcal::geometry {

/// Skew-symmetric matrix [v]× such that [v]× u = v × u.
Eigen::Matrix3d Skew(const Eigen::Vector3d& v);

/// Exponential map so(3) → SO(3): rotation by |w| [rad] about w/|w|.
Eigen::Matrix3d Exp(const Eigen::Vector3d& w);

/// Logarithm SO(3) → so(3): the rotation vector [rad] of R, |result| ≤ π. Accurate near 0 and π.
Eigen::Vector3d Log(const Eigen::Matrix3d& R);

/// Right Jacobian of SO(3), and its inverse (d Log(R Exp(δ)) = Jr⁻¹ δ).
Eigen::Matrix3d RightJacobian(const Eigen::Vector3d& w);
Eigen::Matrix3d RightJacobianInverse(const Eigen::Vector3d& w);

/// Rotation angle [rad] between two rotations, in [0, π].
double AngleBetween(const Eigen::Matrix3d& R_a, const Eigen::Matrix3d& R_b);

/// Elementary rotations about the x, y and z axes by `angle` [rad].
Eigen::Matrix3d Rx(double angle);
Eigen::Matrix3d Ry(double angle);
Eigen::Matrix3d Rz(double angle);

/// R = Rz(yaw) · Ry(pitch) · Rx(roll); angles [rad].
Eigen::Matrix3d FromRpy(double roll, double pitch, double yaw);
inline Eigen::Matrix3d FromRpy(const Eigen::Vector3d& rpy) {
  return FromRpy(rpy(0), rpy(1), rpy(2));
}
/// Inverse of FromRpy: [roll, pitch, yaw] with pitch in [−π/2, π/2].
Eigen::Vector3d ToRpy(const Eigen::Matrix3d& R);

/// Quaternion [w, x, y, z] ↔ rotation matrix. The quaternion is normalised first; the returned
/// quaternion has w ≥ 0 (q and −q are one rotation).
Eigen::Matrix3d QuatToMatrix(const Eigen::Vector4d& q_wxyz);
Eigen::Vector4d MatrixToQuat(const Eigen::Matrix3d& R);

/// Hamilton product a ⊗ b, both [w, x, y, z].
Eigen::Vector4d QuatMultiply(const Eigen::Vector4d& a, const Eigen::Vector4d& b);
/// Conjugate [w, −x, −y, −z].
Eigen::Vector4d QuatConjugate(const Eigen::Vector4d& q);

/// Projects a near-rotation matrix onto SO(3) (closest in Frobenius norm).
Eigen::Matrix3d Orthonormalize(const Eigen::Matrix3d& M);

}  // namespace rcal::geometry
