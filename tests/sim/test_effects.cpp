// Truth effects: parsing, and the effected robot against the geometric model evaluated at joints
// (or lengths) changed by hand.
#include "rcal/sim/effects.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "../kinematics/test_robots.hpp"

namespace rcal::sim {
namespace {

using kinematics::EffectCause;

PoseNoise Exact() {
  PoseNoise n;
  n.position_sigma = 0.0;
  n.orientation_sigma = 0.0;
  return n;
}

TEST(SimEffects, ParsesTheCommandLineSyntax) {
  const auto m = kinematics::testing::UrLikeUrdf();
  auto t = ParseEffectSpec("joint_compliance:j2=2e-6", m);
  EXPECT_EQ(t.effect.cause, EffectCause::kJointCompliance);
  EXPECT_EQ(t.effect.joint, 1);
  EXPECT_DOUBLE_EQ(t.values(0), 2e-6);
  t = ParseEffectSpec("joint_periodic:elbow:h2=1e-4,-5e-5", m);
  EXPECT_EQ(t.effect.joint, 2);
  EXPECT_EQ(t.effect.harmonic, 2);
  EXPECT_DOUBLE_EQ(t.values(1), -5e-5);
  t = ParseEffectSpec("joint_periodic:j1=1e-4", m);
  EXPECT_EQ(t.effect.harmonic, 1);
  EXPECT_DOUBLE_EQ(t.values(1), 0.0);
  t = ParseEffectSpec("thermal:time=3e-9", m);
  EXPECT_EQ(t.effect.thermal_source, kinematics::Effect::ThermalSource::kTime);
  for (const char* bad :
       {"joint_scale=1e-4", "joint_scale:j7=1e-4", "joint_scale:j2=abc", "time_offset=0.01",
        "compliance:j2=1", "joint_scale:j2=1,2", "backlash:j2"})
    EXPECT_THROW(ParseEffectSpec(bad, m), std::invalid_argument) << bad;
}

TEST(SimEffects, ParsesAnOffsetStepAndNamesWhatIsWrong) {
  const auto m = kinematics::testing::UrLikeUrdf();
  auto s = ParseJointOffsetStep("j2=1e-3@25", m);
  EXPECT_EQ(s.joint, 1);
  EXPECT_DOUBLE_EQ(s.delta, 1e-3);
  EXPECT_EQ(s.stop, 25);
  s = ParseJointOffsetStep("elbow=-5e-4@1", m);
  EXPECT_EQ(s.joint, 2);
  EXPECT_DOUBLE_EQ(s.delta, -5e-4);
  const std::pair<const char*, const char*> bad[] = {
      {"j2=1e-3", "JOINT=DELTA@STOP"}, {"j9=1e-3@3", "no joint 'j9'"},
      {"j2=abc@3", "DELTA 'abc'"},     {"j2=0.5@3", "beyond 0.1"},
      {"j2=nan@3", "beyond 0.1"},      {"j2=1e-3@0", "STOP must be"},
      {"j2=1e-3@x", "STOP 'x'"},       {"j2@3=1e-3", "JOINT=DELTA@STOP"}};
  for (const auto& [text, why] : bad) {
    try {
      ParseJointOffsetStep(text, m);
      ADD_FAILURE() << text << " was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
    }
  }
}

TEST(SimEffects, JointEffectsMoveTheJointsByHand) {
  const auto m = kinematics::testing::UrLikeUrdf();
  Rng rng(11);
  const Eigen::VectorXd x = RandomErrors(m, rng, 1e-3, 1e-3);
  const auto qs = SampleJoints(m, 10, rng);
  const auto ctxs = SampleSession(m.num_joints(), 10, {}, rng);
  const EffectTruth truth = MakeEffectTruth(
      m, {ParseEffectSpec("joint_scale:j3=2e-3", m), ParseEffectSpec("backlash:j2=1e-3", m),
          ParseEffectSpec("joint_periodic:j4=1e-3,2e-3", m)});
  for (size_t i = 0; i < qs.size(); ++i) {
    Eigen::VectorXd q = qs[i];
    q(2) *= 1 + 2e-3;
    q(1) += 1e-3 * ctxs[i].dq_sign(1);
    q(3) += 1e-3 * std::sin(qs[i](3)) + 2e-3 * std::cos(qs[i](3));
    const auto meas = MeasurePoseWithEffects(truth, x, qs[i], ctxs[i], Exact(), rng);
    const auto ref = m.Forward(q, x);
    EXPECT_LT((meas.p_WM_W - ref.p_WM_W).norm(), 1e-12);
    EXPECT_LT((meas.R_EI - ref.R_EI).norm(), 1e-12);
  }
}

TEST(SimEffects, ThermalGrowsTheArm) {
  const auto m = kinematics::testing::Grb3016();  // no set-up frames: the whole chain grows
  Rng rng(12);
  const EffectTruth truth = MakeEffectTruth(m, {ParseEffectSpec("thermal=1e-5", m)});
  kinematics::EffectContext ctx;
  ctx.temperature_c = 35.0;
  const Eigen::VectorXd q = SampleJoints(m, 1, rng)[0];
  const auto meas = MeasurePoseWithEffects(truth, m.Nominal(), q, ctx, Exact(), rng);
  EXPECT_LT((meas.p_WM_W - (1 + 15e-5) * m.Forward(q, m.Nominal()).p_WM_W).norm(), 1e-12);
}

TEST(SimEffects, ComplianceDeflectsWithGravityTorqueAndPayload) {
  const auto m = kinematics::testing::UrLikeUrdf();
  Rng rng(13);
  const EffectTruth truth = MakeEffectTruth(m, {ParseEffectSpec("joint_compliance:j2=5e-6", m)});
  Eigen::VectorXd q = Eigen::VectorXd::Zero(6);
  q(1) = -1.2;  // shoulder lift: arm out, large torque
  kinematics::EffectContext light, heavy;
  heavy.payload_kg = 10.0;
  const double t0 = truth.model.GravityTorque(q, 0)(1), t1 = truth.model.GravityTorque(q, 10)(1);
  EXPECT_GT(std::abs(t1), std::abs(t0));
  // Hand-made: a 10 kg load at the end of the chain adds m g × lever arm about joint 2's axis.
  EXPECT_GT(std::abs(t1 - t0), 10.0 * 9.81 * 0.5);
  for (const auto& [ctx, tau] : {std::pair{light, t0}, std::pair{heavy, t1}}) {
    Eigen::VectorXd qd = q;
    qd(1) += 5e-6 * tau;
    const auto meas = MeasurePoseWithEffects(truth, m.Nominal(), q, ctx, Exact(), rng);
    EXPECT_LT((meas.p_WM_W - m.Forward(qd, m.Nominal()).p_WM_W).norm(), 1e-12);
  }
}

TEST(SimEffects, SessionContexts) {
  Rng rng(14);
  SessionSettings s;
  const auto c = SampleSession(6, 50, s, rng);
  ASSERT_EQ(c.size(), 50u);
  EXPECT_DOUBLE_EQ(c.front().time_s, 0.0);
  EXPECT_DOUBLE_EQ(c.back().time_s, s.session_s);
  int neg = 0;
  for (const auto& k : c) {
    EXPECT_GT(k.temperature_c, 18.0);
    EXPECT_LT(k.temperature_c, 34.0);
    neg += (k.dq_sign.array() < 0).count();
    EXPECT_TRUE(k.payload_kg == 0.0 || k.payload_kg == 5.0 || k.payload_kg == 10.0);
  }
  EXPECT_GT(neg, 100);
  EXPECT_LT(neg, 200);
  EXPECT_GT(c.back().temperature_c - c.front().temperature_c, 8.0);
}

// A live stop's context: the approach direction is the sign of the motion from the stop before
// (0 for a joint that did not move, none known at the first stop), time as given, the
// temperature on the warm-up curve within its noise, a payload of the list; every call draws the
// same numbers, so a resumed run that replays its stops continues the same sequence.
TEST(SimEffects, StopContextOfALiveCell) {
  SessionSettings s;
  Rng a(3), b(3);
  Eigen::VectorXd q0(3), q1(3);
  q0 << 0.1, 0.2, 0.3;
  q1 << 0.3, 0.2, -0.1;
  const auto first = StopContext(0.0, q0, {}, s, a);
  EXPECT_EQ(first.dq_sign, Eigen::VectorXi::Zero(3));
  const auto second = StopContext(1200.0, q1, q0, s, a);
  EXPECT_EQ(second.dq_sign, Eigen::Vector3i(1, 0, -1));
  EXPECT_EQ(second.time_s, 1200.0);
  const double warm = s.temperature_start_c +
                      s.temperature_rise_c * (1.0 - std::exp(-1200.0 / s.warmup_time_constant_s));
  EXPECT_NEAR(second.temperature_c, warm, 5 * s.temperature_noise_c);
  EXPECT_TRUE(second.payload_kg == 0.0 || second.payload_kg == 5.0 || second.payload_kg == 10.0);
  // The same draws whatever the joints: a fast-forward through the same stops stays in step.
  StopContext(0.0, q1, q0, s, b);
  const auto replayed = StopContext(1200.0, q1, q0, s, b);
  EXPECT_EQ(replayed.temperature_c, second.temperature_c);
  EXPECT_EQ(replayed.payload_kg, second.payload_kg);
  // Over many stops the payloads cover the list and the temperature follows the curve.
  int heavy = 0;
  double dev = 0;
  for (int k = 0; k < 300; ++k) {
    const auto c = StopContext(10.0 * k, q0, q1, s, a);
    heavy += c.payload_kg == 10.0;
    dev += c.temperature_c -
           (s.temperature_start_c +
            s.temperature_rise_c * (1.0 - std::exp(-10.0 * k / s.warmup_time_constant_s)));
  }
  EXPECT_GT(heavy, 60);
  EXPECT_LT(heavy, 140);
  EXPECT_NEAR(dev / 300, 0.0, 5 * s.temperature_noise_c / std::sqrt(300.0));
}

TEST(SimEffects, EffectOfSize) {
  const auto m = kinematics::testing::UrLikeUrdf();
  Rng rng(15);
  const Eigen::VectorXd x = RandomErrors(m, rng, 1e-3, 1e-3);
  const auto qs = SampleJoints(m, 40, rng);
  auto ctx = SampleSession(m.num_joints(), 40, {}, rng);
  const kinematics::Effect f{EffectCause::kJointPeriodic, 2, 1};
  const TruthEffect total = EffectOfSize(m, f, qs, ctx, x, 1e-4, rng);
  const TruthEffect visible = EffectOfSize(m, f, qs, ctx, x, 1e-4, rng, {}, true);
  // Total size: the RMS displacement of the marker, measured by the truth robot itself.
  const EffectTruth truth = MakeEffectTruth(m, {total});
  double ss = 0;
  for (size_t i = 0; i < qs.size(); ++i)
    ss += (truth.model.Forward(qs[i], ctx[i], x, truth.e).p_WM_W - m.Forward(qs[i], x).p_WM_W)
              .squaredNorm();
  EXPECT_NEAR(std::sqrt(ss / qs.size()), 1e-4, 1e-7);
  // Geometry absorbs part of it: the visible-size values are larger.
  EXPECT_GT(visible.values.norm(), total.values.norm());
  // Backlash with every approach from the same side is a constant joint offset: invisible.
  for (auto& c : ctx) c.dq_sign.setOnes();
  EXPECT_THROW(EffectOfSize(m, {EffectCause::kBacklash, 1}, qs, ctx, x, 1e-4, rng, {}, true),
               std::invalid_argument);
}

}  // namespace
}  // namespace rcal::sim
