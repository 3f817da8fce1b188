// Effect lists in analysis.json: what EffectsJson writes ParseAnalysisEffects reads back to the
// same effects and values (every cause), and each malformed entry is refused naming its key.
#include "rcal/io/effects_json.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "io_test_util.hpp"
#include "rcal/io/robot_urdf.hpp"

namespace rcal::io {
namespace {

using kinematics::Effect;
using kinematics::EffectCause;
using nlohmann::json;

const kinematics::KinematicModel& Grb() {
  static const auto robot = LoadRobot(testing::SourceDir() / "config/robots/grb3016.yaml");
  return robot.model;
}

std::vector<Effect> EveryCause() {
  Effect periodic{EffectCause::kJointPeriodic, 2, 2};
  Effect drift{EffectCause::kThermal};
  drift.thermal_source = Effect::ThermalSource::kTime;
  drift.reference = 30.0;
  return {{EffectCause::kJointCompliance, 1},
          periodic,
          {EffectCause::kJointScale, 3},
          {EffectCause::kBacklash, 4},
          drift};
}

TEST(EffectsJson, WrittenEffectsReadBackExactly) {
  const kinematics::ExtendedModel ext(Grb(), EveryCause());
  Eigen::VectorXd e(ext.num_effect_params()), sigma(ext.num_effect_params());
  for (int i = 0; i < e.size(); ++i) {
    e(i) = 1e-5 * (i + 1) * (i % 2 ? -1 : 1);
    sigma(i) = 1e-7 * (i + 1);
  }
  const json doc = {{"effects", EffectsJson(ext, e, sigma)}};
  // Through text, as a file would carry it.
  const AnalysisEffects back = ParseAnalysisEffects(json::parse(doc.dump()), Grb());
  ASSERT_EQ(back.effects.size(), ext.effects().size());
  for (size_t k = 0; k < back.effects.size(); ++k) {
    EXPECT_TRUE(back.effects[k].SameAs(ext.effects()[k])) << k;
    EXPECT_EQ(back.effects[k].reference, ext.effects()[k].reference) << k;
  }
  EXPECT_EQ(back.values, e);
  EXPECT_TRUE(std::isnan(back.link_density_kg_per_m));  // not said: the caller's default
  json with_density = doc;
  with_density["link_density_kg_per_m"] = 12.5;
  EXPECT_EQ(ParseAnalysisEffects(with_density, Grb()).link_density_kg_per_m, 12.5);
  EXPECT_EQ(doc["effects"][0]["joints"][0], Grb().joints()[1].name);
  EXPECT_EQ(doc["effects"][1]["values"][1]["unit"], "rad");
}

TEST(EffectsJson, MalformedEntriesNameTheirKey) {
  const auto parse = [](const std::string& text) {
    try {
      ParseAnalysisEffects(json::parse(text), Grb());
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  const std::string j2 = Grb().joints()[1].name;
  EXPECT_EQ(parse(R"({"no_effects": []})"), "effects: missing");
  EXPECT_NE(parse(R"({"effects": [{"cause": "gyro_bias", "joints": [], "values": []}]})")
                .find("effects[0].cause: 'gyro_bias' is not a pose-level effect"),
            std::string::npos);
  EXPECT_NE(
      parse(
          R"({"effects": [{"cause": "joint_scale", "joints": ["elbow9"], "values": [{"value": 1e-4}]}]})")
          .find("effects[0].joints: no joint 'elbow9'"),
      std::string::npos);
  EXPECT_NE(parse(R"({"effects": [{"cause": "joint_periodic", "joints": [")" + j2 +
                  R"("], "harmonic": 3, "values": [{"value": 0}, {"value": 0}]}]})")
                .find("effects[0].harmonic: 1 or 2"),
            std::string::npos);
  EXPECT_NE(parse(R"({"effects": [{"cause": "joint_scale", "joints": [")" + j2 +
                  R"("], "values": [{"value": "x"}]}]})")
                .find("effects[0].values[0].value: not a finite number"),
            std::string::npos);
  EXPECT_NE(
      parse(
          R"({"effects": [{"cause": "thermal", "joints": [], "source": "sun", "reference": 20, "values": [{"value": 0}]}]})")
          .find("effects[0].source: 'sun'"),
      std::string::npos);
  testing::ScratchDir dir;
  EXPECT_THROW(ReadAnalysisEffects((dir.path() / "missing.json").string(), Grb()),
               std::runtime_error);
}

}  // namespace
}  // namespace rcal::io
