// IMU model: noise levels match the densities, each effect switches on and off, seeding.
#include "rcal/sim/imu_model.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace rcal::sim {
namespace {

ImuTruth RestTruth(double t) {
  ImuTruth s;
  s.t = t;
  return s;
}

TEST(ImuModel, NoiseFreeAtRestReadsGravityAndField) {
  ImuModelSettings s;
  s.white_noise = false;
  ImuModel imu(s, 1);
  ImuTruth truth = RestTruth(0.0);
  // 90° about z: x_I points east.
  truth.R_WI << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  truth.omega_I = Eigen::Vector3d(0.1, 0.2, 0.3);
  const ImuSample m = imu.Sample(truth);
  EXPECT_LT((m.accel_S - Eigen::Vector3d(0, 0, -9.81)).norm(), 1e-12);  // level: reads −g on z
  EXPECT_LT((m.mag_S - Eigen::Vector3d(0, -20, 44)).norm(), 1e-12);
  EXPECT_LT((m.gyro_S - truth.omega_I).norm(), 1e-12);
}

TEST(ImuModel, WhiteNoiseMatchesXsensDensities) {
  ImuModel imu(ImuModelSettings{}, 42);
  const int n = 20000;
  Eigen::Vector3d sg = Eigen::Vector3d::Zero(), sa = sg, sm = sg;
  for (int k = 0; k < n; ++k) {
    const ImuSample m = imu.Sample(RestTruth(0.01 * k));
    sg += m.gyro_S.cwiseAbs2() / n;
    sa += (m.accel_S - Eigen::Vector3d(0, 0, -9.81)).cwiseAbs2() / n;
    sm += (m.mag_S - Eigen::Vector3d(20, 0, 44)).cwiseAbs2() / n;
  }
  const double gyro = 0.01 * std::numbers::pi / 180 * 10;  // density × √100 Hz
  const double acc = 60e-6 * 9.81 * 10, mag = 0.02 * 10;
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(std::sqrt(sg(i)), gyro, 0.03 * gyro);
    EXPECT_NEAR(std::sqrt(sa(i)), acc, 0.03 * acc);
    EXPECT_NEAR(std::sqrt(sm(i)), mag, 0.03 * mag);
  }
}

TEST(ImuModel, BiasScaleMountingAndSpecificForce) {
  ImuModelSettings s;
  s.white_noise = false;
  s.constant_bias = true;
  s.gyro_bias = {0.01, 0, 0};
  s.accel_bias = {0, 0.1, 0};
  s.mag_bias = {1, 0, 0};
  s.scale_misalignment = true;
  s.gyro_M = Eigen::Vector3d(0.01, 0, 0).asDiagonal();
  s.mounting = true;
  s.R_SI << 0, 1, 0, -1, 0, 0, 0, 0, 1;
  ImuModel imu(s, 1);
  ImuTruth truth = RestTruth(0.0);
  truth.omega_I = {1, 0, 0};
  truth.a_W = s.g_W;  // free fall: specific force zero
  const ImuSample m = imu.Sample(truth);
  EXPECT_LT((m.accel_S - Eigen::Vector3d(0, 0.1, 0)).norm(), 1e-12);
  // ω_S = (I + M) R_SI ω_I + b = (I + M) [0, −1, 0] + b.
  EXPECT_LT((m.gyro_S - Eigen::Vector3d(0.01, -1, 0)).norm(), 1e-12);
  EXPECT_LT((m.mag_S - (s.R_SI * Eigen::Vector3d(20, 0, 44) + Eigen::Vector3d(1, 0, 0))).norm(),
            1e-12);
}

TEST(ImuModel, RandomWalkBiasGrowsWithSqrtTimeAndIsSeeded) {
  ImuModelSettings s;
  s.white_noise = false;
  s.bias_random_walk = true;
  s.gyro_bias_random_walk = 1e-3;
  double var = 0;
  const int runs = 200;
  for (int r = 0; r < runs; ++r) {
    ImuModel imu(s, 100 + r);
    for (int k = 0; k <= 10000; ++k) imu.Sample(RestTruth(0.01 * k));  // 100 s
    var += imu.gyro_bias().squaredNorm() / 3 / runs;
  }
  EXPECT_NEAR(std::sqrt(var), 1e-3 * std::sqrt(100.0), 0.15 * 1e-2);
  ImuModel a(ImuModelSettings{}, 7), b(ImuModelSettings{}, 7), c(ImuModelSettings{}, 8);
  const ImuSample ma = a.Sample(RestTruth(0)), mb = b.Sample(RestTruth(0)),
                  mc = c.Sample(RestTruth(0));
  EXPECT_EQ(ma.gyro_S, mb.gyro_S);
  EXPECT_NE(ma.gyro_S, mc.gyro_S);
  a.Reset(8);
  EXPECT_EQ(a.Sample(RestTruth(0)).gyro_S, mc.gyro_S);
}

}  // namespace
}  // namespace rcal::sim
