// Shared by the integration tests that run ekf_identifier: which poses it used, and its estimate
// against cell::OnlineIdentification (the process's own pose-by-pose logic) run in the test, from
// scratch, on exactly those poses. The same code on the same bits gives the same answer; only the
// checkpoint's round trip (exact: shortest round-trip doubles) lies between, so whatever the
// timing of a run (a kill, a pose lost while the identifier was down) the two agree to
// kSameAsOffline.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "rcal/cell/online_identification.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/checkpoint_json.hpp"

namespace rcal::integration {

/// |identifier − offline| allowed for each value and σ [m | rad].
inline constexpr double kSameAsOffline = 1e-9;

// The poses the identifier used: its final checkpoint's accepted poses, each matched to the
// published POSE_MEASUREMENT it came from (bit-equal joints and position).
inline std::vector<pose_measurement_t> UsedPoses(const std::filesystem::path& checkpoint,
                                                 const std::vector<pose_measurement_t>& published) {
  std::vector<pose_measurement_t> used;
  transport::CheckpointFile f;
  try {
    f = transport::LoadCheckpoint(checkpoint);
  } catch (const std::exception& e) {
    ADD_FAILURE() << e.what();
    return used;
  }
  EXPECT_TRUE(f.held.empty()) << f.held.size() << " poses still held for the set-up guess";
  for (size_t k = 0; k < f.checkpoint.history.size(); ++k) {
    const auto& h = f.checkpoint.history[k];
    const pose_measurement_t* match = nullptr;
    for (const auto& m : published) {
      // The message's own fields (its marker id is the cell's, which only the model maps).
      if (m.num_joints == h.q.size() && m.q.size() == static_cast<size_t>(h.q.size()) &&
          Eigen::Map<const Eigen::VectorXd>(m.q.data(), m.num_joints) == h.q &&
          Eigen::Vector3d(m.p[0], m.p[1], m.p[2]) == h.p_WM_W)
        match = &m;
    }
    EXPECT_NE(match, nullptr) << "accepted pose " << k << " is none of the published poses";
    if (match) used.push_back(*match);
  }
  return used;
}

/// The demo's cell file (config/cells/grb3016.yaml), as the processes under test load it.
inline const io::BuiltCell& DemoCell() {
  static const io::BuiltCell cell = io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml");
  return cell;
}

/// OnlineIdentification(`cell`) run on `used` in order, each message decoded against the cell's
/// model; a pose it refuses is a test failure. (A unique_ptr: the identification holds its cell.)
/// With `effects`, the extended identification (each pose under its logged context).
inline std::unique_ptr<cell::OnlineIdentification> Replayed(
    const io::BuiltCell& cell, const std::vector<pose_measurement_t>& used,
    const std::vector<kinematics::Effect>& effects = {}) {
  auto id = std::make_unique<cell::OnlineIdentification>(cell, effects);
  for (const auto& m : used) {
    std::string error;
    const auto z = transport::FromMessage(m, &error, &cell.model);
    EXPECT_TRUE(z) << error;
    const auto context = transport::ContextFromMessage(m, &error);
    EXPECT_TRUE(context) << error;
    if (!z || !context) continue;
    const auto out = id->Add({*z, m.utime, m.pose_index, *context});
    EXPECT_TRUE(out.rejected.empty()) << out.rejected;
  }
  return id;
}

/// The identifier's final estimate `params` against OnlineIdentification(`cell`) on `used` in
/// order: equal to kSameAsOffline, value by value and σ by σ.
inline void ExpectIdentifierEqualsOffline(const io::BuiltCell& cell,
                                          const std::vector<pose_measurement_t>& used,
                                          const kinematic_params_t& params,
                                          const std::string& what) {
  SCOPED_TRACE(what);
  const auto replayed = Replayed(cell, used);
  const cell::OnlineIdentification& id = *replayed;
  const kinematic_params_t off =
      transport::ToKinematicParams(id.ekf(), id.model().name(), params.utime);
  EXPECT_EQ(params.poses_used, static_cast<int>(used.size())) << what;
  EXPECT_EQ(off.poses_used, params.poses_used) << what;
  ASSERT_EQ(off.num_params, params.num_params) << what;
  double worst = 0;
  for (int i = 0; i < off.num_params; ++i) {
    EXPECT_EQ(off.names[i], params.names[i]);
    EXPECT_EQ(off.identified[i], params.identified[i]) << off.names[i];
    EXPECT_NEAR(params.values[i], off.values[i], kSameAsOffline) << what << " " << off.names[i];
    EXPECT_NEAR(params.sigmas[i], off.sigmas[i], kSameAsOffline) << what << " " << off.names[i];
    worst = std::max({worst, std::abs(params.values[i] - off.values[i]),
                      std::abs(params.sigmas[i] - off.sigmas[i])});
  }
  std::printf("%s: identifier vs offline identification of its %zu poses: max difference %.3g\n",
              what.c_str(), used.size(), worst);
}

/// `poses` written as an LCM log (the real file format: one POSE_MEASUREMENT event each, in order)
/// in `dir`, read by `rcal calibrate-log LOG --cell CELL` (the command at `rcal`): its poses and
/// every parameter value equal the identifier's final `params` (kSameAsOffline).
inline void ExpectCalibrateLogEqualsIdentifier(const std::string& rcal,
                                               const std::filesystem::path& dir,
                                               const std::string& cell_file,
                                               const std::vector<pose_measurement_t>& poses,
                                               const kinematic_params_t& params,
                                               const std::string& effects_file = "") {
  const std::filesystem::path log = dir / "poses.lcmlog";
  {
    lcm::LogFile f(log.string(), "w");
    int64_t event = 0;
    for (const auto& m : poses) {
      std::vector<uint8_t> buf(static_cast<size_t>(m.getEncodedSize()));
      m.encode(buf.data(), 0, static_cast<int>(buf.size()));
      lcm::LogEvent ev;
      ev.eventnum = event++;
      ev.timestamp = m.utime;
      ev.channel = transport::channels::kPoseMeasurement;
      ev.datalen = static_cast<int32_t>(buf.size());
      ev.data = buf.data();
      ASSERT_EQ(f.writeEvent(&ev), 0);
    }
  }
  const std::filesystem::path json = dir / "calibrate_log.json";
  const std::string cmd = rcal + " calibrate-log " + log.string() + " --cell " + cell_file +
                          (effects_file.empty() ? "" : " --effects " + effects_file) + " --json " +
                          json.string() + " > " + (dir / "calibrate_log.out").string();
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const auto j = nlohmann::json::parse(std::ifstream(json));
  EXPECT_EQ(j["poses_accepted"].get<int>(), params.poses_used);
  ASSERT_EQ(static_cast<int>(j["parameters"].size()), params.num_params);
  double worst = 0;
  for (int i = 0; i < params.num_params; ++i) {
    const auto& p = j["parameters"][i];
    EXPECT_EQ(p["name"].get<std::string>(), params.names[i]);
    const auto& value = p.contains("value_m") ? p["value_m"] : p["value_rad"];
    EXPECT_NEAR(value.get<double>(), params.values[i], kSameAsOffline) << params.names[i];
    worst = std::max(worst, std::abs(value.get<double>() - params.values[i]));
  }
  // The effect parameters too (--effects): the JSON's `effects` entries, values in model order.
  std::vector<double> effects;
  if (j.contains("effects"))
    for (const auto& e : j["effects"])
      for (const auto& v : e["values"]) effects.push_back(v["value"].get<double>());
  ASSERT_EQ(static_cast<int>(effects.size()), params.num_effect_params);
  for (int k = 0; k < params.num_effect_params; ++k) {
    EXPECT_NEAR(effects[k], params.effect_values[k], 1e-6 * params.effect_sigmas[k])
        << params.effect_names[k];
  }
  std::printf("rcal calibrate-log on the %zu poses vs the identifier: max difference %.3g\n",
              poses.size(), worst);
}

}  // namespace rcal::integration
