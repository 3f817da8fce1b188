// Message <-> domain conversions: exact round trips through encoded bytes on memq://, and every
// malformed field rejected with its name.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>

#include "fixture.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/lcm_schema.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal::transport {
namespace {

using testing::Grb3016;

// Publishes on memq:// and returns what a subscriber decodes: the bytes really go through LCM.
template <typename Msg>
Msg ThroughLcm(const Msg& m) {
  LcmTransport t("memq://");
  std::optional<Msg> got;
  t.Subscribe<Msg>("C", [&](const Msg& r) { got = r; });
  EXPECT_TRUE(t.Publish("C", m));
  while (t.HandleTimeout(0) > 0) {
  }
  EXPECT_TRUE(got.has_value());
  return got.value_or(Msg{});
}

TEST(PoseMeasurementAdapter, FullPoseRoundTripsExactly) {
  const Grb3016 g(5);
  for (const auto& z : g.poses) {
    ASSERT_TRUE(z.has_orientation);
    const auto msg = ThroughLcm(ToMessage(z, 1000, 3));
    EXPECT_EQ(msg.utime, 1000);
    EXPECT_EQ(msg.pose_index, 3);
    std::string error;
    const auto back = FromMessage(msg, &error);
    ASSERT_TRUE(back) << error;
    EXPECT_EQ(back->q, z.q);
    EXPECT_EQ(back->p_WM_W, z.p_WM_W);
    EXPECT_EQ(back->covariance, z.covariance);
    EXPECT_TRUE(back->has_orientation);
    // Through a quaternion: equal to rounding.
    EXPECT_LT((back->R_EI - z.R_EI).cwiseAbs().maxCoeff(), 1e-15);
    // Same residual against the model at the truth as the original (independent of the codec).
    EXPECT_LT((kinematics::Residual(g.model, *back, g.x_true) -
               kinematics::Residual(g.model, z, g.x_true))
                  .cwiseAbs()
                  .maxCoeff(),
              1e-14);
  }
}

TEST(PoseMeasurementAdapter, PositionOnlyRoundTrips) {
  kinematics::PoseMeasurement z;
  z.q = Eigen::VectorXd::LinSpaced(6, -1, 1);
  z.p_WM_W = {0.5, -0.25, 1.0};
  z.covariance = Eigen::Matrix3d::Identity() * 2.5e-9;
  const auto msg = ToMessage(z, 5, 0);
  EXPECT_EQ(msg.dimension, 3);
  EXPECT_EQ(msg.num_covariance, 9);
  std::string error;
  const auto back = FromMessage(ThroughLcm(msg), &error);
  ASSERT_TRUE(back) << error;
  EXPECT_FALSE(back->has_orientation);
  EXPECT_EQ(back->covariance, z.covariance);
  EXPECT_EQ(back->p_WM_W, z.p_WM_W);
}

TEST(PoseMeasurementAdapter, MalformedFieldsAreRejectedByName) {
  const Grb3016 g(1);
  const auto good = ToMessage(g.poses[0], 1, 0);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  struct Case {
    const char* field;
    std::function<void(pose_measurement_t&)> spoil;
  };
  const std::vector<Case> cases = {
      {"num_joints", [](auto& m) { m.num_joints = 5; }},
      {"num_joints", [](auto& m) { m.num_joints = 0, m.q.clear(); }},
      {"q", [&](auto& m) { m.q[2] = nan; }},
      {"p", [&](auto& m) { m.p[1] = nan; }},
      {"dimension", [](auto& m) { m.dimension = 3; }},
      {"dimension", [](auto& m) { m.has_orientation = false; }},
      {"covariance", [](auto& m) { m.num_covariance = 9, m.covariance.resize(9); }},
      {"covariance", [&](auto& m) { m.covariance[7] = nan; }},
      {"covariance", [](auto& m) { m.covariance[1] = 1e-3; }},  // not symmetric
      {"q_EI", [](auto& m) { m.q_EI[0] = 2; }},
      {"q_EI", [&](auto& m) { m.q_EI[3] = nan; }},
  };
  std::string error;
  ASSERT_TRUE(FromMessage(good, &error)) << error;
  for (const auto& c : cases) {
    auto bad = good;
    c.spoil(bad);
    error.clear();
    EXPECT_FALSE(FromMessage(bad, &error)) << c.field;
    EXPECT_NE(error.find(std::string("pose_measurement.") + c.field), std::string::npos)
        << c.field << ": " << error;
  }
}

// marker_id carries the cell's marker id; FromMessage with the model turns it into the model's
// slot (the UR10 cell: markers 1 and 2 are slots 0 and 1) and refuses an id the model lacks,
// naming the field. Without a model only 0 passes (a single-marker cell).
TEST(PoseMeasurementAdapter, MarkerIdIsTheCellsAndBecomesTheModelsSlot) {
  const io::BuiltCell cell = io::LoadCell(RCAL_SOURCE_DIR "/config/cells/ur10.yaml");
  const auto& model = cell.model;
  ASSERT_EQ(model.markers().size(), 2u);
  EXPECT_EQ(MarkerId(model, 0), 1);
  EXPECT_EQ(MarkerId(model, 1), 2);
  kinematics::PoseMeasurement z;
  z.q = Eigen::VectorXd::Constant(model.num_joints(), 0.3);
  z.p_WM_W = {1.0, 0.5, 0.2};
  z.covariance = Eigen::Matrix3d::Identity() * 1e-8;
  for (int slot : {0, 1}) {
    z.marker = slot;
    const auto msg = ThroughLcm(ToMessage(z, 10, 4, MarkerId(model, slot)));
    EXPECT_EQ(msg.marker_id, slot + 1);
    std::string error;
    const auto back = FromMessage(msg, &error, &model);
    ASSERT_TRUE(back) << error;
    EXPECT_EQ(back->marker, slot);
    // Without the model a marker other than 0 cannot be placed.
    EXPECT_FALSE(FromMessage(msg, &error));
    EXPECT_NE(error.find("pose_measurement.marker_id: " + std::to_string(slot + 1)),
              std::string::npos)
        << error;
  }
  std::string error;
  EXPECT_FALSE(FromMessage(ToMessage(z, 10, 4, 0), &error, &model));
  EXPECT_NE(error.find("pose_measurement.marker_id: 0 is not a marker of"), std::string::npos)
      << error;
  EXPECT_NE(error.find("markers: 1, 2"), std::string::npos) << error;
  // A model without markers (the pose-level GRB3016 cell measures its tool frame): id 0, slot 0.
  const Grb3016 g(1);
  const auto back = FromMessage(ToMessage(g.poses[0], 10, 0), &error, &g.model);
  ASSERT_TRUE(back) << error;
  EXPECT_EQ(back->marker, 0);
  EXPECT_FALSE(FromMessage(ToMessage(g.poses[0], 10, 0, 3), &error, &g.model));
}

// A POSE_MEASUREMENT as recorded by earlier rcal decodes, field for field, with the fields it
// lacked at their defaults: before the context (fingerprint 0xa1f22502bbcd6577: temperature and
// time NaN, payload 0, dq_sign 0) and before marker_id too (0x257fdb5ac9ac24a6: marker 0).
// Anything else keeps its refusal: a damaged old message is refused naming the field, an unknown
// fingerprint as before.
TEST(PoseMeasurementAdapter, TheLayoutsBeforeTheContextAndMarkerIdStillDecode) {
  const Grb3016 g(2);
  kinematics::EffectContext ctx;
  ctx.temperature_c = 31.0;
  ctx.payload_kg = 2.5;
  ctx.time_s = 600.0;
  ctx.dq_sign = Eigen::VectorXi::Constant(g.model.num_joints(), -1);
  const pose_measurement_t now = ToMessage(g.poses[1], 123456, 9, 0, ctx);
  std::vector<uint8_t> bytes(static_cast<size_t>(now.getEncodedSize()));
  now.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  // Before the context: the fingerprint of then, the context (3 doubles, num_joints bytes) left
  // out at the end.
  std::vector<uint8_t> v2(bytes.begin(), bytes.end() - 24 - now.num_joints);
  const uint8_t before_context[8] = {0xa1, 0xf2, 0x25, 0x02, 0xbb, 0xcd, 0x65, 0x77};
  std::copy(before_context, before_context + 8, v2.begin());
  // Before marker_id: that, without marker_id's 4 bytes after pose_index.
  std::vector<uint8_t> v1(v2.begin(), v2.begin() + 20);
  v1.insert(v1.end(), v2.begin() + 24, v2.end());
  const uint8_t before_marker[8] = {0x25, 0x7f, 0xdb, 0x5a, 0xc9, 0xac, 0x24, 0xa6};
  std::copy(before_marker, before_marker + 8, v1.begin());
  for (const auto* old : {&v2, &v1}) {
    pose_measurement_t msg;
    EXPECT_NE(DecodeLcm(old->data(), old->size(), &msg), "");  // the plain decoder refuses it
    ASSERT_EQ(DecodePoseMeasurement(old->data(), old->size(), &msg), "");
    EXPECT_EQ(msg.utime, 123456);
    EXPECT_EQ(msg.pose_index, 9);
    EXPECT_EQ(msg.marker_id, 0);
    EXPECT_EQ(msg.q, now.q);
    EXPECT_EQ(msg.covariance, now.covariance);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(msg.q_EI[i], now.q_EI[i]);
    EXPECT_TRUE(std::isnan(msg.temperature_c));
    EXPECT_EQ(msg.payload_kg, 0.0);
    EXPECT_TRUE(std::isnan(msg.time_s));
    EXPECT_EQ(msg.dq_sign, std::vector<int8_t>(static_cast<size_t>(now.num_joints), 0));
    std::string error;
    const auto c = ContextFromMessage(msg, &error);
    ASSERT_TRUE(c) << error;
    EXPECT_EQ(c->dq_sign.size(), 0);  // all 0: no direction
  }
  // Today's layout decodes as it is, context and all.
  pose_measurement_t msg;
  ASSERT_EQ(DecodePoseMeasurement(bytes.data(), bytes.size(), &msg), "");
  EXPECT_EQ(msg.pose_index, 9);
  std::string error;
  const auto c = ContextFromMessage(msg, &error);
  ASSERT_TRUE(c) << error;
  EXPECT_EQ(c->temperature_c, 31.0);
  EXPECT_EQ(c->payload_kg, 2.5);
  EXPECT_EQ(c->time_s, 600.0);
  EXPECT_EQ(c->dq_sign, ctx.dq_sign);
  // Old messages with num_joints = -1: refused naming the field.
  v1[20] = v1[21] = v1[22] = v1[23] = 0xff;
  EXPECT_NE(DecodePoseMeasurement(v1.data(), v1.size(), &msg).find("num_joints = -1"),
            std::string::npos);
  v2[24] = v2[25] = v2[26] = v2[27] = 0xff;
  EXPECT_NE(DecodePoseMeasurement(v2.data(), v2.size(), &msg).find("num_joints = -1"),
            std::string::npos);
  // Another fingerprint: refused as DecodeLcm refuses it.
  v1[0] ^= 0x01;
  EXPECT_EQ(DecodePoseMeasurement(v1.data(), v1.size(), &msg),
            DecodeLcm(v1.data(), v1.size(), &msg));
  EXPECT_NE(DecodePoseMeasurement(v1.data(), v1.size(), &msg), "");
}

// The context's refusals each name their field; a good context survives the wire.
TEST(PoseMeasurementAdapter, ContextRefusalsNameTheField) {
  const Grb3016 g(1);
  const pose_measurement_t good = ToMessage(g.poses[0], 10, 0);
  std::string error;
  const auto c = ContextFromMessage(ThroughLcm(good), &error);
  ASSERT_TRUE(c) << error;
  EXPECT_TRUE(std::isnan(c->temperature_c));
  EXPECT_EQ(c->payload_kg, 0.0);
  struct Case {
    const char* field;
    std::function<void(pose_measurement_t&)> spoil;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<Case> cases = {
      {"temperature_c", [&](pose_measurement_t& m) { m.temperature_c = inf; }},
      {"temperature_c", [&](pose_measurement_t& m) { m.temperature_c = 2000.0; }},
      {"payload_kg", [&](pose_measurement_t& m) { m.payload_kg = nan; }},
      {"payload_kg", [&](pose_measurement_t& m) { m.payload_kg = -1.0; }},
      {"time_s", [&](pose_measurement_t& m) { m.time_s = -inf; }},
      {"dq_sign", [&](pose_measurement_t& m) { m.dq_sign.pop_back(); }},
      {"dq_sign[2]", [&](pose_measurement_t& m) { m.dq_sign[2] = 7; }},
  };
  for (const auto& k : cases) {
    pose_measurement_t m = good;
    k.spoil(m);
    error.clear();
    EXPECT_FALSE(ContextFromMessage(m, &error)) << k.field;
    EXPECT_NE(error.find(std::string("pose_measurement.") + k.field), std::string::npos)
        << k.field << ": " << error;
  }
}

TEST(KinematicParamsAdapter, RoundTripAndModelChecks) {
  const Grb3016 g(1);
  Eigen::VectorXd sigma = Eigen::VectorXd::Zero(g.model.num_params());
  for (int i : g.base) sigma(i) = 1e-4 * (i + 1);
  const auto msg =
      ThroughLcm(ToKinematicParams(g.model, g.x_true, sigma, g.base, "grb3016", 777, 12));
  EXPECT_EQ(msg.num_params, g.model.num_params());
  EXPECT_EQ(msg.poses_used, 12);
  EXPECT_EQ(msg.robot_id, "grb3016");
  EXPECT_EQ(msg.model_id, ModelId(g.model));
  int n_identified = 0;
  for (int i = 0; i < msg.num_params; ++i) {
    EXPECT_EQ(msg.names[i], g.model.parameters()[i].name);
    EXPECT_EQ(msg.sigmas[i], sigma(i));
    n_identified += msg.identified[i];
  }
  EXPECT_EQ(n_identified, static_cast<int>(g.base.size()));
  std::string error;
  const auto x = ParamsFromMessage(msg, g.model, &error);
  ASSERT_TRUE(x) << error;
  EXPECT_EQ(*x, g.x_true);

  auto renamed = msg;
  std::swap(renamed.names[0], renamed.names[1]);
  EXPECT_FALSE(ParamsFromMessage(renamed, g.model, &error));
  EXPECT_NE(error.find("kinematic_params.names[0]"), std::string::npos) << error;
  auto other = msg;
  other.model_id = "other:0";
  EXPECT_FALSE(ParamsFromMessage(other, g.model, &error));
  EXPECT_NE(error.find("kinematic_params.model_id"), std::string::npos) << error;
  auto nan = msg;
  nan.values[3] = std::nan("");
  EXPECT_FALSE(ParamsFromMessage(nan, g.model, &error));
  EXPECT_NE(error.find("kinematic_params.values"), std::string::npos) << error;
}

// An extended identifier's effect parameters travel with the estimate: names and units of the
// model, values and σ of the filter, read back exactly; a message that does not fit the model is
// refused naming the field; the layout before the effects (fingerprint 0xf474f493449420b3)
// decodes with none.
TEST(KinematicParamsAdapter, EffectParametersTravelWithTheEstimate) {
  const Grb3016 g(10);
  kinematics::Effect compliance;
  compliance.cause = kinematics::EffectCause::kJointCompliance;
  compliance.joint = 1;
  kinematics::Effect periodic;
  periodic.cause = kinematics::EffectCause::kJointPeriodic;
  periodic.joint = 2;
  const kinematics::ExtendedModel ext(g.model, {compliance, periodic});
  identification::EkfIdentifier ekf(ext, g.base);
  kinematics::EffectContext ctx;
  ctx.payload_kg = 5.0;
  for (const auto& z : g.poses) ekf.Update(z, ctx);
  const auto msg = ThroughLcm(ToKinematicParams(ekf, "grb3016", 99));
  ASSERT_EQ(msg.num_effect_params, 3);
  const auto params = ext.EffectParameters();
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(msg.effect_names[k], params[k].name);
    EXPECT_EQ(msg.effect_units[k], params[k].unit);
    EXPECT_EQ(msg.effect_values[k], ekf.e()(k));
    EXPECT_EQ(msg.effect_sigmas[k], ekf.sigma_e()(k));
    EXPECT_GT(msg.effect_sigmas[k], 0.0);
  }
  std::string error;
  const auto e = EffectsFromMessage(msg, ext, &error);
  ASSERT_TRUE(e) << error;
  EXPECT_EQ(*e, ekf.e());
  // A geometric estimate carries none, and does not fit the extended model.
  const auto plain =
      ThroughLcm(ToKinematicParams(g.model, g.x_true, g.x_true * 0, g.base, "r", 1, 1));
  EXPECT_EQ(plain.num_effect_params, 0);
  EXPECT_FALSE(EffectsFromMessage(plain, ext, &error));
  EXPECT_NE(error.find("kinematic_params.num_effect_params"), std::string::npos) << error;
  auto renamed = msg;
  std::swap(renamed.effect_names[0], renamed.effect_names[1]);
  EXPECT_FALSE(EffectsFromMessage(renamed, ext, &error));
  EXPECT_NE(error.find("kinematic_params.effect_names[0]"), std::string::npos) << error;
  auto nan = msg;
  nan.effect_values[2] = std::nan("");
  EXPECT_FALSE(EffectsFromMessage(nan, ext, &error));
  EXPECT_NE(error.find("kinematic_params.effect_values[2]"), std::string::npos) << error;
  auto negative = msg;
  negative.effect_sigmas[1] = -1.0;
  EXPECT_FALSE(EffectsFromMessage(negative, ext, &error));
  EXPECT_NE(error.find("kinematic_params.effect_sigmas[1]"), std::string::npos) << error;

  // The layout before the effects: the same bytes up to poses_used, the fingerprint of then.
  std::vector<uint8_t> bytes(static_cast<size_t>(plain.getEncodedSize()));
  plain.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  std::vector<uint8_t> old(bytes.begin(), bytes.end() - 4);  // num_effect_params = 0 left out
  const uint8_t before[8] = {0xf4, 0x74, 0xf4, 0x93, 0x44, 0x94, 0x20, 0xb3};
  std::copy(before, before + 8, old.begin());
  kinematic_params_t back;
  EXPECT_NE(DecodeLcm(old.data(), old.size(), &back), "");
  ASSERT_EQ(DecodeKinematicParams(old.data(), old.size(), &back), "");
  EXPECT_EQ(back.values, plain.values);
  EXPECT_EQ(back.poses_used, plain.poses_used);
  EXPECT_EQ(back.num_effect_params, 0);
  ASSERT_EQ(DecodeKinematicParams(bytes.data(), bytes.size(), &back), "");
  old[0] ^= 0x01;
  EXPECT_NE(DecodeKinematicParams(old.data(), old.size(), &back), "");
}

TEST(KinematicParamsAdapter, FromTheIdentifier) {
  const Grb3016 g(10);
  identification::EkfIdentifier ekf(g.model, g.base);
  for (const auto& z : g.poses) ekf.Update(z);
  const auto msg = ToKinematicParams(ekf, "grb3016", 99);
  EXPECT_EQ(msg.poses_used, ekf.accepted());
  for (int i = 0; i < g.model.num_params(); ++i) {
    EXPECT_EQ(msg.values[i], ekf.x()(i));
    EXPECT_EQ(msg.sigmas[i], ekf.sigma()(i));
  }
  const auto status = ToCalibrationStatus(ekf, {3.5, 1e-4, 2e-3, 1.0, true}, 99);
  EXPECT_EQ(status.poses_accepted, ekf.accepted());
  EXPECT_EQ(status.poses_rejected, ekf.rejected());
  EXPECT_EQ(status.condition_number, 3.5);
  EXPECT_TRUE(status.converged);
}

// CALIBRATION_STATUS carries the tracking state: converged, then joint 2 read 1 mrad off (an
// encoder swap): change_detected or reconverging, the change named with its size.
TEST(CalibrationStatusAdapter, CarriesTheTrackingStateAndTheChange) {
  const Grb3016 g(300);
  identification::EkfIdentifier ekf(g.model, g.base);
  for (int k = 0; k < 290; ++k) ekf.Update(g.poses[k]);
  auto status = ToCalibrationStatus(ekf, {}, 1);
  EXPECT_EQ(status.tracking_status, "converged");
  EXPECT_EQ(status.changes_detected, 0);
  EXPECT_EQ(status.num_changed, 0);
  sim::Rng rng(5);
  for (int k = 290; k < 300; ++k) {
    kinematics::PoseMeasurement m = g.poses[k];
    Eigen::VectorXd q_arm = m.q;
    q_arm(1) += 1e-3;
    m = sim::MeasurePose(g.model, g.x_true, q_arm, sim::PoseNoise{}, rng);
    m.q = g.poses[k].q;
    ekf.Update(m);
  }
  status = ToCalibrationStatus(ekf, {}, 2);
  EXPECT_TRUE(status.tracking_status == "change_detected" ||
              status.tracking_status == "reconverging" || status.tracking_status == "converged")
      << status.tracking_status;
  EXPECT_EQ(status.changes_detected, 1);
  ASSERT_EQ(status.num_changed, 1);
  ASSERT_EQ(status.changed.size(), 1u);
  EXPECT_TRUE(status.changed[0] == "theta2" || status.changed[0] == "offset of joint j2")
      << status.changed[0];
  EXPECT_NEAR(status.changed_step[0], 1e-3, 2e-4);
  // One step along the named direction, not alternatives (DetectedChange::probability empty).
  ASSERT_TRUE(ekf.changes().back().probability.empty());
  EXPECT_EQ(status.changed_probability, std::vector<double>{1.0});
  std::vector<uint8_t> bytes(status.getEncodedSize());
  ASSERT_EQ(status.encode(bytes.data(), 0, static_cast<int>(bytes.size())),
            static_cast<int>(bytes.size()));
  calibration_status_t back;
  ASSERT_EQ(back.decode(bytes.data(), 0, static_cast<int>(bytes.size())),
            static_cast<int>(bytes.size()));
  EXPECT_EQ(back.changed, status.changed);
  EXPECT_EQ(back.changed_step, status.changed_step);
  EXPECT_EQ(back.changed_probability, status.changed_probability);
  EXPECT_EQ(back.tracking_status, status.tracking_status);
}

TEST(ModelId, DependsOnTheParameterNames) {
  const Grb3016 g(1);
  const auto seven = io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/seven_dof.yaml").model;
  EXPECT_EQ(ModelId(g.model), ModelId(g.model));
  EXPECT_NE(ModelId(g.model), ModelId(seven));
  EXPECT_EQ(ModelId(g.model).rfind(g.model.name() + ":", 0), 0u);
}

TEST(IkAdapter, RequestRoundTripAndRejections) {
  IkQuery q;
  q.request_id = 42;
  q.T_WT.translation() = Eigen::Vector3d(0.4, 0.1, 0.6);
  q.T_WT.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).matrix();
  q.q_seed = Eigen::VectorXd::Constant(6, 0.1);
  std::string error;
  const auto back = FromMessage(ThroughLcm(ToMessage(q, 17)), 6, &error);
  ASSERT_TRUE(back) << error;
  EXPECT_EQ(back->request_id, 42);
  EXPECT_EQ(back->q_seed, q.q_seed);
  EXPECT_LT((back->T_WT.matrix() - q.T_WT.matrix()).cwiseAbs().maxCoeff(), 1e-15);

