// Shared by the integration tests that run ekf_identifier: which poses it used, and its estimate
// against cell::OnlineIdentification (the process's own pose-by-pose logic) run in the test, from
// scratch, on exactly those poses. The same code on the same bits gives the same answer; only the
// checkpoint's round trip (exact: shortest round-trip doubles) lies between, so whatever the
// timing of a run (a kill, a pose lost while the identifier was down) the two agree to
// kSameAsOffline.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "rcal/cell/online_identification.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/transport/adapters.hpp"
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
      std::string error;
      const auto z = transport::FromMessage(m, &error);
      if (z && z->q == h.q && z->p_WM_W == h.p_WM_W) match = &m;
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

/// The identifier's final estimate `params` against OnlineIdentification(`cell`) on `used` in
/// order: equal to kSameAsOffline, value by value and σ by σ.
inline void ExpectIdentifierEqualsOffline(const io::BuiltCell& cell,
                                          const std::vector<pose_measurement_t>& used,
                                          const kinematic_params_t& params,
                                          const std::string& what) {
  cell::OnlineIdentification id(cell);
  for (const auto& m : used) {
    std::string error;
    const auto z = transport::FromMessage(m, &error);
    ASSERT_TRUE(z) << error;
    const auto out = id.Add({*z, m.utime, m.pose_index});
    ASSERT_TRUE(out.rejected.empty()) << what << ": " << out.rejected;
  }
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

}  // namespace rcal::integration
