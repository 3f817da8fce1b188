// IK on an extended model. Truth is independent of the solver: targets come from
// ExtendedModel::ToolFrame (the truth robot with hidden effects) at random joints and contexts,
// and every solution is checked by that same truth model; the geometric IK on the same targets
// shows what ignoring the effects costs.
#include "rcal/ik/extended_ik.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "../kinematics/test_robots.hpp"
#include "rcal/geometry/so3.hpp"

namespace rcal::ik {
namespace {

using kinematics::Effect;
using kinematics::EffectCause;
using kinematics::EffectContext;
using kinematics::ExtendedModel;
using namespace kinematics::testing;

struct Truth {
  std::string name;
  std::vector<Effect> effects;
  std::vector<double> values;
};

EffectContext RandomContext(int n, std::mt19937& rng) {
  std::uniform_real_distribution<double> temp(18.0, 35.0), pay(0.0, 10.0);
  std::bernoulli_distribution b(0.5);
  EffectContext c;
  c.temperature_c = temp(rng);
  c.payload_kg = pay(rng);
  c.time_s = 1000.0;
  c.dq_sign.resize(n);
  for (int j = 0; j < n; ++j) c.dq_sign(j) = b(rng) ? 1 : -1;
  return c;
}

Eigen::VectorXd Vec(const std::vector<double>& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), v.size());
}

const std::vector<Truth> kTruths = {
    {"compliance + periodic",
     {{EffectCause::kJointCompliance, 1}, {EffectCause::kJointPeriodic, 2, 1}},
     {5e-6, 2e-4, -1e-4}},
    {"backlash + scale + periodic h2",
     {{EffectCause::kBacklash, 1},
      {EffectCause::kJointScale, 2},
      {EffectCause::kJointPeriodic, 4, 2}},
     {2e-4, 3e-4, 1e-4, 1e-4}},
    {"thermal + compliance",
     {{EffectCause::kThermal}, {EffectCause::kJointCompliance, 2}},
     {2e-5, 4e-6}},
};

TEST(ExtendedIk, ReachesTheTargetUnderTheTruthModelWhereGeometricIkMissesByTheEffect) {
  const auto model = UrLikeUrdf();
  std::mt19937 rng(42);
  const Eigen::VectorXd x = RandomErrors(model, rng, 1e-3, 1e-3);
  for (const Truth& t : kTruths) {
    const ExtendedModel ext(model, t.effects);
    const Eigen::VectorXd e = Vec(t.values);
    ExtendedIk ik(ext, x, e);
    LevenbergMarquardtIk geometric(model, x);
    std::uniform_real_distribution<double> u(-0.05, 0.05);
    double worst_p = 0, worst_o = 0, min_ratio = 1e9, mean_miss = 0, mean_effect = 0;
    int out_of_reach = 0;
    const int targets = 200;
    for (int k = 0; k < targets; ++k) {
      Eigen::VectorXd q_true = RandomJoints(model, rng) * 0.9;
      const EffectContext ctx = RandomContext(model.num_joints(), rng);
      const Eigen::Isometry3d T = ext.ToolFrame(q_true, ctx, x, e);
      Eigen::VectorXd seed = q_true;
      for (int j = 0; j < seed.size(); ++j) seed(j) += u(rng);
      const IkResult res = ik.Solve(T, seed, ctx);
      ASSERT_TRUE(res.converged) << t.name << ": " << res.reason;
      const Eigen::Isometry3d T_reached = ext.ToolFrame(res.q, ctx, x, e);
      worst_p = std::max(worst_p, (T_reached.translation() - T.translation()).norm());
      worst_o =
          std::max(worst_o, geometry::Log(T.linear() * T_reached.linear().transpose()).norm());
      // The geometric IK solves its own model exactly (or, for a grown arm stretched out, finds
      // the target out of its reach), and misses under the truth by about the displacement the
      // effects cause at that pose.
      const IkResult g = geometric.Solve(T, seed);
      ASSERT_TRUE(g.converged || g.status == IkStatus::kStalled) << g.reason;
      out_of_reach += !g.converged;
      const double miss = (ext.ToolFrame(g.q, ctx, x, e).translation() - T.translation()).norm();
      const double effect =
          (T.translation() - model.ToolFrame(q_true, x).translation()).norm();  // effect's size
      min_ratio = std::min(min_ratio, miss / effect);
      mean_miss += miss / targets;
      mean_effect += effect / targets;
    }
    std::printf(
        "%s: extended IK worst %.2e m, %.2e rad; geometric IK misses by %.4f mm on average "
        "(effect %.4f mm), min miss/effect %.3f; %d targets beyond the geometric model's reach\n",
        t.name.c_str(), worst_p, worst_o, mean_miss * 1e3, mean_effect * 1e3, min_ratio,
        out_of_reach);
    EXPECT_LT(worst_p, 1e-9) << t.name;
    EXPECT_LT(worst_o, 1e-9) << t.name;
    EXPECT_GT(mean_miss, 1e-4) << t.name;  // the effects move the tool by a tenth of a mm or more
    EXPECT_GT(min_ratio, 0.5) << t.name;
    EXPECT_LT(mean_miss, 2.0 * mean_effect) << t.name;
    EXPECT_LE(out_of_reach, targets / 20) << t.name;
  }
}