  auto wrong_count = ToMessage(q, 17);
  EXPECT_FALSE(FromMessage(wrong_count, 7, &error));
  EXPECT_NE(error.find("ik_request.num_joints"), std::string::npos) << error;
  auto bad_quat = ToMessage(q, 17);
  bad_quat.q_WT[0] = 0.2;
  EXPECT_FALSE(FromMessage(bad_quat, 6, &error));
  EXPECT_NE(error.find("ik_request.q_WT"), std::string::npos) << error;
  bad_quat.position_only = true;  // orientation ignored
  EXPECT_TRUE(FromMessage(bad_quat, 6, &error)) << error;
}

TEST(IkAdapter, CommandCarriesBothSolutions) {
  ik_request_t req;
  req.utime = 5;
  req.request_id = 9;
  ik::IkResult cal, nom;
  cal.q = Eigen::VectorXd::Constant(6, 0.2);
  cal.converged = true;
  cal.status = ik::IkStatus::kConverged;
  cal.position_error = 1e-12;
  nom.q = Eigen::VectorXd::Constant(6, 0.21);
  const auto cmd = ThroughLcm(ToIkCommand(req, cal, nom, 3e-3, 77));
  EXPECT_EQ(cmd.request_id, 9);
  EXPECT_EQ(cmd.utime, 5);
  EXPECT_TRUE(cmd.converged);
  EXPECT_EQ(cmd.status, "converged");
  EXPECT_EQ(cmd.q, std::vector<double>(6, 0.2));
  EXPECT_EQ(cmd.q_nominal, std::vector<double>(6, 0.21));
  EXPECT_EQ(cmd.nominal_tool_error, 3e-3);
  EXPECT_EQ(cmd.params_utime, 77);
}

