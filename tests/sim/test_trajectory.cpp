#include "rcal/sim/trajectory.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace rcal::sim {
namespace {

std::vector<Eigen::VectorXd> Waypoints(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-2, 2);
  std::vector<Eigen::VectorXd> w;
  for (int k = 0; k < n; ++k) w.push_back(Eigen::VectorXd::NullaryExpr(6, [&] { return u(rng); }));
  return w;
}

TEST(Trajectory, StandsAtEachWaypointForItsStillTime) {
  TrajectorySettings s;
  const auto w = Waypoints(5, 1);
  const JointTrajectory traj(w, s);
  Eigen::VectorXd q, qd;
  for (int k = 0; k < 5; ++k) {
    const auto [a, b] = traj.StillInterval(k);
    EXPECT_NEAR(b - a, s.still_time, 1e-12);
    for (double t : {a, 0.5 * (a + b), b}) {
      traj.Sample(t, q, &qd);
      EXPECT_LT((q - w[k]).norm(), 1e-12);
      EXPECT_LT(qd.norm(), 1e-12);
      EXPECT_EQ(traj.StillAt(t), k);
    }
  }
  EXPECT_EQ(traj.StillAt(0.5 * (traj.StillInterval(0).second + traj.StillInterval(1).first)), -1);
}

TEST(Trajectory, DerivativesMatchFiniteDifferencesAndRespectLimits) {
  TrajectorySettings s;
  const JointTrajectory traj(Waypoints(6, 2), s);
  Eigen::VectorXd q, qd, qdd, qp, qm, qdp, qdm;
  const double h = 1e-6;
  double max_speed = 0, max_accel = 0;
  for (double t = 0; t < traj.duration(); t += 0.01) {
    traj.Sample(t, q, &qd, &qdd);
    traj.Sample(t + h, qp, &qdp);
    traj.Sample(t - h, qm, &qdm);
    if (t > h && t + h < traj.duration()) {
      EXPECT_LT((qd - (qp - qm) / (2 * h)).norm(), 1e-6);
      EXPECT_LT((qdd - (qdp - qdm) / (2 * h)).norm(), 1e-5);
    }
    max_speed = std::max(max_speed, qd.cwiseAbs().maxCoeff());
    max_accel = std::max(max_accel, qdd.cwiseAbs().maxCoeff());
  }
  EXPECT_LE(max_speed, s.max_joint_speed * (1 + 1e-6));
  EXPECT_LE(max_accel, s.max_joint_accel * (1 + 1e-3));
  EXPECT_GT(max_speed, 0.5 * s.max_joint_speed);  // the limit is used, not merely respected
}

// A program that picks its next stop while it runs moves exactly as the program written with that
// stop from the start, and nothing before the move into the stop changes.
TEST(Trajectory, ARetargetedStopMovesAsTheProgramWrittenWithIt) {
  TrajectorySettings s;
  auto w = Waypoints(6, 3);
  JointTrajectory live(w, s);
  const JointTrajectory before = live;
  const Eigen::VectorXd q3 = Waypoints(1, 4)[0] * 0.3;  // a shorter move: the timing changes
  live.Retarget(3, q3);
  w[3] = q3;
  const JointTrajectory written(w, s);
  EXPECT_NEAR(live.duration(), written.duration(), 1e-12);
  EXPECT_GT(std::abs(live.duration() - before.duration()), 0.1);
  Eigen::VectorXd a, b, ad, bd;
  for (double t = 0; t <= written.duration(); t += 0.01) {
    live.Sample(t, a, &ad);
    written.Sample(t, b, &bd);
    EXPECT_LT((a - b).norm(), 1e-12) << "t = " << t;
    EXPECT_LT((ad - bd).norm(), 1e-12) << "t = " << t;
    EXPECT_EQ(live.StillAt(t), written.StillAt(t));
  }
  const double move_into_3 = before.StillInterval(2).second;
  for (double t = 0; t < move_into_3; t += 0.01) {
    live.Sample(t, a);
    before.Sample(t, b);
    EXPECT_LT((a - b).norm(), 1e-12) << "t = " << t;
  }
  EXPECT_THROW(live.Retarget(0, q3), std::invalid_argument);  // the start is where the arm is
  EXPECT_THROW(live.Retarget(6, q3), std::invalid_argument);
  EXPECT_THROW(live.Retarget(2, Eigen::VectorXd::Zero(5)), std::invalid_argument);
  EXPECT_THROW(live.Retarget(2, Eigen::VectorXd::Constant(6, NAN)), std::invalid_argument);
}

TEST(Trajectory, RejectsBadWaypoints) {
  EXPECT_THROW(JointTrajectory({}), std::invalid_argument);
  EXPECT_THROW(JointTrajectory({Eigen::VectorXd::Zero(6), Eigen::VectorXd::Zero(5)}),
               std::invalid_argument);
}

}  // namespace
}  // namespace rcal::sim
