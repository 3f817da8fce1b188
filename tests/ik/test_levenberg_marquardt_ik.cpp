// Levenberg–Marquardt IK. Truth is independent of the solver: targets come from
// KinematicModel::ToolFrame (ET by ET) at random joints, and every solution is checked by that same
// model, not by the CompiledChain the solver uses.
#include "rcal/ik/levenberg_marquardt_ik.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <iostream>
#include <random>

#include "../kinematics/test_robots.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::ik {
namespace {

using kinematics::KinematicModel;
using namespace kinematics::testing;

KinematicModel ModelFor(int which) {
  switch (which) {
    case 0:
      return Grb3016();
    case 1:
      return SevenJointSetup();
    default:
      return UrLikeUrdf();
  }
}

Eigen::VectorXd Clamp(const KinematicModel& m, Eigen::VectorXd q) {
  for (int j = 0; j < m.num_joints(); ++j)
    q(j) = std::clamp(q(j), m.joints()[j].lower, m.joints()[j].upper);
  return q;
}

/// Seed near q: every joint moved by up to ±spread [rad], kept inside the limits.
Eigen::VectorXd NearbySeed(const KinematicModel& m, const Eigen::VectorXd& q, double spread,
                           std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-spread, spread);
  Eigen::VectorXd seed = q;
  for (int j = 0; j < m.num_joints(); ++j) seed(j) += u(rng);
  return Clamp(m, seed);
}

constexpr int kTargets = 2000;
constexpr double kPositionCheck = 1e-9;     // [m]
constexpr double kOrientationCheck = 1e-9;  // [rad]

class IkRoundTrip : public ::testing::TestWithParam<int> {};

TEST_P(IkRoundTrip, FullPoseFromNearbySeeds) {
  const KinematicModel m = ModelFor(GetParam());
  std::mt19937 rng(100 + GetParam());
  const Eigen::VectorXd x = RandomErrors(m, rng);  // a calibrated (non-nominal) model
  LevenbergMarquardtIk ik(m, x);
  int ok = 0, false_claims = 0, same_branch = 0, total_iterations = 0;
  double max_from_seed = 0.0;
  for (int t = 0; t < kTargets; ++t) {
    const Eigen::VectorXd q_true = RandomJoints(m, rng);
    const Eigen::Isometry3d T_WT = m.ToolFrame(q_true, x);
    const Eigen::VectorXd seed = NearbySeed(m, q_true, 0.3, rng);
    const IkResult res = ik.Solve(T_WT, seed);
    ASSERT_EQ(res.q.size(), m.num_joints());
    // Independent check of the answer.
    const Eigen::Isometry3d T_check = m.ToolFrame(res.q, x);
    const double dp = (T_check.translation() - T_WT.translation()).norm();
    const double dR = geometry::AngleBetween(T_check.linear(), T_WT.linear());
    const bool good = dp <= kPositionCheck && dR <= kOrientationCheck && m.WithinLimits(res.q);
    if (res.converged) {
      EXPECT_TRUE(res.reason.empty());
      EXPECT_NEAR(res.position_error, dp, 1e-12);
      EXPECT_NEAR(res.orientation_error, dR, 1e-12);
      total_iterations += res.iterations;
      if (good)
        ++ok;
      else
        ++false_claims;
    } else {
      EXPECT_FALSE(res.reason.empty());
      if (std::getenv("RCAL_IK_VERBOSE"))
        std::cout << "  fail: " << res.reason << " q_true " << q_true.transpose() << "\n";
    }
    if ((res.q - q_true).lpNorm<Eigen::Infinity>() < 1e-6) ++same_branch;
    if (res.converged)
      max_from_seed = std::max(max_from_seed, (res.q - seed).lpNorm<Eigen::Infinity>());
  }
  const double rate = double(ok) / kTargets;
  std::cout << m.name() << ": full pose, " << ok << "/" << kTargets << " solved (" << 100 * rate
            << "%), " << same_branch
            << " back at the generating joints, farthest solution from its seed " << max_from_seed
            << " rad, mean iterations " << double(total_iterations) / std::max(ok, 1) << "\n";
  RecordProperty("success_rate", std::to_string(rate));
  EXPECT_EQ(false_claims, 0) << "converged=true but the independent FK disagrees";
  EXPECT_GE(rate, 0.995);
  if (m.num_joints() == 6) {
    // A non-redundant arm has isolated solutions: from a nearby seed it mostly returns to q_true
    // exactly; near the elbow or wrist singularity the other branch lies close and may be found
    // (about 2–4 % here). A jump to a distant branch (a wrist flip moves q4 and q6 by π) never
    // happens.
    EXPECT_GE(double(same_branch) / kTargets, 0.95);
    EXPECT_LT(max_from_seed, 1.0);
  }
}

