// Still detection (joints and IMU) and the pose over a still window.
#include "rcal/estimation/still_window.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "rcal/geometry/so3.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::estimation {
namespace {

constexpr double kG = 9.81;

TEST(StillDetector, FromJointsAfterMinDuration) {
  StillDetector d;
  Eigen::VectorXd q = Eigen::VectorXd::Zero(6);
  const Eigen::Vector3d moving_gyro(1, 0, 0), f(0, 0, -kG);
  int first_still = -1;
  for (int k = 0; k < 300; ++k) {
    const double t = 0.01 * k;
    if (k < 100) q(2) += 0.01;                      // 1 rad/s, then stop
    const auto r = d.Update(t, q, moving_gyro, f);  // joints take precedence over the gyro
    ASSERT_TRUE(r.ok()) << r.error();
    if (*r && first_still < 0) first_still = k;
  }
  EXPECT_EQ(first_still, 149);  // last move ends at t = 0.99 s; min_duration 0.5 s
  EXPECT_TRUE(d.still());
  EXPECT_NEAR(d.still_since(), 0.99, 1e-9);
}

TEST(StillDetector, FromImuAndRefusesBadInput) {
  StillDetector d;
  const Eigen::Vector3d f(0, 0, -kG);
  for (int k = 0; k < 100; ++k)
    ASSERT_TRUE(d.Update(0.01 * k, std::nullopt, {0.001, 0, 0}, f).ok());
  EXPECT_TRUE(d.still());
  ASSERT_TRUE(d.Update(1.0, std::nullopt, {0.5, 0, 0}, f).ok());
  EXPECT_FALSE(d.still());
  ASSERT_TRUE(d.Update(1.01, std::nullopt, {0.0, 0, 0}, f + Eigen::Vector3d(2, 0, 0)).ok());
  EXPECT_FALSE(d.still());                                        // accelerating
  EXPECT_FALSE(d.Update(1.01, std::nullopt, {0, 0, 0}, f).ok());  // time not increasing
  const auto bad = d.Update(1.02, std::nullopt, {NAN, 0, 0}, f);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().find("gyro"), std::string::npos);
}

TEST(StillWindow, MeanPoseAndCovariance) {
  std::mt19937_64 rng(4);
  std::normal_distribution<double> N(0.0, 1.0);
  const Eigen::Vector3d p_true(0.3, -0.1, 0.8);
  const Eigen::Matrix3d R_true = geometry::FromRpy(0.2, -0.4, 2.9);
  StillWindow w;
  EXPECT_FALSE(w.Estimate().ok());
  const Eigen::Matrix3d P_p = 1e-6 * Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d P_th = 1e-4 * Eigen::Matrix3d::Identity();
  for (int k = 0; k < 200; ++k) {
    const Eigen::Vector3d p = p_true + 1e-3 * sim::Draw3(N, rng);
    const Eigen::Matrix3d R = geometry::Exp(0.01 * sim::Draw3(N, rng)) * R_true;
    Eigen::Vector4d q = geometry::MatrixToQuat(R);
    if (k % 2) q = -q;  // q and −q are one rotation
    ASSERT_TRUE(w.Add(0.01 * k, p, P_p, q, P_th).ok());
  }
  const auto est = w.Estimate();
  ASSERT_TRUE(est.ok());
  EXPECT_EQ(est->samples, 200);
  EXPECT_LT((est->p_WM_W - p_true).norm(), 5e-4);
  EXPECT_LT(geometry::AngleBetween(geometry::QuatToMatrix(est->q_EB), R_true), 3e-3);
  EXPECT_GE(est->q_EB(0), 0.0);
  // Conservative: at least the mean filter covariance, plus the scatter over N.
  EXPECT_GT(est->P_p(0, 0), 1e-6);
  EXPECT_LT(est->P_p(0, 0), 1e-6 + 2e-6 / 200);
  EXPECT_GT(est->P_theta(2, 2), 1e-4);
  EXPECT_TRUE((est->P.topLeftCorner<3, 3>() - est->P_p).isZero(0.0));
  EXPECT_TRUE((est->P.bottomRightCorner<3, 3>() - est->P_theta).isZero(0.0));
  EXPECT_FALSE(w.Add(2.0, Eigen::Vector3d(NAN, 0, 0), P_p, Eigen::Vector4d(1, 0, 0, 0), P_th).ok());
  EXPECT_FALSE(w.Add(2.0, p_true, P_p, Eigen::Vector4d::Zero(), P_th).ok());
  EXPECT_EQ(w.size(), 200);
  w.Reset();
  EXPECT_EQ(w.size(), 0);
}

}  // namespace
}  // namespace rcal::estimation