TEST(ExtendedIk, PositionOnlyReachesThePoint) {
  const auto model = UrLikeUrdf();
  std::mt19937 rng(43);
  const Eigen::VectorXd x = RandomErrors(model, rng, 1e-3, 1e-3);
  const Truth& t = kTruths[2];
  const ExtendedModel ext(model, t.effects);
  ExtendedIk ik(ext, x, Vec(t.values));
  for (int k = 0; k < 50; ++k) {
    const Eigen::VectorXd q_true = RandomJoints(model, rng) * 0.9;
    const EffectContext ctx = RandomContext(model.num_joints(), rng);
    const Eigen::Vector3d p = ext.ToolFrame(q_true, ctx, x, Vec(t.values)).translation();
    const IkResult res = ik.SolvePosition(p, q_true, ctx);
    ASSERT_TRUE(res.converged) << res.reason;
    EXPECT_EQ(res.orientation_error, 0.0);
    EXPECT_LT((ext.ToolFrame(res.q, ctx, x, Vec(t.values)).translation() - p).norm(), 1e-9);
  }
}

TEST(ExtendedIk, WithoutEffectsItIsTheGeometricIk) {
  const auto model = UrLikeUrdf();
  std::mt19937 rng(44);
  const Eigen::VectorXd x = RandomErrors(model, rng, 1e-3, 1e-3);
  const ExtendedModel ext(model, kTruths[0].effects);
  ExtendedIk ik(ext, x, ext.NoEffects());
  LevenbergMarquardtIk geometric(model, x);
  for (int k = 0; k < 20; ++k) {
    const Eigen::VectorXd q = RandomJoints(model, rng) * 0.9;
    const Eigen::Isometry3d T = model.ToolFrame(q, x);
    const EffectContext ctx = RandomContext(model.num_joints(), rng);
    const IkResult a = ik.Solve(T, q + Eigen::VectorXd::Constant(q.size(), 0.02), ctx);
    const IkResult b = geometric.Solve(T, q + Eigen::VectorXd::Constant(q.size(), 0.02));
    ASSERT_TRUE(a.converged);
    EXPECT_LT((a.q - b.q).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(ExtendedIk, BadInputIsRefusedNamingTheField) {
  const auto model = UrLikeUrdf();
  const ExtendedModel ext(model, kTruths[0].effects);
  const Eigen::VectorXd x = model.Nominal();
  try {
    ExtendedIk bad(ext, x, Eigen::VectorXd::Zero(2));
    FAIL() << "no exception";
  } catch (const std::invalid_argument& err) {
    EXPECT_NE(std::string(err.what()).find("e:"), std::string::npos) << err.what();
  }
  ExtendedIk ik(ext, x, ext.NoEffects());
  EXPECT_THROW(ik.SetParameters(Eigen::VectorXd::Zero(3), ext.NoEffects()), std::invalid_argument);
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(6, 0.3);
  const Eigen::Isometry3d T = model.ToolFrame(q, x);
  EffectContext ctx;
  ctx.dq_sign = Eigen::VectorXi::Ones(4);
  IkResult r = ik.Solve(T, q, ctx);
  EXPECT_EQ(r.status, IkStatus::kInvalidInput);
  EXPECT_NE(r.reason.find("dq_sign"), std::string::npos) << r.reason;
  r = ik.Solve(T, Eigen::VectorXd::Zero(5), {});
  EXPECT_EQ(r.status, IkStatus::kInvalidInput);
  EXPECT_NE(r.reason.find("seed"), std::string::npos) << r.reason;
}

}  // namespace
}  // namespace rcal::ik
