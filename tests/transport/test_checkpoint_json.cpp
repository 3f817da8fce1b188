// A checkpoint written as text and restored continues exactly as the uninterrupted identifier.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>

#include "fixture.hpp"
#include "rcal/io/effects_json.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/checkpoint_json.hpp"

namespace rcal::transport {
namespace {

using testing::Grb3016;

TEST(Checkpoint, RestoredIdentifierContinuesBitForBit) {
  const Grb3016 g(30);
  identification::EkfIdentifier whole(g.model, g.base), first(g.model, g.base);
  for (int k = 0; k < 15; ++k) {
    whole.Update(g.poses[k]);
    first.Update(g.poses[k]);
  }
  CheckpointFile f{ModelId(g.model), 1234, 14, first.Checkpoint(), {}, {}};
  const auto dir = std::filesystem::temp_directory_path() /
                   ("rcal_checkpoint_test_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  SaveCheckpoint(dir / "ekf.json", f);
  const CheckpointFile back = LoadCheckpoint(dir / "ekf.json");
  EXPECT_EQ(back.model_id, f.model_id);
  EXPECT_EQ(back.utime, 1234);
  EXPECT_EQ(back.last_pose_index, 14);

  identification::EkfIdentifier resumed(g.model, g.base);
  resumed.Restore(back.checkpoint);
  EXPECT_EQ(resumed.x(), first.x());
  EXPECT_EQ(resumed.P(), first.P());
  EXPECT_EQ(resumed.accepted(), first.accepted());
  for (int k = 15; k < 30; ++k) {
    whole.Update(g.poses[k]);
    resumed.Update(g.poses[k]);
  }
  EXPECT_EQ(resumed.x(), whole.x());
  EXPECT_EQ(resumed.P(), whole.P());
  EXPECT_EQ(resumed.relinearizations(), whole.relinearizations());
  std::filesystem::remove_all(dir);
}

// The tracking state (status, a released change's inflation before its pose) round-trips; an
// unknown status is refused naming the key.
TEST(Checkpoint, TrackingStateRoundTrips) {
  const Grb3016 g(12);
  identification::EkfIdentifier ekf(g.model, g.base);
  for (int k = 0; k < 12; ++k) ekf.Update(g.poses[k]);
  CheckpointFile f{ModelId(g.model), 1, 11, ekf.Checkpoint(), {}, {}};
  const int n = static_cast<int>(g.base.size());
  f.checkpoint.inflations.resize(f.checkpoint.history.size());
  f.checkpoint.inflations[4] = Eigen::MatrixXd::Identity(n, n) * 1e-6;
  f.checkpoint.inflations[4](0, 1) = f.checkpoint.inflations[4](1, 0) = 2.5e-7;
  f.checkpoint.status = identification::TrackingStatus::kReconverging;
  f.checkpoint.small_steps = 3;
  f.checkpoint.second_look_onset = 4;            // that release's second look is pending
  f.checkpoint.second_look_alternatives = true;  // its directions are alternatives
  const CheckpointFile back = ParseCheckpoint(CheckpointText(f));
  EXPECT_EQ(back.checkpoint.status, identification::TrackingStatus::kReconverging);
  EXPECT_EQ(back.checkpoint.small_steps, 3);
  EXPECT_EQ(back.checkpoint.second_look_onset, 4);
  EXPECT_TRUE(back.checkpoint.second_look_alternatives);
  ASSERT_EQ(back.checkpoint.inflations.size(), f.checkpoint.inflations.size());
  EXPECT_EQ(back.checkpoint.inflations[4], f.checkpoint.inflations[4]);
  EXPECT_EQ(back.checkpoint.inflations[3].size(), 0);
  identification::EkfIdentifier a(g.model, g.base), b(g.model, g.base);
  a.Restore(f.checkpoint);
  b.Restore(back.checkpoint);
  EXPECT_EQ(b.status(), identification::TrackingStatus::kReconverging);
  EXPECT_EQ(a.Refine(3), b.Refine(3));
  EXPECT_EQ(a.x(), b.x());  // the inflation is used by the passes, identically
  EXPECT_EQ(b.Checkpoint().second_look_onset, 4);
  EXPECT_TRUE(b.Checkpoint().second_look_alternatives);
  // A pending look at a pose without a release (or beyond the history) is refused, named.
  for (const int bad : {3, 12, -2}) {
    identification::EkfCheckpoint c = back.checkpoint;
    c.second_look_onset = bad;
    try {
      b.Restore(c);
      FAIL() << "no exception for " << bad;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("second_look_onset"), std::string::npos) << e.what();
    }
  }
  std::string text = CheckpointText(f);
  {  // not a boolean: refused, named
    std::string t = text;
    t.replace(t.find("\"second_look_alternatives\":true"), 31, "\"second_look_alternatives\":2");
    try {
      ParseCheckpoint(t);
      FAIL() << "no exception";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("second_look_alternatives"), std::string::npos)
          << e.what();
    }
  }
  text.replace(text.find("reconverging"), 12, "wandering");
  try {
    ParseCheckpoint(text);
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("status"), std::string::npos) << e.what();
  }
}

