#include "rcal/sim/random_arm.hpp"

#include <gtest/gtest.h>

#include "rcal/sim/pose_sim.hpp"

namespace rcal::sim {
namespace {

// Standard D–H: Rz(θ) · Tz(d) · Tx(a) · Rx(α), written out here (not the model's ETs).
Eigen::Matrix4d Dh(double a, double alpha, double d, double theta) {
  const double ct = std::cos(theta), st = std::sin(theta), ca = std::cos(alpha),
               sa = std::sin(alpha);
  Eigen::Matrix4d T;
  T << ct, -st * ca, st * sa, a * ct, st, ct * ca, -ct * sa, a * st, 0, sa, ca, d, 0, 0, 0, 1;
  return T;
}

// The product of the standard D–H transforms of the arm's six links at joints q, from their
// nominal parameters (absent: 0).
Eigen::Matrix4d DhChain(const kinematics::KinematicModel& m, const Eigen::VectorXd& q) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  for (int i = 1; i <= 6; ++i) {
    const std::string n = std::to_string(i);
    const auto nominal = [&](const std::string& name) {
      const int k = m.FindParameter(name + n);
      return k < 0 ? 0.0 : m.parameters()[k].nominal;
    };
    T = T * Dh(nominal("a"), nominal("alpha"), nominal("d"), nominal("theta") + q(i - 1));
  }
  return T;
}

TEST(RandomArm, ADrawnArmIsTheStandardDhArmItsParametersDescribe) {
  for (std::uint64_t seed : {1u, 7u, 101u, 102u}) {
    const auto m = RandomDhArm(seed);
    ASSERT_EQ(m.num_joints(), 6);
    EXPECT_EQ(m.name(), "random_dh_" + std::to_string(seed));
    // Base frame (6), per link θ, a, α and d or β, marker (3).
    EXPECT_EQ(m.num_params(), 6 + 6 * 4 + 3);
    EXPECT_NE(m.parameters()[m.FindParameter("alpha1")].nominal, 0.0);
    Rng rng(seed);
    // β only where the next axis is parallel (α = 0), and then no d.
    for (int i = 1; i <= 6; ++i) {
      const std::string n = std::to_string(i);
      if (m.FindParameter("beta" + n) >= 0) {
        EXPECT_EQ(m.parameters()[m.FindParameter("alpha" + n)].nominal, 0.0);
        EXPECT_LT(m.FindParameter("d" + n), 0);
      }
    }
    for (const auto& q : SampleJoints(m, 5, rng)) {
      const Eigen::Matrix4d T = DhChain(m, q);
      const Eigen::Vector3d p = (T * Eigen::Vector4d(0.05, 0.0, 0.1, 1.0)).head<3>();
      EXPECT_LT((m.Forward(q, m.Nominal()).p_WM_W - p).norm(), 1e-12);
    }
    for (const auto& j : m.joints()) {
      EXPECT_GE(j.upper, 2.0);
      EXPECT_LE(j.upper, 3.0);
      EXPECT_EQ(j.lower, -j.upper);
    }
  }
  // Seeded: the same seed, the same arm; another seed, another arm.
  const auto a = RandomDhArm(5), b = RandomDhArm(5), c = RandomDhArm(6);
  Eigen::VectorXd q = Eigen::VectorXd::Constant(6, 0.3);
  EXPECT_EQ(a.Forward(q, a.Nominal()).p_WM_W, b.Forward(q, b.Nominal()).p_WM_W);
  EXPECT_GT((a.Forward(q, a.Nominal()).p_WM_W - c.Forward(q, c.Nominal()).p_WM_W).norm(), 1e-3);
}

// For full poses: the IMU frame is three more parameters on the same arm, and the IMU's nominal
// orientation is the flange's, the product of the standard D–H rotations.
TEST(RandomArm, AnImuFrameAddsTheFlangesOrientationAndKeepsTheArm) {
  RandomArmSettings with_imu;
  with_imu.imu_frame = true;
  for (std::uint64_t seed : {3u, 201u}) {
    const auto plain = RandomDhArm(seed), m = RandomDhArm(seed, with_imu);
    ASSERT_EQ(m.num_params(), plain.num_params() + 3);
    for (const char* name : {"imu_rx", "imu_ry", "imu_rz"})
      EXPECT_GE(m.FindParameter(name), 0) << name;
    Rng rng(seed);
    for (const auto& q : SampleJoints(m, 5, rng)) {
      const Eigen::Matrix4d T = DhChain(m, q);
      const auto pose = m.Forward(q, m.Nominal());
      EXPECT_LT((pose.R_EI - T.topLeftCorner<3, 3>()).norm(), 1e-12);
      EXPECT_LT((pose.p_WM_W - plain.Forward(q, plain.Nominal()).p_WM_W).norm(), 1e-15);
    }
  }
}

}  // namespace
}  // namespace rcal::sim
