// The extended pose measurement (identification/extended_measurement.hpp): the residual against
// measurements built by hand (a known position offset and a known rotation vector), the joint
// effects against the geometric model at the joints they should produce (closed forms of
// joint_scale, backlash, joint_periodic), H against central finite differences for position-only
// and full-pose measurements away from r = 0, and ValidateContext naming the field.
#include "rcal/identification/extended_measurement.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <random>

#include "../kinematics/test_robots.hpp"

namespace rcal::identification {
namespace {

using kinematics::Effect;
using kinematics::EffectCause;
using kinematics::EffectContext;
using kinematics::ExtendedModel;
using kinematics::PoseMeasurement;

PoseMeasurement At(const Eigen::VectorXd& q, const kinematics::ToolPose& pose, bool orientation) {
  PoseMeasurement z;
  z.q = q;
  z.p_WM_W = pose.p_WM_W;
  z.R_EI = pose.R_EI;
  z.has_orientation = orientation;
  z.covariance = Eigen::MatrixXd::Identity(z.dimension(), z.dimension());
  return z;
}

TEST(ExtendedMeasurement, ResidualIsTheMeasuredOffsetAndRotationVector) {
  const auto model = kinematics::testing::UrLikeUrdf();
  const ExtendedModel ext(model, {{EffectCause::kJointScale, 1}});
  std::mt19937 rng(1);
  const Eigen::VectorXd x = kinematics::testing::RandomErrors(model, rng, 1e-3, 1e-3);
  Eigen::VectorXd e(1);
  e << 2e-3;
  const EffectContext ctx;
  const Eigen::VectorXd q = kinematics::testing::RandomJoints(model, rng);
  const kinematics::ToolPose pose = ext.Forward(q, ctx, x, e);
  const Eigen::Vector3d dp(1e-3, -2e-3, 0.5e-3), dtheta(0.02, -0.01, 0.03);
  PoseMeasurement z = At(q, pose, true);
  z.p_WM_W += dp;
  z.R_EI = Eigen::AngleAxisd(dtheta.norm(), dtheta.normalized()).toRotationMatrix() * pose.R_EI;
  Eigen::VectorXd r;
  ExtendedResidualAndJacobian(ext, z, ctx, x, e, {}, r, nullptr);
  ASSERT_EQ(r.size(), 6);
  EXPECT_LT((r.head<3>() - dp).norm(), 1e-12);
  EXPECT_LT((r.tail<3>() - dtheta).norm(), 1e-12);
  // Position only: the first three rows alone; H has no columns when nothing is identified and
  // the model has no effects.
  z.has_orientation = false;
  Eigen::MatrixXd H;
  ExtendedResidualAndJacobian(ext, z, ctx, x, e, {}, r, &H);
  ASSERT_EQ(r.size(), 3);
  EXPECT_LT((r - dp).norm(), 1e-12);
  EXPECT_EQ(H.rows(), 3);
  EXPECT_EQ(H.cols(), 1);
  const ExtendedModel plain(model, {});
  ExtendedResidualAndJacobian(plain, z, ctx, x, plain.NoEffects(), {}, r, &H);
  EXPECT_EQ(H.cols(), 0);
}

TEST(ExtendedMeasurement, JointEffectsMoveTheJointsAsTheirClosedForms) {
  // The pose of the extended model is the geometric pose at q̃: each effect's q̃ by hand.
  const auto model = kinematics::testing::UrLikeUrdf();
  const ExtendedModel ext(model, {{EffectCause::kJointScale, 1},
                                  {EffectCause::kBacklash, 2},
                                  {EffectCause::kJointPeriodic, 4, 2}});
  ASSERT_EQ(ext.num_effect_params(), 4);
  std::mt19937 rng(2);
  const Eigen::VectorXd x = kinematics::testing::RandomErrors(model, rng, 1e-3, 1e-3);
  Eigen::VectorXd e(4);
  const double s = 3e-3, b = 1.5e-3, a2 = 2e-3, c2 = -1e-3;
  e << s, b, a2, c2;
  EffectContext ctx;
  ctx.dq_sign = Eigen::VectorXi::Zero(6);
  for (int k = 0; k < 10; ++k) {
    const Eigen::VectorXd q = kinematics::testing::RandomJoints(model, rng);
    ctx.dq_sign(2) = k % 3 - 1;
    Eigen::VectorXd q_eff = q;
    q_eff(1) += s * q(1);
    q_eff(2) += b * ctx.dq_sign(2);
    q_eff(4) += a2 * std::sin(2 * q(4)) + c2 * std::cos(2 * q(4));
    const PoseMeasurement z = At(q, model.Forward(q_eff, x), true);
    Eigen::VectorXd r;
    ExtendedResidualAndJacobian(ext, z, ctx, x, e, {}, r, nullptr);
    EXPECT_LT(r.norm(), 1e-12) << "pose " << k;
    // And the geometric model at the joints as read is off by what the effects move.
    ExtendedResidualAndJacobian(ext, z, ctx, x, ext.NoEffects(), {}, r, nullptr);
    EXPECT_GT(r.head<3>().norm(), 1e-5) << "pose " << k;
  }
}

TEST(ExtendedMeasurement, WithoutEffectsItIsTheGeometricMeasurement) {
  const auto model = kinematics::testing::SevenJointSetup();
  const ExtendedModel ext(model, {});
  std::mt19937 rng(3);
  const Eigen::VectorXd x = kinematics::testing::RandomErrors(model, rng, 1e-3, 1e-3);
  const std::vector<int> identified = {0, 2, 5, 9, 14};
  for (bool orientation : {false, true}) {
    const Eigen::VectorXd q = kinematics::testing::RandomJoints(model, rng);
    PoseMeasurement z =
        At(q, model.Forward(q, Eigen::VectorXd::Zero(model.num_params())), orientation);
    Eigen::VectorXd r, r_geo;
    Eigen::MatrixXd H, H_geo;
    ExtendedResidualAndJacobian(ext, z, {}, x, ext.NoEffects(), identified, r, &H);
    kinematics::ResidualAndJacobian(model, z, x, identified, r_geo, H_geo);
    EXPECT_LT((r - r_geo).norm(), 1e-12);
    EXPECT_LT((H - H_geo).norm(), 1e-12);
  }
}

TEST(ExtendedMeasurement, JacobianMatchesCentralDifferencesAwayFromTheSolution) {
  // Every cause, position-only and full pose, residuals not zero. The position rows are exact
  // derivatives of r; the orientation rows are −∂Log(R_meas R(θ)ᵀ)/∂θ only at r = 0, so away
  // from it they agree to the order of the residual (3 mrad here).
  const auto model = kinematics::testing::UrLikeUrdf();
  Effect thermal{EffectCause::kThermal};
  thermal.reference = 20.0;
  const ExtendedModel ext(model, {{EffectCause::kJointCompliance, 1},
                                  {EffectCause::kJointPeriodic, 2, 1},
                                  {EffectCause::kJointScale, 3},
                                  {EffectCause::kBacklash, 0},
                                  thermal});
  std::mt19937 rng(4);
  const Eigen::VectorXd x = kinematics::testing::RandomErrors(model, rng, 1e-3, 1e-3);
  Eigen::VectorXd e(ext.num_effect_params());
  e << 2e-6, 1e-3, -2e-3, 4e-4, 8e-4, 1e-5;
  EffectContext ctx;
  ctx.temperature_c = 31.0;
  ctx.payload_kg = 2.0;
  ctx.dq_sign = Eigen::VectorXi::Ones(6);
  ctx.dq_sign(0) = -1;
  const std::vector<int> identified = {1, 4, 8, 13, 21};
  const int ng = identified.size();
  for (bool orientation : {false, true}) {
    const Eigen::VectorXd q = kinematics::testing::RandomJoints(model, rng);
    PoseMeasurement z = At(q, ext.Forward(q, ctx, x, e), orientation);
    z.p_WM_W += Eigen::Vector3d(2e-3, -1e-3, 3e-3);
    z.R_EI = Eigen::AngleAxisd(3e-3, Eigen::Vector3d(1, 2, -1).normalized()) * z.R_EI;
    Eigen::VectorXd r;
    Eigen::MatrixXd H;
    ExtendedResidualAndJacobian(ext, z, ctx, x, e, identified, r, &H);
    ASSERT_EQ(H.rows(), z.dimension());
    ASSERT_EQ(H.cols(), ng + ext.num_effect_params());
    for (int c = 0; c < H.cols(); ++c) {
      const bool geo = c < ng;
      const double h = geo ? 1e-6 : 1e-3 * std::abs(e(c - ng));
      Eigen::VectorXd xp = x, xm = x, ep = e, em = e, rp, rm;
      if (geo) {
        xp(identified[c]) += h;
        xm(identified[c]) -= h;
      } else {
        ep(c - ng) += h;
        em(c - ng) -= h;
      }
      ExtendedResidualAndJacobian(ext, z, ctx, xp, ep, identified, rp, nullptr);
      ExtendedResidualAndJacobian(ext, z, ctx, xm, em, identified, rm, nullptr);
      const Eigen::VectorXd fd = -(rp - rm) / (2 * h);
      const double scale = std::max(1e-3, fd.norm());
      EXPECT_LT((fd.head<3>() - H.col(c).head<3>()).norm(), 1e-6 * scale)
          << "column " << c << (orientation ? " (full pose)" : " (position)");
      if (orientation) {
        EXPECT_LT((fd.tail<3>() - H.col(c).tail<3>()).norm(), 1e-2 * scale + 1e-9) << c;
      }
    }
  }
}

TEST(ExtendedMeasurement, ValidateContextNamesTheField) {
  const ExtendedModel ext(kinematics::testing::UrLikeUrdf(), {{EffectCause::kBacklash, 1}});
  EffectContext ok;
  EXPECT_EQ(ValidateContext(ext, ok), "");
  ok.dq_sign = Eigen::VectorXi::Zero(6);
  ok.dq_sign(3) = -1;
  ok.temperature_c = 25.0;
  ok.time_s = 10.0;
  ok.payload_kg = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(ValidateContext(ext, ok), "");
  const auto reason = [&](auto change) {
    EffectContext c;
    change(c);
    return ValidateContext(ext, c);
  };
  EXPECT_EQ(reason([](EffectContext& c) { c.dq_sign = Eigen::VectorXi::Zero(5); }),
            "dq_sign: 5 values, expected 6 (or none)");
  EXPECT_EQ(reason([](EffectContext& c) {
              c.dq_sign = Eigen::VectorXi::Zero(6);
              c.dq_sign(2) = 2;
            }),
            "dq_sign: value 2 of joint 3 is not -1, 0 or +1");
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(reason([&](EffectContext& c) { c.temperature_c = -inf; }), "temperature_c: infinite");
  EXPECT_EQ(reason([&](EffectContext& c) { c.time_s = inf; }), "time_s: infinite");
  EXPECT_EQ(reason([](EffectContext& c) { c.payload_kg = -0.1; }),
            "payload_kg: negative or infinite");
  EXPECT_EQ(reason([&](EffectContext& c) { c.payload_kg = inf; }),
            "payload_kg: negative or infinite");
}

}  // namespace
}  // namespace rcal::identification