TEST(JointStateAdapter, NamesFromTheModel) {
  const Grb3016 g(1);
  const auto msg = ThroughLcm(ToJointState(g.model, g.poses[0].q, 11));
  ASSERT_EQ(msg.num_joints, 6);
  EXPECT_EQ(msg.names[0], g.model.joints()[0].name);
  EXPECT_EQ(msg.q[5], g.poses[0].q(5));
  EXPECT_EQ(msg.dq, std::vector<double>(6, 0.0));
}

// CLOCK_OFFSET → the sources' clocks (ros2_input's message, read by still_window and dds_bridge).
TEST(ClockOffsetAdapter, SourcesAndRefusals) {
  clock_offset_t m{};
  m.utime = 5;
  m.num_sources = 3;
  m.source = {"imu", "position/0", "position/2"};
  m.state = {2, 1, 3};
  m.offset = {0.037, -0.12, 0.0};
  m.sigma = {7e-4, 0.02, 0.0};
  m.resets = {1, 0, 0};
  std::string error;
  const auto c = ClockOffsetsFromMessage(m, &error);
  ASSERT_TRUE(c) << error;
  ASSERT_EQ(c->size(), 3u);
  EXPECT_EQ((*c)[0].source, "imu");
  EXPECT_EQ((*c)[0].offset.state, estimation::ClockState::kLocked);
  EXPECT_TRUE((*c)[0].offset.usable);
  EXPECT_EQ((*c)[0].offset.offset_s, 0.037);
  EXPECT_EQ((*c)[0].offset.sigma_s, 7e-4);
  EXPECT_EQ((*c)[0].resets, 1);
  EXPECT_EQ((*c)[1].offset.state, estimation::ClockState::kEstimating);
  EXPECT_FALSE((*c)[1].offset.usable);
  EXPECT_TRUE((*c)[2].fixed);
  // Unknown: σ = +inf is allowed.
  m.state[1] = 0;
  m.sigma[1] = std::numeric_limits<double>::infinity();
  EXPECT_TRUE(ClockOffsetsFromMessage(m, &error));
  auto bad = m;
  bad.state[2] = 7;
  EXPECT_FALSE(ClockOffsetsFromMessage(bad, &error));
  EXPECT_EQ(error, "clock_offset.source[2] (position/2).state: 7 is not 0 to 3");
  bad = m;
  bad.offset[0] = std::nan("");
  EXPECT_FALSE(ClockOffsetsFromMessage(bad, &error));
  EXPECT_EQ(error, "clock_offset.source[0] (imu).offset: not finite");
  bad = m;
  bad.sigma[0] = -1;
  EXPECT_FALSE(ClockOffsetsFromMessage(bad, &error));
  EXPECT_EQ(error, "clock_offset.source[0] (imu).sigma: NaN or negative");
  bad = m;
  bad.resets.pop_back();
  EXPECT_FALSE(ClockOffsetsFromMessage(bad, &error));
  EXPECT_EQ(error, "clock_offset.num_sources: 3, the arrays disagree");
  bad = m;
  bad.num_sources = -1;
  EXPECT_FALSE(ClockOffsetsFromMessage(bad, &error));
  EXPECT_EQ(error, "clock_offset.num_sources: -1 is not 0 to 4096");
}