TEST_P(IkRoundTrip, PositionOnlyFromNearbySeeds) {
  const KinematicModel m = ModelFor(GetParam());
  std::mt19937 rng(200 + GetParam());
  const Eigen::VectorXd x = RandomErrors(m, rng);
  LevenbergMarquardtIk ik(m, x);
  int ok = 0, false_claims = 0;
  for (int t = 0; t < kTargets; ++t) {
    const Eigen::VectorXd q_true = RandomJoints(m, rng);
    const Eigen::Vector3d p_WT_W = m.ToolFrame(q_true, x).translation();
    const IkResult res = ik.SolvePosition(p_WT_W, NearbySeed(m, q_true, 0.3, rng));
    const double dp = (m.ToolFrame(res.q, x).translation() - p_WT_W).norm();
    const bool good = dp <= kPositionCheck && m.WithinLimits(res.q);
    if (res.converged) {
      if (good)
        ++ok;
      else
        ++false_claims;
    } else {
      EXPECT_FALSE(res.reason.empty());
    }
  }
  const double rate = double(ok) / kTargets;
  std::cout << m.name() << ": position only, " << ok << "/" << kTargets << " solved (" << 100 * rate
            << "%)\n";
  EXPECT_EQ(false_claims, 0);
  EXPECT_GE(rate, 0.995);
}

