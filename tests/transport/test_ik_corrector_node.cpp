// IkCorrectorNode over memq://: answers on the nominal model until the first calibration, then on
// the calibrated one (checked against forward kinematics of the truth parameters), reports how
// far the nominal answer lands, and rejects bad parameters and requests without changing state.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "rcal/health_t.hpp"
#include "rcal/ik_command_t.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/ik_corrector_node.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal::transport {
namespace {

struct Fixture {
  kinematics::KinematicModel model =
      io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml").model;
  Eigen::VectorXd x_true = sim::Table3Errors(model);
  LcmTransport t{"memq://"};
  IkCorrectorNode node{t, model};
  std::vector<ik_command_t> commands;
  Fixture() {
    t.Subscribe<ik_command_t>(channels::kIkCommand,
                              [this](const ik_command_t& m) { commands.push_back(m); });
  }
  void Drain() {
    while (t.HandleTimeout(0) > 0) {
    }
  }
  ik_request_t Request(const Eigen::VectorXd& q_target, int64_t utime, int64_t id) {
    IkQuery query;
    query.request_id = id;
    query.T_WT = model.ToolFrame(q_target, x_true);  // where the real arm's tool is at q_target
    query.q_seed = q_target.array() + 0.05;
    return ToMessage(query, utime);
  }
  kinematic_params_t Params(int64_t utime) {
    std::vector<int> all(model.num_params());
    for (int i = 0; i < model.num_params(); ++i) all[i] = i;
    return ToKinematicParams(model, x_true, Eigen::VectorXd::Constant(model.num_params(), 1e-6),
                             all, model.name(), utime, 50);
  }
};

Eigen::VectorXd Q(const std::vector<double>& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<int>(v.size()));
}

TEST(IkCorrectorNode, AnnouncesItselfBeforeAnyMessage) {
  Fixture f;
  std::vector<health_t> beats;
  f.t.Subscribe<health_t>(channels::kHealth, [&](const health_t& h) { beats.push_back(h); });
  f.node.Announce();
  f.Drain();
  ASSERT_EQ(beats.size(), 1u);
  EXPECT_EQ(beats[0].utime, 0);
  EXPECT_EQ(beats[0].process, "ik_corrector");
  EXPECT_EQ(beats[0].received, 0);
}

TEST(IkCorrectorNode, NominalUntilCalibratedThenCalibratedAgainstTruth) {
  Fixture f;
  sim::Rng rng(7);
  const Eigen::VectorXd q_target = sim::SampleJoints(f.model, 1, rng)[0];
  const ik_request_t request = f.Request(q_target, 1'000'000, 1);
  const Eigen::Vector3d p_star = f.model.ToolFrame(q_target, f.x_true).translation();

  // Before any calibration: both answers on the nominal model, the same.
  f.t.Publish(channels::kIkRequest, request);
  f.Drain();
  ASSERT_EQ(f.commands.size(), 1u);
  const ik_command_t& c0 = f.commands[0];
  EXPECT_EQ(c0.request_id, 1);
  EXPECT_EQ(c0.params_utime, 0);
  ASSERT_TRUE(c0.converged) << c0.reason;
  EXPECT_EQ(Q(c0.q), Q(c0.q_nominal));
  const double nominal_miss = (f.model.ToolFrame(Q(c0.q), f.x_true).translation() - p_star).norm();
  EXPECT_GT(nominal_miss, 1e-4);  // Table 3 errors move the tool by more than 0.1 mm

  // After KINEMATIC_PARAMS with the truth: the calibrated answer reaches the target on the truth.
  f.t.Publish(channels::kKinematicParams, f.Params(2'000'000));
  f.t.Publish(channels::kIkRequest, f.Request(q_target, 2'100'000, 2));
  f.Drain();
  ASSERT_EQ(f.commands.size(), 2u);
  const ik_command_t& c1 = f.commands[1];
  EXPECT_EQ(c1.params_utime, 2'000'000);
  ASSERT_TRUE(c1.converged) << c1.reason;
  EXPECT_LT((f.model.ToolFrame(Q(c1.q), f.x_true).translation() - p_star).norm(), 1e-6);
  // The nominal answer is still the nominal model's, and its reported miss is the truth's.
  const double miss = (f.model.ToolFrame(Q(c1.q_nominal), f.x_true).translation() - p_star).norm();
  EXPECT_NEAR(c1.nominal_tool_error, miss, 1e-9);
  EXPECT_NEAR(c1.nominal_tool_error, nominal_miss, 1e-6);
  EXPECT_EQ(f.node.health().rejected(), 0);
}