// ARM_CONDITIONS (the controller's report, read by still_window): through the encoded bytes, NaN
// kept as "not measured / not known", each bad field refused by name with a hint at the unit.
TEST(ArmConditionsAdapter, RoundTripAndRefusals) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::string error;
  const auto c =
      ArmConditionsFromMessage(ThroughLcm(ToArmConditions({1'500'000, 31.25, 4.5})), &error);
  ASSERT_TRUE(c) << error;
  EXPECT_EQ(c->utime, 1'500'000);
  EXPECT_EQ(c->temperature_c, 31.25);
  EXPECT_EQ(c->payload_kg, 4.5);
  const auto unknown = ArmConditionsFromMessage(ToArmConditions({7, nan, nan}), &error);
  ASSERT_TRUE(unknown) << error;
  EXPECT_TRUE(std::isnan(unknown->temperature_c));
  EXPECT_TRUE(std::isnan(unknown->payload_kg));
  const auto refused = [&](ArmConditions bad, const std::string& expected) {
    error.clear();
    EXPECT_FALSE(ArmConditionsFromMessage(ToArmConditions(bad), &error)) << expected;
    EXPECT_EQ(error, expected);
  };
  const double inf = std::numeric_limits<double>::infinity();
  refused({-1, 20.0, 0.0}, "arm_conditions.utime: -1 is negative");
  refused({1, inf, 0.0}, "arm_conditions.temperature_c: infinite");
  refused({1, 300.15, 0.0},
          "arm_conditions.temperature_c: 300.150000 °C is not -60 to 200 (kelvin?)");
  refused({1, -80.0, 0.0}, "arm_conditions.temperature_c: -80.000000 °C is not -60 to 200");
  refused({1, 20.0, -inf}, "arm_conditions.payload_kg: infinite");
  refused({1, 20.0, -0.5}, "arm_conditions.payload_kg: -0.500000 kg is not 0 to 1000");
  refused({1, 20.0, 2500.0}, "arm_conditions.payload_kg: 2500.000000 kg is not 0 to 1000 (grams?)");
}

