// Position sensor model: rate, noise, latency, dropouts, frame, seeding.
#include "rcal/sim/position_sensor_model.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace rcal::sim {
namespace {

TEST(PositionSensorModel, DecimatesToItsRateWithNoise) {
  PositionSensorModel sensor(PositionSensorSettings{}, 3);
  const Eigen::Vector3d p(0.1, 0.2, 0.3);
  int count = 0;
  double var = 0;
  for (int k = 0; k < 100000; ++k) {  // 1000 s at 100 Hz
    const auto m = sensor.Sample(0.01 * k, p);
    if (!m) continue;
    ++count;
    EXPECT_EQ(m->t_available, m->t);
    var += (m->p_M - p).squaredNorm() / 3;
  }
  EXPECT_EQ(count, 20000);  // 20 Hz
  EXPECT_NEAR(std::sqrt(var / count), 1e-3, 2e-5);
}

TEST(PositionSensorModel, LatencyDropoutsAndFrame) {
  PositionSensorSettings s;
  s.noise = false;
  s.latency_enabled = true;
  s.latency = 0.03;
  s.dropouts = true;
  s.dropout_probability = 0.25;
  s.R_MW << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  s.t_MW = {1, 2, 3};
  PositionSensorModel sensor(s, 5);
  int fired = 0;
  for (int k = 0; k < 40000; ++k) {
    const auto m = sensor.Sample(0.01 * k, Eigen::Vector3d(1, 0, 0));
    if (!m) continue;
    ++fired;
    EXPECT_NEAR(m->t_available - m->t, 0.03, 1e-12);
    EXPECT_LT((m->p_M - Eigen::Vector3d(1, 3, 3)).norm(), 1e-12);
  }
  EXPECT_EQ(fired + sensor.dropped(), 8000);
  EXPECT_NEAR(static_cast<double>(sensor.dropped()) / 8000, 0.25, 0.02);
}

TEST(PositionSensorModel, Seeded) {
  PositionSensorModel a(PositionSensorSettings{}, 9), b(PositionSensorSettings{}, 9),
      c(PositionSensorSettings{}, 10);
  const Eigen::Vector3d p = Eigen::Vector3d::Zero();
  EXPECT_EQ(a.Sample(0, p)->p_M, b.Sample(0, p)->p_M);
  EXPECT_NE(a.Sample(0.05, p)->p_M, c.Sample(0.05, p)->p_M);
}

}  // namespace
}  // namespace rcal::sim