TEST(IkCorrectorNode, BadParametersAndRequestsAreRejectedAndChangeNothing) {
  Fixture f;
  f.t.Publish(channels::kKinematicParams, f.Params(1'000'000));
  f.Drain();
  const Eigen::VectorXd x_before = f.node.x();
  ASSERT_EQ(x_before, f.x_true);

  auto nan = f.Params(1'100'000);
  nan.values[3] = NAN;
  f.t.Publish(channels::kKinematicParams, nan);
  auto other_model = f.Params(1'200'000);
  other_model.model_id = "another:0000000000000000";
  f.t.Publish(channels::kKinematicParams, other_model);
  auto short_params = f.Params(1'300'000);
  short_params.num_params -= 1;
  short_params.names.pop_back();
  short_params.values.pop_back();
  short_params.sigmas.pop_back();
  short_params.identified.pop_back();
  f.t.Publish(channels::kKinematicParams, short_params);
  sim::Rng rng(3);
  auto wrong_joints = f.Request(sim::SampleJoints(f.model, 1, rng)[0], 1'400'000, 9);
  wrong_joints.num_joints -= 1;
  wrong_joints.q_seed.pop_back();
  f.t.Publish(channels::kIkRequest, wrong_joints);
  const char garbage[] = "garbage";
  f.t.PublishRaw(channels::kIkRequest, garbage, sizeof garbage);
  f.t.PublishRaw(channels::kKinematicParams, garbage, sizeof garbage);
  f.Drain();

  EXPECT_EQ(f.node.health().rejected(), 6) << f.node.health().last_error();
  EXPECT_EQ(f.node.health().received(), 7);
  EXPECT_EQ(f.node.x(), x_before);
  EXPECT_EQ(f.node.params_utime(), 1'000'000);
  EXPECT_TRUE(f.commands.empty());
}

}  // namespace
}  // namespace rcal::transport