// NEXT_POSES: the advice round-trips through the encoded bytes; each malformed field is refused
// by name, and a suggestion outside the joint limits is never passed on to a cell.
TEST(NextPosesAdapter, RoundTripAndRefusals) {
  const Grb3016 g(2);
  cell::NextPoseAdvice a;
  for (int i = 0; i < 2; ++i) {
    a.q.push_back(g.poses[i].q);
    identification::NextPose p;
    p.gain_m2 = 1e-9 * (2 - i);
    p.distance = 0.5 + i;
    a.poses.push_back(p);
  }
  a.predicted_rms_m = 3e-5;
  const int nj = g.model.num_joints();
  const next_poses_t m = ThroughLcm(ToNextPoses(a, 1234, 17, nj));
  std::string error;
  const auto n = NextPosesFromMessage(m, g.model, &error);
  ASSERT_TRUE(n) << error;
  EXPECT_EQ(n->utime, 1234);
  EXPECT_EQ(n->poses_used, 17);
  ASSERT_EQ(n->q.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(n->q[i], g.poses[i].q);
    EXPECT_EQ(n->gain_m2[i], a.poses[i].gain_m2);
    EXPECT_EQ(n->distance[i], a.poses[i].distance);
  }
  EXPECT_EQ(n->predicted_rms_m, 3e-5);
  auto refused = [&](next_poses_t bad, const std::string& why) {
    std::string e;
    EXPECT_FALSE(NextPosesFromMessage(bad, g.model, &e));
    EXPECT_EQ(e, why);
  };
  auto bad = m;
  bad.num_joints = 5;
  refused(bad, "next_poses.num_joints: 5, the model has 6");
  bad = m;
  bad.count = 1 << 20;
  refused(bad, "next_poses.count: 1048576 is not 0 to 1000");
  bad = m;
  bad.q.pop_back();
  refused(bad, "next_poses.num_values: 12 is not count × num_joints (12) or q disagrees");
  bad = m;
  bad.gain.pop_back();
  refused(bad, "next_poses.count: 2, gain or distance disagrees");
  bad = m;
  bad.gain[1] = std::nan("");
  refused(bad, "next_poses.gain[1]: not a finite value ≥ 0");
  bad = m;
  bad.distance[0] = -1;
  refused(bad, "next_poses.distance[0]: not a finite value ≥ 0");
  bad = m;
  bad.predicted_rms_position = std::numeric_limits<double>::infinity();
  refused(bad, "next_poses.predicted_rms_position: not a finite value ≥ 0");
  bad = m;
  bad.q[nj + 1] = std::numeric_limits<double>::quiet_NaN();
  refused(bad, "next_poses.q[1] joint j2: not finite");
  bad = m;
  bad.q[2] = g.model.joints()[2].upper + 0.1;
  EXPECT_FALSE(NextPosesFromMessage(bad, g.model, &error));
  EXPECT_NE(error.find("next_poses.q[0] joint j3: "), std::string::npos) << error;
  EXPECT_NE(error.find("outside its limits"), std::string::npos) << error;
  // No suggestion is a valid message (an identifier with nothing to advise).
  cell::NextPoseAdvice none;
  const auto empty = NextPosesFromMessage(ToNextPoses(none, 5, 0, nj), g.model, &error);
  ASSERT_TRUE(empty) << error;
  EXPECT_TRUE(empty->q.empty());
}