TEST_P(IkRoundTrip, UnreachableTargetsFailClearly) {
  const KinematicModel m = ModelFor(GetParam());
  std::mt19937 rng(300 + GetParam());
  const Eigen::VectorXd x = RandomErrors(m, rng);
  LevenbergMarquardtIk ik(m, x);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int t = 0; t < 50; ++t) {
    // 5 m from a point the arm reaches; every test arm reaches less than 1.5 m from its base.
    const Eigen::Vector3d dir = sim::Draw3(n, rng).normalized();
    Eigen::Isometry3d T_WT = Eigen::Isometry3d::Identity();
    T_WT.translation() =
        m.ToolFrame(Eigen::VectorXd::Zero(m.num_joints()), x).translation() + 5.0 * dir;
    T_WT.linear() = geometry::Exp(sim::Draw3(n, rng));
    const Eigen::VectorXd seed = RandomJoints(m, rng);
    for (const IkResult& res : {ik.Solve(T_WT, seed), ik.SolvePosition(T_WT.translation(), seed)}) {
      EXPECT_FALSE(res.converged);
      EXPECT_TRUE(res.status == IkStatus::kStalled || res.status == IkStatus::kMaxIterations)
          << ToString(res.status);
      EXPECT_FALSE(res.reason.empty());
      EXPECT_GT(res.position_error, 2.0);
      EXPECT_TRUE(m.WithinLimits(res.q));
      EXPECT_LE(res.iterations, ik.settings().max_iterations);
      // The reported error is the true one at the returned joints.
      EXPECT_NEAR(res.position_error,
                  (m.ToolFrame(res.q, x).translation() - T_WT.translation()).norm(), 1e-9);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Robots, IkRoundTrip, ::testing::Values(0, 1, 2));

TEST(Ik, TargetBeyondJointLimitsFailsAndNamesTheJoint) {
  // GRB3016 with joint 1 limited to ±0.5 rad; the target was made with q1 = 2 rad. The wrist centre
  // must then lie at an azimuth no other joint can provide.
  kinematics::ModelBuilder b("grb_limited");
  b.DhLink(0.150, -kPi / 2, 0.250, 0.0, Rev("j1", 0.5))
      .DhLink(0.570, -kPi, 0.0, -kPi / 2, Rev("j2"))
      .DhLink(0.150, kPi / 2, 0.0, 0.0, Rev("j3"))
      .DhLink(0.0, -kPi / 2, 0.645, 0.0, Rev("j4"))
      .DhLink(0.0, kPi / 2, 0.0, -kPi / 2, Rev("j5"))
      .DhLink(0.0, 0.0, -0.200, 0.0, Rev("j6"));
  const KinematicModel m = b.Build();
  LevenbergMarquardtIk ik(m, m.Nominal());
  Eigen::VectorXd q_target(6);
  q_target << 2.0, 0.3, -0.4, 0.5, 0.8, 0.1;
  Eigen::VectorXd unlimited_ok = q_target;
  const Eigen::Isometry3d T_WT = m.ToolFrame(q_target, m.Nominal());
  Eigen::VectorXd seed(6);
  seed << 0.4, 0.3, -0.4, 0.5, 0.8, 0.1;
  const IkResult res = ik.Solve(T_WT, seed);
  EXPECT_FALSE(res.converged);
  EXPECT_TRUE(m.WithinLimits(res.q));
  EXPECT_NE(res.reason.find("j1"), std::string::npos) << res.reason;
  // The same target without the limit is solved: it is the limit that stops it.
  ik.settings().respect_joint_limits = false;
  const IkResult free = ik.Solve(T_WT, seed);
  EXPECT_TRUE(free.converged) << free.reason;
}

TEST(Ik, SeedAtSolutionConvergesInZeroIterations) {
  const KinematicModel m = Grb3016();
  std::mt19937 rng(7);
  const Eigen::VectorXd x = RandomErrors(m, rng);
  LevenbergMarquardtIk ik(m, x);
  const Eigen::VectorXd q = RandomJoints(m, rng);
  const IkResult res = ik.Solve(m.ToolFrame(q, x), q);
  EXPECT_TRUE(res.converged);
  EXPECT_EQ(res.iterations, 0);
  EXPECT_EQ(res.q, q);
}

TEST(Ik, SetParametersSolvesTheRecalibratedModel) {
  const KinematicModel m = UrLikeUrdf();
  std::mt19937 rng(8);
  const Eigen::VectorXd x = RandomErrors(m, rng, 0.01, 0.03);
  LevenbergMarquardtIk ik(m, m.Nominal());
  const Eigen::VectorXd q = RandomJoints(m, rng);
  const Eigen::Isometry3d T_WT = m.ToolFrame(q, x);
  ik.SetParameters(x);
  const IkResult res = ik.Solve(T_WT, NearbySeed(m, q, 0.1, rng));
  ASSERT_TRUE(res.converged) << res.reason;
  EXPECT_LT((m.ToolFrame(res.q, x).translation() - T_WT.translation()).norm(), 1e-9);
  // The nominal model at the same joints misses the target by the calibration's size.
  EXPECT_GT((m.ToolFrame(res.q, m.Nominal()).translation() - T_WT.translation()).norm(), 1e-4);
}

TEST(Ik, InvalidInputIsRejectedWithAReason) {
  const KinematicModel m = Grb3016();
  LevenbergMarquardtIk ik(m, m.Nominal());
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(6, 0.1);
  Eigen::Isometry3d T = m.ToolFrame(q, m.Nominal());

  IkResult res = ik.Solve(T, Eigen::VectorXd::Zero(5));
  EXPECT_EQ(res.status, IkStatus::kInvalidInput);
  EXPECT_NE(res.reason.find("seed has 5 joints"), std::string::npos) << res.reason;

  Eigen::VectorXd bad_seed = q;
  bad_seed(2) = std::nan("");
  res = ik.Solve(T, bad_seed);
  EXPECT_EQ(res.status, IkStatus::kInvalidInput);
  EXPECT_FALSE(res.reason.empty());

  Eigen::Isometry3d T_nan = T;
  T_nan.translation().x() = std::nan("");
  res = ik.Solve(T_nan, q);
  EXPECT_EQ(res.status, IkStatus::kInvalidInput);
  EXPECT_NE(res.reason.find("NaN"), std::string::npos);

  Eigen::Isometry3d T_skew = T;
  T_skew.linear()(0, 1) += 0.1;
  res = ik.Solve(T_skew, q);
  EXPECT_EQ(res.status, IkStatus::kInvalidInput);
  EXPECT_NE(res.reason.find("orthonormal"), std::string::npos);
  EXPECT_FALSE(res.converged);
}

}  // namespace
}  // namespace rcal::ik
