// The arm test matrix of issue 12, item 1: on every arm of tests/data/arms (and the real UR10,
// config/robots/ur10.urdf), full pose and positions only, calibration reaches the noise floor
// against the simulator's truth, and `rcal analyze` names nothing on clean data. Runs the commands
// as a user runs them (`rcal calibration-sweep`, `rcal detection-sweep`) and reads their --json
// figures; and checks the sweep's seeding (tools/rcal/calibration_sweep).
#include "calibration_sweep.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "rcal_cli.hpp"

namespace {

namespace fs = std::filesystem;
using rcal::tool::testing::ReadJson;
using rcal::tool::testing::Result;
using rcal::tool::testing::RunRcal;
std::filesystem::path TempDir(const std::string& name) {
  return rcal::tool::testing::TempDir("sweep", name);
}
using nlohmann::json;
using rcal::tool::CalibrationSeed;

struct Arm {
  std::string name, file;
};
// The matrix: published geometry, hand-written (each file's comment gives its source).
const std::vector<Arm> kArms = {
    {"grb3016", "tests/data/arms/grb3016.urdf"},
    {"ur10", "config/robots/ur10.urdf"},
    {"kr6_like", "tests/data/arms/kr6_like.urdf"},
    {"ur5e_like", "tests/data/arms/ur5e_like.urdf"},
    {"panda_like", "tests/data/arms/panda_like.urdf"},
    {"irb120_like", "tests/data/arms/irb120_like.urdf"},
};

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// A run's seed is a function of (robot, mode, seed index) alone, and distinct runs get distinct
// seeds.
TEST(CalibrationSweep, EveryRunHasItsOwnSeed) {
  EXPECT_EQ(CalibrationSeed("kr6_like", true, 7), CalibrationSeed("kr6_like", true, 7));
  std::set<std::uint64_t> seeds;
  int n = 0;
  for (const auto& arm : kArms)
    for (bool position_only : {false, true})
      for (unsigned s = 0; s < 1000; ++s) {
        seeds.insert(CalibrationSeed(arm.name, position_only, s));
        ++n;
      }
  EXPECT_EQ(static_cast<int>(seeds.size()), n);
}

// The command's figures do not depend on --jobs or on which other seeds run: seeds 1–3 on one
// thread, on two, and seed 3 alone give the same runs (CPU time aside).
TEST(CalibrationSweep, RunsDoNotDependOnJobsOrOnOtherRuns) {
  const fs::path d = TempDir("jobs");
  const std::string common =
      "calibration-sweep --robot tests/data/arms/kr6_like.urdf --position-only --poses 40 "
      "--test-poses 10 ";
  for (const auto& [args, out] :
       {std::pair{"--seeds 3 --jobs 1", "a.json"}, std::pair{"--seeds 3 --jobs 2", "b.json"},
        std::pair{"--seeds 1 --first-seed 3", "c.json"}}) {
    const Result r = RunRcal(common + args + " --json " + (d / out).string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  json a = ReadJson(d / "a.json")["runs"], b = ReadJson(d / "b.json")["runs"],
       c = ReadJson(d / "c.json")["runs"];
  ASSERT_EQ(a.size(), 3u);
  ASSERT_EQ(c.size(), 1u);
  for (json* runs : {&a, &b, &c})
    for (auto& run : *runs) run.erase("cpu_s");
  EXPECT_EQ(a, b);
  EXPECT_EQ(a[2], c[0]);
  // Distinct seeds give distinct data (the figures are not all one run's).
  EXPECT_NE(a[0]["test_mean_position_error_m"], a[1]["test_mean_position_error_m"]);
  fs::remove_all(d);
}

// Issue 12, item 1, on every arm and both modes (0.5 mm / 1 mrad geometric errors, random set-up
// frames, 200 calibration and 100 test poses, 0.05 mm / 0.05° noise, starting noise 2× wrong):
// - the identified count equal to the rank of the identification Jacobian at the truth;
// - the estimated noise within 1.1× of the truth on every seed, the median within 1.05×
//   (measured over 20 seeds per arm and mode: 0.93–1.07, medians 0.98–1.02);
// - LM converged (stopped before its 100-iteration cap): with a base set chosen ill-conditioned,
//   it crept along a nearly flat direction for all 100 iterations on 27 of 120 positions-only
//   runs, drifting |x| to 1.3 (now ≤ 0.01), up to 30 χ² units above the optimum and 1.7× its
//   test error;
// - the test-pose position error against the truth within 10 % of its Cramér–Rao prediction, as
//   a median over all runs. A single calibration's error is one draw of the estimate's scatter
//   over ~rank directions, so it fluctuates around its Cramér–Rao mean by roughly 1/√(2·rank),
//   13 % at rank 30: measured over the 20-seed matrix, 0.59–1.50 (sd 0.145), every extreme at the
//   optimum LM reaches from the truth. Single seeds are held only to a band that catches a fit
//   that failed outright; orientation (a few directions carry it: sd 0.31 per seed, pooled median
//   1.01 over 120 runs) to 25 % as a median.
TEST(CalibrationSweep, EveryArmReachesItsNoiseFloor) {
  constexpr int kSeeds = 5;
  const fs::path d = TempDir("matrix");
  std::vector<double> position_ratios, orientation_ratios;
  for (const auto& arm : kArms)
    for (bool position_only : {false, true}) {
      const std::string mode = position_only ? "positions only" : "full pose";
      SCOPED_TRACE(arm.name + ", " + mode);
      const fs::path out = d / (arm.name + (position_only ? "_pos.json" : "_full.json"));
      const Result r =
          RunRcal("calibration-sweep --robot " + arm.file + " --seeds " + std::to_string(kSeeds) +
                  (position_only ? " --position-only" : "") + " --json " + out.string());
      ASSERT_EQ(r.exit_code, 0) << r.output;
      const json j = ReadJson(out);
      std::vector<double> noise;
      for (const auto& run : j["runs"]) {
        const unsigned seed = run["seed_index"];
        SCOPED_TRACE("seed " + std::to_string(seed));
        EXPECT_EQ(run["identified"], run["rank_at_truth"]);
        EXPECT_LT(run["lm_iterations"].get<int>(), 100);
        std::vector<double> ratios = {run["position_noise_ratio"].get<double>()};
        if (!position_only) ratios.push_back(run["orientation_noise_ratio"].get<double>());
        for (double k : ratios) {
          EXPECT_LT(k, 1.1);
          EXPECT_GT(k, 1.0 / 1.1);
          noise.push_back(k);
        }
        const double cr = run["position_error_over_cramer_rao"];
        EXPECT_GT(cr, 0.5);
        EXPECT_LT(cr, 1.7);
        position_ratios.push_back(cr);
        if (!position_only)
          orientation_ratios.push_back(run["orientation_error_over_cramer_rao"].get<double>());
      }
      const double m = Median(noise);
      EXPECT_LT(m, 1.05);
      EXPECT_GT(m, 1.0 / 1.05);
    }
  ASSERT_EQ(position_ratios.size(), kArms.size() * 2 * kSeeds);
  const double m = Median(position_ratios), mo = Median(orientation_ratios);
  EXPECT_GT(m, 0.9);
  EXPECT_LT(m, 1.1);
  EXPECT_GT(mo, 0.75);
  EXPECT_LT(mo, 1.25);
  std::printf("test / Cramér–Rao, median over %zu runs: position %.3f, orientation %.3f\n",
              position_ratios.size(), m, mo);
  fs::remove_all(d);
}

// `rcal analyze` names nothing on clean data of any arm, full pose or positions only (the issue
// asks ≤ 1 % over ≥ 100 seeds per arm: the README table, 0 / 100 everywhere; here 5 seeds per arm
// and mode).
TEST(CalibrationSweep, AnalyzeNamesNothingOnCleanDataOfAnyArm) {
  constexpr int kSeeds = 5;
  const fs::path d = TempDir("clean");
  for (const auto& arm : kArms)
    for (bool position_only : {false, true}) {
      SCOPED_TRACE(arm.name + (position_only ? ", positions only" : ", full pose"));
      const fs::path out = d / "clean.json";
      const Result r =
          RunRcal("detection-sweep --robot " + arm.file + " --effects clean --seeds " +
                  std::to_string(kSeeds) + (position_only ? "" : " --orientation-sigma-deg 0.05") +
                  " --json " + out.string());
      ASSERT_EQ(r.exit_code, 0) << r.output;
      const json j = ReadJson(out);
      EXPECT_EQ(j["clean_runs"], kSeeds);
      EXPECT_EQ(j["false_positives"], 0) << j["clean_cells"].dump();
    }
  fs::remove_all(d);
}

}  // namespace
