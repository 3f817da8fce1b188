#include "rcal/geometry/so3.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "rcal/sim/draw.hpp"

namespace rcal::geometry {
namespace {

Eigen::Vector3d RandomRotationVector(std::mt19937& rng, double max_angle) {
  std::normal_distribution<double> n(0.0, 1.0);
  std::uniform_real_distribution<double> u(0.0, max_angle);
  Eigen::Vector3d axis = sim::Draw3(n, rng);
  return axis.normalized() * u(rng);
}

TEST(So3, ExpMatchesAngleAxis) {
  std::mt19937 rng(1);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d w = RandomRotationVector(rng, std::numbers::pi);
    const Eigen::Matrix3d expected = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    EXPECT_LT((Exp(w) - expected).norm(), 1e-12);
  }
}

TEST(So3, LogInvertsExpIncludingNearZeroAndPi) {
  std::mt19937 rng(2);
  for (double max_angle : {1e-9, 1e-4, 1.0, std::numbers::pi - 1e-6}) {
    for (int i = 0; i < 100; ++i) {
      const Eigen::Vector3d w = RandomRotationVector(rng, max_angle);
      EXPECT_LT((Log(Exp(w)) - w).norm(), 1e-9 * std::max(1.0, w.norm())) << w.transpose();
    }
  }
}

TEST(So3, RightJacobianMatchesFiniteDifferences) {
  std::mt19937 rng(3);
  for (int i = 0; i < 20; ++i) {
    const Eigen::Vector3d w = RandomRotationVector(rng, 2.5);
    // Exp(w + δ) ≈ Exp(w) Exp(Jr(w) δ)
    Eigen::Matrix3d numeric;
    const double h = 1e-6;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d d = Eigen::Vector3d::Unit(k) * h;
      numeric.col(k) = Log(Exp(w).transpose() * Exp(w + d)) / h;
    }
    EXPECT_LT((numeric - RightJacobian(w)).norm(), 1e-5);
    EXPECT_LT((RightJacobianInverse(w) * RightJacobian(w) - Eigen::Matrix3d::Identity()).norm(),
              1e-9);
  }
}

TEST(So3, RpyRoundTripAndConvention) {
  // Rz(yaw)·Ry(pitch)·Rx(roll): a pure yaw of 90° maps x to y.
  EXPECT_LT(
      (FromRpy(0, 0, std::numbers::pi / 2) * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY())
          .norm(),
      1e-15);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d rpy = sim::Draw3(u, rng).cwiseProduct(Eigen::Vector3d(2, 1, 2));
    EXPECT_LT((ToRpy(FromRpy(rpy)) - rpy).norm(), 1e-12);
  }
}

TEST(So3, QuaternionMatrixRoundTripAndProduct) {
  std::mt19937 rng(5);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Matrix3d Ra = Exp(RandomRotationVector(rng, 3.0));
    const Eigen::Matrix3d Rb = Exp(RandomRotationVector(rng, 3.0));
    const Eigen::Vector4d qa = MatrixToQuat(Ra), qb = MatrixToQuat(Rb);
    EXPECT_GE(qa(0), 0.0);
    EXPECT_LT((QuatToMatrix(qa) - Ra).norm(), 1e-12);
    EXPECT_LT((QuatToMatrix(QuatMultiply(qa, qb)) - Ra * Rb).norm(), 1e-12);
    EXPECT_LT((QuatToMatrix(QuatConjugate(qa)) - Ra.transpose()).norm(), 1e-12);
  }
}

TEST(So3, OrthonormalizeRepairsPerturbedRotation) {
  const Eigen::Matrix3d R = FromRpy(0.3, -0.2, 1.1);
  const Eigen::Matrix3d M = R + 1e-4 * Eigen::Matrix3d::Ones();
  const Eigen::Matrix3d P = Orthonormalize(M);
  EXPECT_LT((P.transpose() * P - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(P.determinant(), 1.0, 1e-12);
  EXPECT_LT(AngleBetween(P, R), 1e-3);
}

}  // namespace
}  // namespace rcal::geometry