// MODEL_DISCREPANCY (issue 15 item 5): the watch's report round-trips; every malformed field is
// refused naming it.
TEST(ModelDiscrepancyAdapter, RoundTripAndRefusals) {
  cell::DiscrepancyReport r;
  r.window_poses = 100;
  r.noise_against = "stated noise";
  r.chi2 = 1100;
  r.chi2_dof = 575;
  r.chi2_log_p = -200;
  cell::SuspectedEffect s;
  s.effect.cause = kinematics::EffectCause::kJointCompliance;
  s.effect.joint = 1;
  s.cause = "joint_compliance";
  s.joints = {"j2"};
  s.description = "joint_compliance j2";
  s.z = 5.5;
  r.suspects.push_back(s);
  s.effect.cause = kinematics::EffectCause::kThermal;
  s.cause = "thermal";
  s.joints.clear();
  s.description = "thermal (time)";
  s.z = 3.1;
  s.in_model = true;
  r.suspects.push_back(s);
  r.heldout_rms_before_m = 1.6e-4;
  r.heldout_rms_after_m = 0.8e-4;
  r.expected_gain = 0.5;
  r.scheme = "nested 5-fold";
  r.correlations.push_back({"gravity torque j2 [N*m]", 0.41, -12.5});
  r.correlations.push_back({"temperature [degC]", -0.05, -0.3});
  std::vector<cell::WithdrawnChange> withdrawn(2);
  withdrawn[0].onset_pose_index = 43;
  withdrawn[0].names = {"theta2", "d4"};
  withdrawn[0].evidence_gain = 5.8;
  withdrawn[1].evidence_gain = 0.0;  // raised before a restart: pose and names not known
  const model_discrepancy_t m = ThroughLcm(ToModelDiscrepancy(r, 123, 100, true, withdrawn));
  std::string error;
  const auto d = ModelDiscrepancyFromMessage(m, &error);
  ASSERT_TRUE(d) << error;
  EXPECT_EQ(d->utime, 123);
  EXPECT_EQ(d->poses_used, 100);
  EXPECT_EQ(d->window_poses, 100);
  EXPECT_EQ(d->chi2, 1100);
  EXPECT_EQ(d->chi2_log_p, -200);
  ASSERT_EQ(d->suspects.size(), 2u);
  EXPECT_EQ(d->suspects[0].cause, "joint_compliance");
  EXPECT_EQ(d->suspects[0].joints, "j2");
  EXPECT_EQ(d->suspects[0].description, "joint_compliance j2");
  EXPECT_EQ(d->suspects[0].z, 5.5);
  EXPECT_FALSE(d->suspects[0].in_model);
  EXPECT_EQ(d->suspects[1].joints, "");
  EXPECT_TRUE(d->suspects[1].in_model);
  EXPECT_EQ(d->expected_gain, 0.5);
  EXPECT_EQ(d->scheme, "nested 5-fold");
  EXPECT_TRUE(d->switched_in);
  ASSERT_EQ(d->correlations.size(), 2u);
  EXPECT_EQ(d->correlations[0].regressor, "gravity torque j2 [N*m]");
  EXPECT_EQ(d->correlations[0].r, 0.41);
  EXPECT_EQ(d->correlations[1].log_p, -0.3);
  ASSERT_EQ(d->withdrawn.size(), 2u);
  EXPECT_EQ(d->withdrawn[0].onset_pose_index, 43);
  EXPECT_EQ(d->withdrawn[0].changed, "theta2,d4");
  EXPECT_EQ(d->withdrawn[0].evidence, 5.8);
  EXPECT_EQ(d->withdrawn[1].onset_pose_index, -1);
  EXPECT_EQ(d->withdrawn[1].changed, "");
  EXPECT_EQ(ThroughLcm(ToModelDiscrepancy(r, 123, 100, false)).num_withdrawn, 0);
  // An infinite z (zero spread of the paired differences) and a log p that underflowed are valid.
  model_discrepancy_t extreme = m;
  extreme.z[0] = std::numeric_limits<double>::infinity();
  extreme.chi2_log_p = -std::numeric_limits<double>::infinity();
  EXPECT_TRUE(ModelDiscrepancyFromMessage(extreme, &error)) << error;
  const auto refused = [&](const std::function<void(model_discrepancy_t&)>& spoil,
                           const std::string& field) {
    model_discrepancy_t bad = m;
    spoil(bad);
    std::string e;
    EXPECT_FALSE(ModelDiscrepancyFromMessage(bad, &e)) << field;
    EXPECT_NE(e.find("model_discrepancy." + field), std::string::npos) << e;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  refused([](auto& b) { b.num_suspects = 3; }, "num_suspects");
  refused([](auto& b) { b.num_suspects = -1; }, "num_suspects");
  refused([](auto& b) { b.num_suspects = 1 << 30; }, "num_suspects");
  refused([](auto& b) { b.window_poses = -1; }, "window_poses");
  refused([&](auto& b) { b.chi2 = nan; }, "chi2");
  refused([](auto& b) { b.chi2_dof = -1; }, "chi2_dof");
  refused([](auto& b) { b.chi2_log_p = 0.5; }, "chi2_log_p");
  refused([](auto& b) { b.cause[1] = "gremlins"; }, "cause[1]");
  refused([&](auto& b) { b.z[0] = nan; }, "z[0]");
  refused([](auto& b) { b.in_model[0] = 2; }, "in_model[0]");
  refused([](auto& b) { b.description[0] = std::string(300, 'x'); }, "description[0]");
  refused([](auto& b) { b.heldout_rms_after = -1e-3; }, "heldout_rms_after");
  refused([](auto& b) { b.expected_gain = 2; }, "expected_gain");
  refused([](auto& b) { b.switched_in = 7; }, "switched_in");
  refused([](auto& b) { b.num_correlations = 5; }, "num_correlations");
  refused([](auto& b) { b.num_correlations = 65; }, "num_correlations");
  refused([](auto& b) { b.correlation[1] = 1.5; }, "correlation[1]");
  refused([](auto& b) { b.correlation_log_p[0] = 0.1; }, "correlation_log_p[0]");
  refused([](auto& b) { b.regressor[0] = std::string(257, 'r'); }, "regressor[0]");
  refused([](auto& b) { b.num_withdrawn = 3; }, "num_withdrawn");
  refused([](auto& b) { b.num_withdrawn = 1 << 30; }, "num_withdrawn");
  refused([](auto& b) { b.withdrawn_onset_pose_index[0] = -2; }, "withdrawn_onset_pose_index[0]");
  refused([](auto& b) { b.withdrawn_changed[1] = std::string(257, 'c'); }, "withdrawn_changed[1]");
  refused([&](auto& b) { b.withdrawn_evidence[0] = nan; }, "withdrawn_evidence[0]");
  refused([](auto& b) { b.withdrawn_evidence[1] = -1; }, "withdrawn_evidence[1]");
}

}  // namespace
}  // namespace rcal::transport
