// ExtendedModel: reduces to the geometric model without effects, analytic Jacobians against
// finite differences, gravity torque and thermal scaling against hand-computed values.
#include <gtest/gtest.h>

#include <random>

#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "test_robots.hpp"

namespace rcal::kinematics {
namespace {

using testing::kPi;

Eigen::VectorXd RandomVector(int n, std::mt19937_64& rng, double s) {
  std::normal_distribution<double> d(0.0, s);
  Eigen::VectorXd v(n);
  for (int i = 0; i < n; ++i) v(i) = d(rng);
  return v;
}

EffectContext SomeContext(int n) {
  EffectContext c;
  c.temperature_c = 31.5;
  c.time_s = 1800.0;
  c.payload_kg = 4.0;
  c.dq_sign = Eigen::VectorXi::Ones(n);
  for (int j = 0; j < n; j += 2) c.dq_sign(j) = -1;
  return c;
}

std::vector<Effect> AllEffects(int n) {
  std::vector<Effect> fx;
  for (int j = 0; j < n; ++j) {
    fx.push_back({EffectCause::kJointCompliance, j});
    fx.push_back({EffectCause::kJointPeriodic, j, 1});
    fx.push_back({EffectCause::kJointPeriodic, j, 2});
    fx.push_back({EffectCause::kJointScale, j});
    fx.push_back({EffectCause::kBacklash, j});
  }
  Effect t{EffectCause::kThermal};
  fx.push_back(t);
  t.thermal_source = Effect::ThermalSource::kTime;
  t.reference = 0.0;
  fx.push_back(t);
  return fx;
}

TEST(JointEffects, WithoutEffectsEqualsGeometricModel) {
  std::mt19937_64 rng(3);
  for (const KinematicModel& m :
       {testing::SevenJointSetup(), testing::UrLikeUrdf(), testing::Grb3016()}) {
    const ExtendedModel ext(m, {});
    for (int k = 0; k < 5; ++k) {
      const Eigen::VectorXd q = RandomVector(m.num_joints(), rng, 1.0);
      const Eigen::VectorXd x = RandomVector(m.num_params(), rng, 0.01);
      const ToolPose a = m.Forward(q, x);
      Eigen::MatrixXd Jx, Je, Jref(6, m.num_params());
      ToolPose b;
      ext.Jacobians(q, SomeContext(m.num_joints()), x, ext.NoEffects(), &Jx, &Je, &b);
      m.IdentificationJacobian(q, x, Jref);
      EXPECT_LT((a.p_WM_W - b.p_WM_W).norm(), 1e-12);
      EXPECT_LT((a.R_EI - b.R_EI).norm(), 1e-12);
      EXPECT_LT((Jx - Jref).norm(), 1e-10) << m.name();
      EXPECT_EQ(Je.cols(), 0);
    }
  }
}

// Pose difference in the Jacobian convention: [Δp ; Log(R_b R_aᵀ)].
Eigen::Matrix<double, 6, 1> Delta(const ToolPose& a, const ToolPose& b) {
  Eigen::Matrix<double, 6, 1> d;
  const Eigen::AngleAxisd aa(b.R_EI * a.R_EI.transpose());
  d << b.p_WM_W - a.p_WM_W, aa.angle() * aa.axis();
  return d;
}

TEST(JointEffects, JacobiansMatchFiniteDifferences) {
  std::mt19937_64 rng(5);
  for (const KinematicModel& m : {testing::SevenJointSetup(), testing::UrLikeUrdf()}) {
    const ExtendedModel ext(m, AllEffects(m.num_joints()));
    const EffectContext ctx = SomeContext(m.num_joints());
    for (int k = 0; k < 3; ++k) {
      const Eigen::VectorXd q = RandomVector(m.num_joints(), rng, 1.0);
      const Eigen::VectorXd x = RandomVector(m.num_params(), rng, 0.01);
      Eigen::VectorXd e = RandomVector(ext.num_effect_params(), rng, 1e-4);
      Eigen::MatrixXd Jx, Je;
      ext.Jacobians(q, ctx, x, e, &Jx, &Je);
      const double h = 1e-7;
      for (int i = 0; i < ext.num_effect_params(); ++i) {
        // Scale the step to the regressor: compliance multiplies torques of ~100 N·m.
        const double hi = h / std::max(1.0, Je.col(i).norm());
        Eigen::VectorXd ep = e, em = e;
        ep(i) += hi;
        em(i) -= hi;
        const Eigen::Matrix<double, 6, 1> fd =
            Delta(ext.Forward(q, ctx, x, em), ext.Forward(q, ctx, x, ep)) / (2 * hi);
        EXPECT_LT((fd - Je.col(i)).norm(), 1e-6 * std::max(1.0, fd.norm()))
            << m.name() << " " << ext.EffectParameters()[i].name;
      }
      for (int i = 0; i < m.num_params(); ++i) {
        Eigen::VectorXd xp = x, xm = x;
        xp(i) += h;
        xm(i) -= h;
        const Eigen::Matrix<double, 6, 1> fd =
            Delta(ext.Forward(q, ctx, xm, e), ext.Forward(q, ctx, xp, e)) / (2 * h);
        EXPECT_LT((fd - Jx.col(i)).norm(), 1e-6) << m.name() << " " << m.parameters()[i].name;
      }
    }
  }
}

TEST(JointEffects, EffectiveJointsPerCause) {
  const KinematicModel m = testing::Grb3016();
  const ExtendedModel ext(m, {{EffectCause::kJointPeriodic, 1, 2},
                              {EffectCause::kJointScale, 2},
                              {EffectCause::kBacklash, 3}});
  ASSERT_EQ(ext.num_effect_params(), 4);
  Eigen::VectorXd e(4);
  e << 1e-3, 2e-3, 5e-4, 3e-4;
  Eigen::VectorXd q(6);
  q << 0.1, 0.7, -1.2, 2.0, 0.3, -0.4;
  EffectContext ctx;
  ctx.dq_sign = Eigen::VectorXi::Zero(6);
  ctx.dq_sign(3) = -1;
  const Eigen::VectorXd qe = ext.EffectiveJoints(q, ctx, e);
  EXPECT_NEAR(qe(0), 0.1, 1e-15);
  EXPECT_NEAR(qe(1), 0.7 + 1e-3 * std::sin(1.4) + 2e-3 * std::cos(1.4), 1e-15);
  EXPECT_NEAR(qe(2), -1.2 * (1 + 5e-4), 1e-15);
  EXPECT_NEAR(qe(3), 2.0 - 3e-4, 1e-15);
  // The IK corrector's inverse.
  EXPECT_LT((ext.EffectiveJoints(ext.ReadJointsFor(q, ctx, e), ctx, e) - q).norm(), 1e-12);
  EXPECT_EQ(ext.EffectParameters()[0].name, "joint_periodic.j2.sin2");
  EXPECT_EQ(ext.EffectParameters()[3].unit, "rad");
}

TEST(JointEffects, GravityTorqueOfPlanarArmByHand) {
  // Two links in the base x–y plane, joint axes z, gravity along −y: a vertical-plane arm.
  ModelBuilder b("planar");
  b.DhLink(1.0, 0.0, 0.0, 0.0, testing::Rev("j1")).DhLink(0.5, 0.0, 0.0, 0.0, testing::Rev("j2"));
  GravityModel g;
  g.link_density_kg_per_m = 8.0;
  g.tool_mass_kg = 2.0;
  g.g_B = Eigen::Vector3d(0, -9.81, 0);
  const ExtendedModel ext(b.Build(), {{EffectCause::kJointCompliance, 1}}, g);
  const double payload = 3.0, mt = 2.0 + payload;
  const Eigen::VectorXd tau = ext.GravityTorque(Eigen::Vector2d(0, 0), payload);
  EXPECT_NEAR(tau(0), -9.81 * (8.0 * 0.5 + 4.0 * 1.25 + mt * 1.5), 1e-9);
  EXPECT_NEAR(tau(1), -9.81 * (4.0 * 0.25 + mt * 0.5), 1e-9);
  // Pointing straight down (q1 = −π/2): no torque.
  EXPECT_LT(ext.GravityTorque(Eigen::Vector2d(-kPi / 2, 0), payload).norm(), 1e-9);
  // Compliance: the joint gives way by c·τ.
  Eigen::VectorXd e(1);
  e << 1e-5;
  EffectContext ctx;
  ctx.payload_kg = payload;
  EXPECT_NEAR(ext.EffectiveJoints(Eigen::Vector2d(0, 0), ctx, e)(1), 1e-5 * tau(1), 1e-15);
  // The IK corrector's inverse, with a torque that depends on the joints themselves.
  const Eigen::Vector2d q_eff(0.3, -0.7);
  EXPECT_LT((ext.EffectiveJoints(ext.ReadJointsFor(q_eff, ctx, e), ctx, e) - q_eff).norm(), 1e-12);
}

TEST(JointEffects, ThermalScalesTheArm) {
  // No base frame: the whole chain is arm, so the tool position scales by 1 + κ (T − T_ref).
  const KinematicModel m = testing::Grb3016();
  const ExtendedModel ext(m, {{EffectCause::kThermal}});
  Eigen::VectorXd q(6);
  q << 0.3, -0.5, 0.8, 0.1, 0.9, -0.2;
  EffectContext ctx;
  ctx.temperature_c = 30.0;
  Eigen::VectorXd e(1);
  e << 1.2e-5;
  const Eigen::Vector3d p0 = m.Forward(q, m.Nominal()).p_WM_W;
  const ToolPose p = ext.Forward(q, ctx, m.Nominal(), e);
  EXPECT_LT((p.p_WM_W - (1 + 1.2e-4) * p0).norm(), 1e-12);
  EXPECT_LT((p.R_EI - m.Forward(q, m.Nominal()).R_EI).norm(), 1e-12);
  // The set-up frames do not grow.
  const KinematicModel s = testing::SevenJointSetup();
  const ExtendedModel es(s, {{EffectCause::kThermal}});
  ctx.temperature_c = 20.0;  // at the reference: no change
  EXPECT_LT((es.Forward(Eigen::VectorXd::Zero(7), ctx, s.Nominal(), e).p_WM_W -
             s.Forward(Eigen::VectorXd::Zero(7), s.Nominal()).p_WM_W)
                .norm(),
            1e-12);
}

TEST(JointEffects, RejectsBadEffects) {
  const KinematicModel m = testing::Grb3016();
  EXPECT_THROW(ExtendedModel(m, {{EffectCause::kJointScale, 6}}), std::invalid_argument);
  EXPECT_THROW(ExtendedModel(m, {{EffectCause::kJointPeriodic, 1, 3}}), std::invalid_argument);
  EXPECT_THROW(ExtendedModel(m, {{EffectCause::kBacklash, 1}, {EffectCause::kBacklash, 1}}),
               std::invalid_argument);
  EXPECT_EQ(ParseEffectCause("joint_compliance"), EffectCause::kJointCompliance);
  EXPECT_FALSE(ParseEffectCause("compliance").has_value());
}

}  // namespace
}  // namespace rcal::kinematics
