// The pose pipeline on synthetic streams with a known truth: still stops at known poses joined
// by constant-rate moves (gyro consistent with the rotation), white sensor noise of an Xsens
// MTi-100 class IMU and a 0.5 mm position sensor. Checks: one pose per stop, its error against
// the truth consistent with its covariance (NEES), bad input refused with a reason.
#include "rcal/estimation/pose_pipeline.hpp"

#include <gtest/gtest.h>

#include <random>

#include "rcal/geometry/so3.hpp"

namespace rcal::estimation {
namespace {

struct Stop {
  Eigen::Matrix3d R_EI;
  Eigen::Vector3d p_W;
};

struct Outcome {
  std::vector<StillPose> poses;
  std::vector<Stop> stops;
};

Outcome Simulate(int num_stops, unsigned seed, double still_s = 1.5, double move_s = 1.0) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0, 1);
  auto n3 = [&] { return Eigen::Vector3d(n(rng), n(rng), n(rng)); };
  const double dt = 0.01;
  const Eigen::Vector3d g_E(0, 0, 9.81), m_E(20, 0, 44);
  const double sg = 0.01 * M_PI / 180 * 10, sa = 60e-6 * 9.81 * 10, sm = 0.02 * 10, sp = 5e-4;
  Outcome o;
  for (int k = 0; k < num_stops; ++k)
    o.stops.push_back({geometry::Exp(0.8 * n3()), Eigen::Vector3d(1, 0.2, 0.5) + 0.3 * n3()});
  PosePipeline pipe;
  double t = 0;
  auto sample = [&](const Eigen::Matrix3d& R, const Eigen::Vector3d& p, const Eigen::Vector3d& w_I,
                    const Eigen::VectorXd& q) {
    ASSERT_TRUE(pipe.AddJoints(t, q));
    ASSERT_TRUE(pipe.AddImu(t, w_I + sg * n3(), -R.transpose() * g_E + sa * n3(),
                            R.transpose() * m_E + sm * n3()));
    ASSERT_TRUE(pipe.AddPosition(t, p + sp * n3()));
    t += dt;
  };
  for (int k = 0; k < num_stops; ++k) {
    const Eigen::VectorXd q = Eigen::VectorXd::Constant(6, 0.1 * k);
    for (int i = 0; i < static_cast<int>(still_s / dt); ++i)
      sample(o.stops[k].R_EI, o.stops[k].p_W, Eigen::Vector3d::Zero(), q);
    if (k + 1 == num_stops) break;
    // Move: constant body rate to the next orientation, straight line in position.
    const Eigen::Vector3d w_I =
        geometry::Log(o.stops[k].R_EI.transpose() * o.stops[k + 1].R_EI) / move_s;
    const int steps = static_cast<int>(move_s / dt);
    for (int i = 0; i < steps; ++i) {
      const double s = static_cast<double>(i) / steps;
      const Eigen::Matrix3d R = o.stops[k].R_EI * geometry::Exp(w_I * s * move_s);
      const Eigen::Vector3d p = (1 - s) * o.stops[k].p_W + s * o.stops[k + 1].p_W;
      sample(R, p, w_I, Eigen::VectorXd::Constant(6, 0.1 * k + 0.1 * s));
    }
  }
  pipe.Flush();
  o.poses = pipe.TakePoses();
  return o;
}

TEST(PosePipeline, OnePosePerStopWithAConsistentCovariance) {
  const Outcome o = Simulate(40, 7);
  ASSERT_EQ(o.poses.size(), o.stops.size());
  double nees = 0;
  for (size_t k = 0; k < o.poses.size(); ++k) {
    const StillPose& p = o.poses[k];
    ASSERT_TRUE(p.has_orientation);
    ASSERT_EQ(p.covariance.rows(), 6);
    EXPECT_NEAR(p.q(0), 0.1 * k, 1e-12);
    Eigen::Matrix<double, 6, 1> r;
    r.head<3>() = p.p_WM_W - o.stops[k].p_W;
    r.tail<3>() = geometry::Log(p.R_EI * o.stops[k].R_EI.transpose());
    EXPECT_LT(r.head<3>().norm(), 5e-4);              // far below one sample's 0.5 mm
    EXPECT_LT(r.tail<3>().norm(), 0.2 * M_PI / 180);  // 0.2°
    nees += r.dot(p.covariance.ldlt().solve(r));
    // The identifier's measurement carries the window unchanged.
    const kinematics::PoseMeasurement z = p.ToMeasurement();
    EXPECT_EQ(z.q, p.q);
    EXPECT_EQ(z.p_WM_W, p.p_WM_W);
    EXPECT_EQ(z.R_EI, p.R_EI);
    EXPECT_EQ(z.covariance, p.covariance);
    EXPECT_EQ(z.dimension(), 6);
  }
  nees /= o.poses.size();
  // χ²₆ mean 6; over 40 windows the mean has σ ≈ 0.55. Neither over- nor under-confident.
  EXPECT_GT(nees, 3.0);
  EXPECT_LT(nees, 10.0);
}

TEST(PosePipeline, DeterministicForTheSameInput) {
  const Outcome a = Simulate(5, 3), b = Simulate(5, 3);
  ASSERT_EQ(a.poses.size(), b.poses.size());
  for (size_t k = 0; k < a.poses.size(); ++k) {
    EXPECT_EQ(a.poses[k].p_WM_W, b.poses[k].p_WM_W);
    EXPECT_EQ(a.poses[k].covariance, b.poses[k].covariance);
  }
}

TEST(PosePipeline, RefusesBadInputNamingTheFieldAndKeepsGoing) {
  PosePipeline pipe;
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(6);
  ASSERT_TRUE(pipe.AddJoints(1.0, q));
  Status s = pipe.AddJoints(0.5, q);
  EXPECT_FALSE(s);
  EXPECT_NE(s.error().find("joints.t"), std::string::npos) << s.error();
  s = pipe.AddJoints(1.1, Eigen::VectorXd::Zero(5));
  EXPECT_NE(s.error().find("joints.q"), std::string::npos) << s.error();
  s = pipe.AddImu(1.1, Eigen::Vector3d(NAN, 0, 0), Eigen::Vector3d(0, 0, -9.81),
                  Eigen::Vector3d(20, 0, 44));
  EXPECT_NE(s.error().find("imu.gyro"), std::string::npos) << s.error();
  s = pipe.AddPosition(1.1, Eigen::Vector3d(0, INFINITY, 0));
  EXPECT_NE(s.error().find("position.p_WM_W"), std::string::npos) << s.error();
  EXPECT_EQ(pipe.counters().input_rejected, 4);
  EXPECT_TRUE(pipe.AddImu(1.1, Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, -9.81),
                          Eigen::Vector3d(20, 0, 44)));
  pipe.Reset();
  EXPECT_EQ(pipe.counters().input_rejected, 0);
  EXPECT_TRUE(pipe.AddJoints(0.0, q));  // time restarts after Reset
}

TEST(PosePipeline, StopsShorterThanDetectionAndSettlingGiveNoPose) {
  const Outcome o = Simulate(4, 11, /*still_s=*/0.6);  // 0.5 s detection + 0.2 s settle > 0.6 s
  EXPECT_TRUE(o.poses.empty());
}

}  // namespace
}  // namespace rcal::estimation