TEST(Checkpoint, MalformedTextIsAnErrorNamingTheKey) {
  EXPECT_THROW(ParseCheckpoint("not json"), std::runtime_error);
  try {
    ParseCheckpoint(R"({"schema": "rcal.ekf_checkpoint/1", "model_id": "m", "utime": 0,
                        "last_pose_index": 0})");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("x0"), std::string::npos) << e.what();
  }
  try {
    ParseCheckpoint(R"({"schema": "other/1"})");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("schema"), std::string::npos) << e.what();
  }
}

// Schema 2: the poses held back for the set-up guess survive a save and load bit for bit.
TEST(Checkpoint, HeldPosesRoundTrip) {
  const Grb3016 g(4);
  identification::EkfIdentifier ekf(g.model, g.base);
  CheckpointFile f{ModelId(g.model), 5678, -1, ekf.Checkpoint(), {}, {}};
  for (int k = 0; k < 3; ++k) f.held.push_back({g.poses[k], 1000 + k, k, {}});
  const CheckpointFile back = ParseCheckpoint(CheckpointText(f));
  ASSERT_EQ(back.held.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(back.held[k].utime, 1000 + k);
    EXPECT_EQ(back.held[k].pose_index, k);
    EXPECT_EQ(back.held[k].z.q, g.poses[k].q);
    EXPECT_EQ(back.held[k].z.p_WM_W, g.poses[k].p_WM_W);
    EXPECT_EQ(back.held[k].z.R_EI, g.poses[k].R_EI);
    EXPECT_EQ(back.held[k].z.covariance, g.poses[k].covariance);
    EXPECT_EQ(back.held[k].z.has_orientation, g.poses[k].has_orientation);
  }
  EXPECT_EQ(back.checkpoint.accepted, 0);
}

// An extended identifier's checkpoint keeps each pose's context (unknown temperature and time as
// null, dq_sign as given) and the held poses' contexts: restored, the identifier continues bit for
// bit as the one it was taken from; a malformed context is an error naming its key.
TEST(Checkpoint, ContextsRoundTrip) {
  const Grb3016 g(12);
  kinematics::Effect compliance;
  compliance.cause = kinematics::EffectCause::kJointCompliance;
  compliance.joint = 1;
  const kinematics::ExtendedModel ext(g.model, {compliance});
  const auto context = [&](int k) {
    kinematics::EffectContext c;
    c.payload_kg = 2.5 * k;
    if (k % 2) c.temperature_c = 20.0 + 0.1 * k;  // else unknown (NaN)
    if (k % 3) c.time_s = 60.0 * k;
    c.dq_sign = Eigen::VectorXi::Constant(g.model.num_joints(), k % 2 ? 1 : -1);
    return c;
  };
  identification::EkfIdentifier a(ext, g.base), b(ext, g.base);
  for (int k = 0; k < 8; ++k) a.Update(g.poses[k], context(k));
  CheckpointFile f{ModelId(g.model), 5678, 7, a.Checkpoint(), {}, {}};
  f.held.push_back({g.poses[8], 9000, 8, context(8)});
  const CheckpointFile back = ParseCheckpoint(CheckpointText(f));
  ASSERT_EQ(back.checkpoint.contexts.size(), 8u);
  for (int k = 0; k < 8; ++k) {
    const auto& c = back.checkpoint.contexts[k];
    const auto want = context(k);
    EXPECT_EQ(std::isnan(c.temperature_c), std::isnan(want.temperature_c)) << k;
    if (!std::isnan(want.temperature_c)) {
      EXPECT_EQ(c.temperature_c, want.temperature_c) << k;
    }
    EXPECT_EQ(std::isnan(c.time_s), std::isnan(want.time_s)) << k;
    if (!std::isnan(want.time_s)) {
      EXPECT_EQ(c.time_s, want.time_s) << k;
    }
    EXPECT_EQ(c.payload_kg, want.payload_kg) << k;
    EXPECT_EQ(c.dq_sign, want.dq_sign) << k;
  }
  ASSERT_EQ(back.held.size(), 1u);
  EXPECT_EQ(back.held[0].context.payload_kg, 20.0);
  EXPECT_EQ(back.held[0].context.dq_sign, context(8).dq_sign);
  b.Restore(back.checkpoint);
  for (int k = 8; k < 12; ++k) {
    a.Update(g.poses[k], context(k));
    b.Update(g.poses[k], context(k));
  }
  EXPECT_EQ(b.state(), a.state());
  EXPECT_EQ(b.P(), a.P());
  // A geometric identifier writes no contexts.
  identification::EkfIdentifier plain(g.model, g.base);
  plain.Update(g.poses[0]);
  EXPECT_EQ(CheckpointText({ModelId(g.model), 1, 0, plain.Checkpoint(), {}, {}}).find("contexts"),
            std::string::npos);
  // Malformed: named.
  std::string text = CheckpointText(f);
  const auto at = text.find("\"dq_sign\":[");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, text.find(']', at) + 1 - at, "\"dq_sign\":7");
  try {
    ParseCheckpoint(text);
    ADD_FAILURE() << "a dq_sign that is not an array loaded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("dq_sign"), std::string::npos) << e.what();
  }
}

