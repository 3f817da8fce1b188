#include "rcal/geometry/so3.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

namespace rcal::geometry {

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0, -v(2), v(1), v(2), 0, -v(0), -v(1), v(0), 0;
  return S;
}

Eigen::Matrix3d Exp(const Eigen::Vector3d& w) {
  const double theta2 = w.squaredNorm();
  const Eigen::Matrix3d W = Skew(w);
  double a, b;  // R = I + a W + b W²
  if (theta2 < 1e-12) {
    a = 1.0 - theta2 / 6.0;
    b = 0.5 - theta2 / 24.0;
  } else {
    const double theta = std::sqrt(theta2);
    a = std::sin(theta) / theta;
    b = (1.0 - std::cos(theta)) / theta2;
  }
  return Eigen::Matrix3d::Identity() + a * W + b * W * W;
}

Eigen::Vector3d Log(const Eigen::Matrix3d& R) {
  // Through the quaternion: atan2 keeps full precision near 0 and near π, unlike acos(trace).
  const Eigen::Quaterniond q(R);
  double w = q.w();
  Eigen::Vector3d v = q.vec();
  if (w < 0) {
    w = -w;
    v = -v;
  }
  const double n = v.norm();
  if (n < 1e-12) return 2.0 * v / std::max(w, 1e-300);
  return 2.0 * std::atan2(n, w) / n * v;
}

Eigen::Matrix3d RightJacobian(const Eigen::Vector3d& w) {
  const double theta2 = w.squaredNorm();
  const Eigen::Matrix3d W = Skew(w);
  if (theta2 < 1e-10) return Eigen::Matrix3d::Identity() - 0.5 * W + W * W / 6.0;
  const double theta = std::sqrt(theta2);
  return Eigen::Matrix3d::Identity() - (1.0 - std::cos(theta)) / theta2 * W +
         (theta - std::sin(theta)) / (theta2 * theta) * W * W;
}

Eigen::Matrix3d RightJacobianInverse(const Eigen::Vector3d& w) {
  const double theta2 = w.squaredNorm();
  const Eigen::Matrix3d W = Skew(w);
  if (theta2 < 1e-10) return Eigen::Matrix3d::Identity() + 0.5 * W + W * W / 12.0;
  const double theta = std::sqrt(theta2);
  return Eigen::Matrix3d::Identity() + 0.5 * W +
         (1.0 / theta2 - (1.0 + std::cos(theta)) / (2.0 * theta * std::sin(theta))) * W * W;
}

double AngleBetween(const Eigen::Matrix3d& R_a, const Eigen::Matrix3d& R_b) {
  return Log(R_a.transpose() * R_b).norm();
}

Eigen::Matrix3d Rx(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Eigen::Matrix3d R;
  R << 1, 0, 0, 0, c, -s, 0, s, c;
  return R;
}

Eigen::Matrix3d Ry(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Eigen::Matrix3d R;
  R << c, 0, s, 0, 1, 0, -s, 0, c;
  return R;
}

Eigen::Matrix3d Rz(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Eigen::Matrix3d R;
  R << c, -s, 0, s, c, 0, 0, 0, 1;
  return R;
}

Eigen::Matrix3d FromRpy(double roll, double pitch, double yaw) {
  return Rz(yaw) * Ry(pitch) * Rx(roll);
}

Eigen::Vector3d ToRpy(const Eigen::Matrix3d& R) {
  const double pitch = std::atan2(-R(2, 0), std::hypot(R(0, 0), R(1, 0)));
  const double yaw = std::atan2(R(1, 0), R(0, 0));
  const double roll = std::atan2(R(2, 1), R(2, 2));
  return {roll, pitch, yaw};
}

Eigen::Matrix3d QuatToMatrix(const Eigen::Vector4d& q) {
  return Eigen::Quaterniond(q(0), q(1), q(2), q(3)).normalized().toRotationMatrix();
}

Eigen::Vector4d MatrixToQuat(const Eigen::Matrix3d& R) {
  const Eigen::Quaterniond q(R);
  Eigen::Vector4d out(q.w(), q.x(), q.y(), q.z());
  out.normalize();
  if (out(0) < 0) out = -out;
  return out;
}

Eigen::Vector4d QuatMultiply(const Eigen::Vector4d& a, const Eigen::Vector4d& b) {
  return {a(0) * b(0) - a(1) * b(1) - a(2) * b(2) - a(3) * b(3),
          a(0) * b(1) + a(1) * b(0) + a(2) * b(3) - a(3) * b(2),
          a(0) * b(2) - a(1) * b(3) + a(2) * b(0) + a(3) * b(1),
          a(0) * b(3) + a(1) * b(2) - a(2) * b(1) + a(3) * b(0)};
}

Eigen::Vector4d QuatConjugate(const Eigen::Vector4d& q) {
  return {q(0), -q(1), -q(2), -q(3)};
}

Eigen::Matrix3d Orthonormalize(const Eigen::Matrix3d& M) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

}  // namespace rcal::geometry