namespace rcal::transport {
namespace {

// An arm with joint-2 compliance and a second-harmonic gear error on joint 3 (values as
// `rcal analyze` would pass them): with the effects in its options the node's calibrated answer
// reaches the target on the truth (extended) arm; without them it misses by about the effects'
// size. Both see the same KINEMATIC_PARAMS.
TEST(IkCorrectorNode, WithEffectsCommandsTheExtendedArm) {
  const kinematics::KinematicModel model =
      io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml").model;
  const Eigen::VectorXd x_true = sim::Table3Errors(model);
  IkCorrectorNode::Options with;
  with.effects = {{kinematics::EffectCause::kJointCompliance, 1},
                  {kinematics::EffectCause::kJointPeriodic, 2, 2}};
  with.effect_values = Eigen::Vector3d(5e-6, 2e-4, -1e-4);  // rad/(N·m), rad, rad
  with.payload_kg = 2.0;
  with.command_channel = "IK_COMMAND_EXTENDED";
  const kinematics::ExtendedModel truth(model, with.effects, with.gravity);
  std::vector<int> all(model.num_params());
  for (int i = 0; i < model.num_params(); ++i) all[i] = i;
  const kinematic_params_t params = ToKinematicParams(
      model, x_true, Eigen::VectorXd::Constant(model.num_params(), 1e-6), all, model.name(), 1, 50);

  LcmTransport t("memq://");
  IkCorrectorNode extended(t, model, with), geometric(t, model);
  std::vector<ik_command_t> by_extended, by_geometric;
  t.Subscribe<ik_command_t>(with.command_channel,
                            [&](const ik_command_t& m) { by_extended.push_back(m); });
  t.Subscribe<ik_command_t>(channels::kIkCommand,
                            [&](const ik_command_t& m) { by_geometric.push_back(m); });
  const auto drain = [&] {
    while (t.HandleTimeout(0) > 0) {
    }
  };
  t.Publish(channels::kKinematicParams, params);
  drain();
  ASSERT_EQ(extended.x(), x_true);
  ASSERT_EQ(extended.e(), with.effect_values);

  sim::Rng rng(11);
  double worst_extended = 0, least_geometric = 1;
  for (int k = 0; k < 20; ++k) {
    const Eigen::VectorXd q_target = sim::SampleJoints(model, 1, rng)[0];
    IkQuery query;
    query.request_id = k;
    query.q_seed = q_target.array() + 0.05;
    kinematics::EffectContext ctx;
    ctx.payload_kg = with.payload_kg;
    query.T_WT = truth.ToolFrame(q_target, ctx, x_true, with.effect_values);
    by_extended.clear();
    by_geometric.clear();
    t.Publish(channels::kIkRequest, ToMessage(query, 2 + k));
    drain();
    ASSERT_EQ(by_extended.size(), 1u);
    ASSERT_EQ(by_geometric.size(), 1u);
    const auto miss = [&](const ik_command_t& c) {
      EXPECT_TRUE(c.converged) << c.reason;
      return (truth.ToolFrame(Q(c.q), ctx, x_true, with.effect_values).translation() -
              query.T_WT.translation())
          .norm();
    };
    worst_extended = std::max(worst_extended, miss(by_extended[0]));
    least_geometric = std::min(least_geometric, miss(by_geometric[0]));
  }
  EXPECT_LT(worst_extended, 1e-8);
  EXPECT_GT(least_geometric, 1e-5);  // the effects move the tool by tenths of a millimetre
  EXPECT_EQ(extended.health().rejected(), 0);
}

// An identifier run with --effects sends the effect values it identified: they replace the
// options' (the file's) when they are this model's effects; an estimate without effects keeps
// them; effects of another model refuse the message, naming the field, and change nothing.
TEST(IkCorrectorNode, EffectValuesIdentifiedLiveReplaceTheFilesValues) {
  const kinematics::KinematicModel model =
      io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml").model;
  const Eigen::VectorXd x_true = sim::Table3Errors(model);
  IkCorrectorNode::Options with;
  with.effects = {{kinematics::EffectCause::kJointCompliance, 1}};
  with.effect_values = Eigen::VectorXd::Constant(1, 1e-6);  // the file's [rad/(N·m)]
  const kinematics::ExtendedModel ext(model, with.effects, with.gravity);
  std::vector<int> all(model.num_params());
  for (int i = 0; i < model.num_params(); ++i) all[i] = i;
  const auto params = [&](int64_t utime, int poses) {
    return ToKinematicParams(model, x_true, Eigen::VectorXd::Constant(model.num_params(), 1e-6),
                             all, model.name(), utime, poses);
  };
  LcmTransport t("memq://");
  IkCorrectorNode node(t, model, with);
  const auto drain = [&] {
    while (t.HandleTimeout(0) > 0) {
    }
  };
  // Without effects in the message: the file's values stay.
  t.Publish(channels::kKinematicParams, params(1, 10));
  drain();
  EXPECT_EQ(node.e(), with.effect_values);
  // With this model's effects: the live values.
  kinematic_params_t live = params(2, 11);
  live.num_effect_params = 1;
  live.effect_names = {ext.EffectParameters()[0].name};
  live.effect_units = {ext.EffectParameters()[0].unit};
  live.effect_values = {2.5e-6};
  live.effect_sigmas = {1e-7};
  t.Publish(channels::kKinematicParams, live);
  drain();
  EXPECT_EQ(node.e(), Eigen::VectorXd::Constant(1, 2.5e-6));
  EXPECT_EQ(node.health().rejected(), 0);
  // Another model's effect: refused, naming the field; the values in use stay.
  kinematic_params_t other = live;
  other.utime = 3;
  other.poses_used = 12;
  other.effect_names = {"joint_compliance.j5.c"};
  other.effect_values = {9e-6};
  t.Publish(channels::kKinematicParams, other);
  drain();
  EXPECT_EQ(node.e(), Eigen::VectorXd::Constant(1, 2.5e-6));
  EXPECT_EQ(node.health().rejected(), 1);
  EXPECT_NE(node.health().last_error().find("kinematic_params.effect_names[0]"), std::string::npos)
      << node.health().last_error();
}

// Issue 11: a duplicate or older KINEMATIC_PARAMS replaced the estimate in use (a stale 1-pose
// estimate replaced the 30-pose one, IK off by 0.036 rad, rejected = 0). The newest by
// (poses_used, utime) is kept, refusals counted; an identifier that started over is followed
// after restart_params newer estimates in a row.
TEST(IkCorrectorNode, KeepsTheNewestEstimateByPosesUsedThenUtime) {
  Fixture f;
  std::vector<int> all(f.model.num_params());
  for (int i = 0; i < f.model.num_params(); ++i) all[i] = i;
  const Eigen::VectorXd sigma = Eigen::VectorXd::Constant(f.model.num_params(), 1e-6);
  const Eigen::VectorXd x_stale = f.model.Nominal() + 0.5 * (f.x_true - f.model.Nominal());
  auto params = [&](const Eigen::VectorXd& x, int64_t utime, int32_t poses) {
    return ToKinematicParams(f.model, x, sigma, all, f.model.name(), utime, poses);
  };
  f.node.OnParams(params(f.x_true, 60'000'000, 30));
  ASSERT_EQ(f.node.x(), f.x_true);
  // Older by poses_used (even with a later utime), older by utime, and a duplicate.
  f.node.OnParams(params(x_stale, 5'000'000, 1));
  f.node.OnParams(params(x_stale, 70'000'000, 29));
  f.node.OnParams(params(x_stale, 59'000'000, 30));
  f.node.OnParams(params(f.x_true, 60'000'000, 30));
  EXPECT_EQ(f.node.x(), f.x_true);
  EXPECT_EQ(f.node.params_utime(), 60'000'000);
  EXPECT_EQ(f.node.params_poses_used(), 30);
  EXPECT_EQ(f.node.health().stale(), 3);
  EXPECT_EQ(f.node.health().duplicates(), 1);
  EXPECT_EQ(f.node.health().rejected(), 4);
  // Newer on poses_used (same utime) and on utime (same poses_used) are taken.
  f.node.OnParams(params(x_stale, 60'000'000, 31));
  EXPECT_EQ(f.node.x(), x_stale);
  f.node.OnParams(params(f.x_true, 60'000'001, 31));
  EXPECT_EQ(f.node.x(), f.x_true);
  // A far-future utime is refused.
  f.node.OnParams(params(x_stale, int64_t{1} << 62, 40));
  EXPECT_EQ(f.node.x(), f.x_true);
  EXPECT_EQ(f.node.health().out_of_horizon(), 1);
  // The identifier started over without a checkpoint: 1, 2, 3, 4 refused, the 5th taken.
  for (int k = 1; k <= 5; ++k) {
    f.node.OnParams(params(x_stale, 1'000'000 * k, k));
    EXPECT_EQ(f.node.x() == x_stale, k == 5) << k;
  }
  EXPECT_EQ(f.node.params_poses_used(), 5);
  EXPECT_EQ(f.node.health().resyncs(), 1);
  EXPECT_EQ(f.node.health().stale(), 3 + 4);
}

TEST(IkCorrectorNode, ADuplicateRequestIsAnsweredOnce) {
  Fixture f;
  sim::Rng rng(3);
  const ik_request_t r = f.Request(sim::SampleJoints(f.model, 1, rng)[0], 1'000'000, 7);
  f.node.OnRequest(r);
  f.node.OnRequest(r);
  f.Drain();
  EXPECT_EQ(f.commands.size(), 1u);
  EXPECT_EQ(f.node.health().duplicates(), 1);
}

}  // namespace
}  // namespace rcal::transport