// A schema-1 file (written before `held` existed) still loads, with nothing held; a schema-3
// file without `held` is an error naming the key. A schema-2 file (before `x_fixed` and the
// measurements' marker) loads with the identifier's own fixed values and marker 0.
// The effects of the state's model (an identifier whose discrepancy watch switched them in) are
// kept as analysis.json entries and read back as written; a malformed entry is named.
TEST(Checkpoint, TheEffectsOfTheStatesModelRoundTrip) {
  const Grb3016 g(13);
  kinematics::Effect compliance;
  compliance.cause = kinematics::EffectCause::kJointCompliance;
  compliance.joint = 1;
  const kinematics::ExtendedModel ext(g.model, {compliance});
  identification::EkfIdentifier a(ext, g.base);
  for (int k = 0; k < 4; ++k) a.Update(g.poses[k]);
  const std::string effects = io::EffectsJson(ext, a.e(), a.sigma_e()).dump();
  const CheckpointFile f{ModelId(g.model), 1, 3, a.Checkpoint(), {}, effects};
  const CheckpointFile back = ParseCheckpoint(CheckpointText(f));
  EXPECT_EQ(back.effects_json, effects);
  const auto parsed =
      io::ParseAnalysisEffects({{"effects", nlohmann::json::parse(back.effects_json)}}, g.model);
  ASSERT_EQ(parsed.effects.size(), 1u);
  EXPECT_TRUE(parsed.effects[0].SameAs(compliance));
  // A geometric state writes no key.
  EXPECT_EQ(CheckpointText({ModelId(g.model), 1, 3, a.Checkpoint(), {}, {}}).find("\"effects\""),
            std::string::npos);
  std::string text = CheckpointText(f);
  text.replace(text.find("\"effects\""), 10, "\"effects\": 5, \"_x\":");
  try {
    ParseCheckpoint(text);
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("effects"), std::string::npos) << e.what();
  }
}

TEST(Checkpoint, SchemaOneStillLoads) {
  const Grb3016 g(10);
  identification::EkfIdentifier ekf(g.model, g.base);
  for (int k = 0; k < 10; ++k) ekf.Update(g.poses[k]);
  std::string text = CheckpointText({ModelId(g.model), 42, 9, ekf.Checkpoint(), {}, {}});
  const auto v3 = text.find("rcal.ekf_checkpoint/3");
  ASSERT_NE(v3, std::string::npos);
  {
    std::string v2 = text;
    v2.replace(v3, 21, "rcal.ekf_checkpoint/2");
    const CheckpointFile back = ParseCheckpoint(v2);
    EXPECT_EQ(back.checkpoint.x_fixed.size(), 0);  // schema 2 has none: not read
    ASSERT_EQ(ParseCheckpoint(text).checkpoint.x_fixed, ekf.Checkpoint().x_fixed);
  }
  const auto held = text.find(",\"held\":[]");
  ASSERT_NE(held, std::string::npos) << text.substr(0, 200);
  std::string v1 = text;
  v1.erase(held, std::string(",\"held\":[]").size());
  try {
    ParseCheckpoint(v1);
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("held"), std::string::npos) << e.what();
  }
  v1.replace(v1.find("rcal.ekf_checkpoint/3"), 21, "rcal.ekf_checkpoint/1");
  const CheckpointFile back = ParseCheckpoint(v1);
  EXPECT_TRUE(back.held.empty());
  EXPECT_EQ(back.last_pose_index, 9);
  identification::EkfIdentifier resumed(g.model, g.base);
  resumed.Restore(back.checkpoint);
  EXPECT_EQ(resumed.x(), ekf.x());
  EXPECT_EQ(resumed.P(), ekf.P());
}

// Issue 11: a checkpoint holding a far-future time (2^62 µs) kept a restarted identifier stuck.
TEST(Checkpoint, AFarFutureTimeIsNotTrusted) {
  CheckpointFile c;
  c.utime = 5'000'000;
  EXPECT_EQ(UntrustedCheckpointTime(c, 10'000'000), "");
  c.held.push_back({});
  c.held[0].utime = int64_t{1} << 62;
  EXPECT_NE(UntrustedCheckpointTime(c, 10'000'000).find("held[0].utime"), std::string::npos);
  c.held.clear();
  c.utime = int64_t{1} << 62;
  EXPECT_NE(UntrustedCheckpointTime(c, 10'000'000).find("utime"), std::string::npos);
}

}  // namespace
}  // namespace rcal::transport
