// The rcal command line end to end: each command as a user runs it, figures read back from its
// --json output and checked against the issue's targets and independent facts.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "rcal_cli.hpp"

namespace {

namespace fs = std::filesystem;
using rcal::tool::testing::ReadJson;
using rcal::tool::testing::Result;
using rcal::tool::testing::RunRcal;
std::filesystem::path TempDir(const std::string& name) {
  return rcal::tool::testing::TempDir("cli", name);
}
using nlohmann::json;

// Every leaf of `golden` is in `got` with the same value (numbers to 1e-6 relative, 1e-15
// absolute); keys `got` has beyond the golden file are allowed (new outputs).
void ExpectGolden(const json& got, const json& golden, const std::string& path) {
  if (golden.is_object()) {
    for (const auto& [key, value] : golden.items()) {
      if (!got.is_object() || !got.contains(key)) {
        ADD_FAILURE() << path << "/" << key << ": missing from the output";
        continue;
      }
      ExpectGolden(got[key], value, path + "/" + key);
    }
  } else if (golden.is_array()) {
    ASSERT_TRUE(got.is_array() && got.size() == golden.size()) << path << ": array size";
    for (size_t i = 0; i < golden.size(); ++i)
      ExpectGolden(got[i], golden[i], path + "[" + std::to_string(i) + "]");
  } else if (golden.is_number_float()) {
    ASSERT_TRUE(got.is_number()) << path;
    const double a = got.get<double>(), b = golden.get<double>();
    EXPECT_NEAR(a, b, 1e-6 * std::abs(b) + 1e-15) << path;
  } else {
    EXPECT_EQ(got, golden) << path;
  }
}

TEST(RcalCli, ExperimentPaperMeetsTheNoiseLimitAndEkfAgreesWithLm) {
  const fs::path d = TempDir("paper");
  const Result r = RunRcal("experiment paper --out " + (d / "out").string() + " --json " +
                           (d / "r.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "r.json");
  EXPECT_EQ(j["rank"], 25);
  EXPECT_EQ(j["num_params"], 28);
  // Issue 2: after-calibration test error within 1.5x of the Cramér–Rao figure, EKF ≈ LM.
  EXPECT_LE(j["ekf_to_crb_ratio"].get<double>(), 1.5);
  EXPECT_LE(j["lm_to_crb_ratio"].get<double>(), 1.5);
  EXPECT_LT(j["ekf_lm_max_difference_sigma"].get<double>(), 0.1);
  // Table 3 moves the tool by centimetres before calibration (NOTES.md: ~32 mm over the ranges).
  EXPECT_GT(j["nominal"]["test_truth"]["mean_position_error_m"].get<double>(), 0.015);
  EXPECT_EQ(j["ekf"]["rejected_poses"], 0);
  for (const char* f : {"report.md", "convergence.png", "poses.png", "parameters.png"})
    EXPECT_TRUE(fs::exists(d / "out" / f)) << f;
  // Golden output: every seed-1 figure the README states for this experiment (the testing-set
  // table, the Table 2 layout against the measured poses, the Cramér–Rao ratio, EKF ≈ LM) is
  // tests/tools/golden/experiment_paper_seed1.json, reproduced to 1e-6. Regenerate with
  //   rcal experiment paper --json F   (then drop F's ekf.median_update_time_s)
  ExpectGolden(j, ReadJson(RCAL_SOURCE_DIR "/tests/tools/golden/experiment_paper_seed1.json"), "");
  // Deterministic: the same seed gives the same figures.
  const Result again = RunRcal("experiment paper --out " + (d / "out2").string() + " --json " +
                               (d / "r2.json").string());
  ASSERT_EQ(again.exit_code, 0);
  json a = ReadJson(d / "r2.json"), b = j;
  a["ekf"].erase("median_update_time_s");  // wall-clock time is the only thing that may differ
  b["ekf"].erase("median_update_time_s");
  EXPECT_EQ(a, b);
}

TEST(RcalCli, IdentifiabilityRanksOfTheGrb3016) {
  const fs::path d = TempDir("ident");
  struct Case {
    std::string args;
    int rank;
  };
  // The paper's arm as its file describes it (--frames none: no set-up frames).
  for (const Case& c : {Case{"--frames none", 25}, Case{"--frames none --position-only", 22},
                        Case{"--frames none --tool 0,0,0,0", 23},
                        Case{"--frames none --tool 0,0,0,0 --position-only", 19}}) {
    const Result r = RunRcal("identifiability " + c.args + " --json " + (d / "i.json").string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_EQ(ReadJson(d / "i.json")["rank"], c.rank) << c.args;
  }
  const Result r = RunRcal("identifiability --frames none");
  EXPECT_NE(r.output.find("d3 and d2 enter only as d3 - d2"), std::string::npos) << r.output;
}

// Issue 12, item 3: identifiability takes the robot, tip, base link and set-up frames calibrate
// takes and counts what calibrate identifies: a 6R URDF arm in a cell (world ← base, a marker)
// 4·6 + 6 − 3 = 27 with positions only, + 3 per further marker, 30 with full poses (flange → IMU),
// 33 when the orientation is an IMU's own earth frame; and at a dataset's own poses the count of
// `rcal calibrate` on it (the real UR10: 30, tests/tools/golden/calibrate_ur10.json).
TEST(RcalCli, IdentifiabilityCountsWhatCalibrateIdentifies) {
  const fs::path d = TempDir("ident_cell");
  const std::string urdf = RCAL_SOURCE_DIR "/config/robots/ur10.urdf";
  const std::string data = RCAL_SOURCE_DIR "/data/figaroh_ur10/calibration.csv";
  struct Case {
    std::string args;
    int rank;
  };
  for (const Case& c :
       {Case{"--position-only", 27}, Case{"--position-only --markers 2", 30},
        Case{"--position-only --markers 3", 33}, Case{"", 30}, Case{"--earth-frame", 33},
        Case{"--tip wrist_2_link --position-only", 23}, Case{data, 30}}) {
    const Result r = RunRcal("identifiability --robot " + urdf + " " + c.args + " --json " +
                             (d / "i.json").string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const json j = ReadJson(d / "i.json");
    EXPECT_EQ(j["rank"], c.rank) << c.args;
    EXPECT_EQ(j["chain"]["base_link"], "world") << c.args;
  }
  const Result r = RunRcal("calibrate " + data + " --robot " + urdf + " --out " +
                           (d / "cal").string() + " --json " + (d / "c.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(ReadJson(d / "c.json")["num_identified"], 30);
}

TEST(RcalCli, CalibrateTheRealUr10) {
  const fs::path d = TempDir("ur10");
  const std::string data = RCAL_SOURCE_DIR "/data/figaroh_ur10/calibration.csv";
  const std::string urdf = RCAL_SOURCE_DIR "/config/robots/ur10.urdf";
  json by_method;
  for (const std::string method : {"lm", "ekf"}) {
    const Result r =
        RunRcal("calibrate " + data + " --robot " + urdf + " --method " + method + " --out " +
                (d / method).string() + " --json " + (d / (method + ".json")).string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const json j = ReadJson(d / (method + ".json"));
    EXPECT_EQ(j["num_poses"], 23);
    // Calibration must beat the nominal kinematics on the poses it fitted and on held-out poses.
    EXPECT_LT(j["fit_mean_position_error_m"].get<double>(),
              j["fit_nominal_mean_position_error_m"].get<double>());
    EXPECT_LT(j["test_mean_orientation_error_rad"].get<double>(),
              j["test_nominal_mean_orientation_error_rad"].get<double>());
    // A real UR10 is within millimetres of its URDF once the frames are known.
    EXPECT_LT(j["test_nominal_mean_position_error_m"].get<double>(), 0.01);
    EXPECT_TRUE(fs::exists(d / method / "robot_calibrated.urdf"));
    EXPECT_TRUE(fs::exists(d / method / "robot_calibrated.yaml"));
    by_method[method] = j;
  }
  EXPECT_NEAR(by_method["lm"]["test_mean_position_error_m"].get<double>(),
              by_method["ekf"]["test_mean_position_error_m"].get<double>(), 2e-5);

  // Golden output: the README's UR10 table (fitted, 5-fold and leave-one-out rows, LM and EKF)
  // is tests/tools/golden/calibrate_ur10.json, reproduced to 1e-6 (the fits and the fold
  // assignment are deterministic). Each entry M_folds_K is the --json output of
  //   rcal calibrate DATA --robot URDF --method M --folds K   without its "data" and "robot" paths.
  const json golden = ReadJson(RCAL_SOURCE_DIR "/tests/tools/golden/calibrate_ur10.json");
  for (const std::string method : {"lm", "ekf"})
    for (const int folds : {5, 23}) {
      const std::string key = method + "_folds_" + std::to_string(folds);
      const fs::path out = d / (key + ".json");
      const Result r = RunRcal("calibrate " + data + " --robot " + urdf + " --method " + method +
                               " --folds " + std::to_string(folds) + " --out " +
                               (d / key).string() + " --json " + out.string());
      ASSERT_EQ(r.exit_code, 0) << r.output;
      ExpectGolden(ReadJson(out), golden.at(key), key);
    }
}

// Issue 12, item 2: a simulated laser tracker with three reflectors on the tool (`marker`
// column, one row per reflector and stop), positions only. Each reflector gets its own offset;
// the folds keep the rows of a stop together; the report names the chain and each offset's frame;
// the calibrated URDF carries them as fixed joints. A reflector seen only in test rows needs its
// offset from somewhere, and is judged with it.
std::vector<std::vector<std::string>> ReadCsvRows(const fs::path& p,
                                                  std::vector<std::string>* comments) {
  std::ifstream in(p);
  std::vector<std::vector<std::string>> rows;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("#", 0) == 0) {
      comments->push_back(line);
      continue;
    }
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    rows.push_back(cells);
  }
  return rows;
}

TEST(RcalCli, CalibrateThreeReflectorsFromTheMarkerColumn) {
  const fs::path d = TempDir("markers");
  const std::string urdf = RCAL_SOURCE_DIR "/config/robots/ur10.urdf";
  const double truth[3][3] = {{0.10, 0.02, 0.05}, {-0.03, 0.09, 0.06}, {0.01, -0.07, 0.11}};
  std::string markers;
  for (int k = 0; k < 3; ++k)
    markers += " --marker " + std::to_string(k) + "=" + std::to_string(truth[k][0]) + "," +
               std::to_string(truth[k][1]) + "," + std::to_string(truth[k][2]);
  Result r = RunRcal("simulate --robot " + urdf + markers +
                     " --poses 60 --seed 4 --test-fraction 0.25 --out " +
                     (d / "data.csv").string() + " --truth-json " + (d / "truth.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("60 poses of ur10e (180 rows)"), std::string::npos) << r.output;
  // The whole dataset, k-fold (the set column dropped: every stop may be held out).
  std::vector<std::string> comments;
  auto rows = ReadCsvRows(d / "data.csv", &comments);
  const auto column = [&](const std::string& name) {
    return static_cast<int>(std::find(rows[0].begin(), rows[0].end(), name) - rows[0].begin());
  };
  const int set = column("set"), marker = column("marker");
  ASSERT_LT(set, static_cast<int>(rows[0].size()));
  ASSERT_LT(marker, static_cast<int>(rows[0].size()));
  const auto write = [&](const fs::path& p, bool with_set) {
    std::ofstream f(p);
    for (const auto& c : comments) f << c << "\n";
    for (const auto& row : rows) {
      bool first = true;
      for (size_t i = 0; i < row.size(); ++i)
        if (with_set || static_cast<int>(i) != set) {
          f << (first ? "" : ",") << row[i];
          first = false;
        }
      f << "\n";
    }
  };
  write(d / "all.csv", false);
  r = RunRcal("calibrate " + (d / "all.csv").string() + " --robot " + urdf + " --out " +
              (d / "out").string() + " --json " + (d / "r.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "r.json");
  EXPECT_EQ(j["num_poses"], 180);
  EXPECT_EQ(j["num_identified"], 33);  // 4·6 + 3·3 (test_identifiability)
  EXPECT_EQ(j["validation"], "5-fold (by configuration)");
  EXPECT_NEAR(j["position_noise_m"].get<double>() / 5e-5, 1.0, 0.1);
  EXPECT_EQ(j["chain"]["base_link"], "world");
  EXPECT_EQ(j["chain"]["tip_link"], "wrist_3_link");
  const json& fitted = j["setup_frames"]["tip_to_markers"];
  ASSERT_EQ(fitted.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(fitted[k]["id"], k);
    EXPECT_EQ(fitted[k]["source"], "fitted");
    // Within 2 mm of the truth: what is left is the arm's own error along its last axis, which
    // no marker can tell from its offset (the arm keeps its drawing there).
    for (int a = 0; a < 3; ++a)
      EXPECT_NEAR(fitted[k]["xyz_m"][a].get<double>(), truth[k][a], 2e-3) << k << " " << a;
  }
  for (const auto& p : j["parameters"])
    EXPECT_FALSE(p["frame"].get<std::string>().empty()) << p["name"];
  std::ifstream report(d / "out" / "report.md");
  const std::string md((std::istreambuf_iterator<char>(report)), {});
  EXPECT_NE(md.find("Chain: world → wrist_3_link (6 joints"), std::string::npos);
  EXPECT_NE(md.find("wrist_3_link → marker 2"), std::string::npos);
  std::ifstream urdf_out(d / "out" / "robot_calibrated.urdf");
  const std::string cal((std::istreambuf_iterator<char>(urdf_out)), {});
  for (const char* link : {"rcal_world", "rcal_marker\"", "rcal_marker_1", "rcal_marker_2"})
    EXPECT_NE(cal.find(link), std::string::npos) << link;

  // Marker 2 only in test rows: refused until its offset is given or measured at a stated
  // configuration (a row of it), then judged.
  int reference_row = 0;
  for (size_t i = 1; i < rows.size(); ++i) {
    if (rows[i][marker] == "2") {
      rows[i][set] = "test";
      if (reference_row == 0) reference_row = static_cast<int>(i);
    }
  }
  write(d / "split.csv", true);
  const std::string split = "calibrate " + (d / "split.csv").string() + " --robot " + urdf +
                            " --out " + (d / "split").string() + " --json " +
                            (d / "s.json").string();
  r = RunRcal(split);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("marker 2 appears only in test rows"), std::string::npos) << r.output;
  r = RunRcal(split + " --marker-reference 2=" + std::to_string(reference_row));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json s = ReadJson(d / "s.json");
  EXPECT_EQ(s["validation"], "cal/test split");
  EXPECT_NE(s["setup_frames"]["tip_to_markers"][2]["source"].get<std::string>().find(
                "measured at row " + std::to_string(reference_row)),
            std::string::npos);
  // Held-out rows (marker 2's with it) at the noise floor: 1.6σ per row, the reference's noise too.
  EXPECT_LT(s["test_mean_position_error_m"].get<double>(), 2.5 * 5e-5);
  r = RunRcal(split + " --marker-offset 2=" + std::to_string(truth[2][0]) + "," +
              std::to_string(truth[2][1]) + "," + std::to_string(truth[2][2]));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(ReadJson(d / "s.json")["setup_frames"]["tip_to_markers"][2]["source"],
            "given (--marker-offset)");
  // A reference for a marker that has calibration rows is refused: its offset is fitted.
  r = RunRcal(split + " --marker-reference 1=2");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("has calibration rows"), std::string::npos) << r.output;
}

// Positions only (a tracker without orientation): no orientation was measured, so calibrate
// prints no orientation error (it printed 0.000 / 0.000 on every line), the report's table says
// n/a, and the JSON has no orientation noise or errors.
TEST(RcalCli, CalibratePositionsOnlyPrintsNoOrientation) {
  const fs::path d = TempDir("positions_only");
  Result r = RunRcal("simulate --robot config/robots/ur10.urdf --poses 40 --seed 2 --out " +
                     (d / "data.csv").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunRcal("calibrate " + (d / "data.csv").string() + " --robot config/robots/ur10.urdf --out " +
              (d / "out").string() + " --json " + (d / "r.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string summary = r.output.substr(r.output.find("rcal calibrate —"));
  EXPECT_NE(summary.find("positions only: no orientation"), std::string::npos) << summary;
  EXPECT_EQ(summary.find("orientation mean/max"), std::string::npos) << summary;
  EXPECT_EQ(summary.find("0.000 / 0.000"), std::string::npos) << summary;
  EXPECT_EQ(r.output.find("0.000°"), std::string::npos) << r.output;
  const json j = ReadJson(d / "r.json");
  EXPECT_FALSE(j.contains("orientation_noise_rad"));
  EXPECT_FALSE(j.contains("test_mean_orientation_error_rad"));
  EXPECT_TRUE(j.contains("test_mean_position_error_m"));
  std::ifstream md(d / "out" / "report.md");
  const std::string report((std::istreambuf_iterator<char>(md)), {});
  EXPECT_NE(report.find("| n/a |"), std::string::npos) << report;
  EXPECT_NE(report.find("positions only: no orientation measured"), std::string::npos);
}

TEST(RcalCli, CalibrateRejectsBadFilesNamingTheProblem) {
  const fs::path d = TempDir("bad");
  {
    std::ofstream f(d / "missing.csv");
    f << "# no x column\nq1,q2,q3,q4,q5,q6,y,z\n0,0,0,0,0,0,1,2\n";
  }
  Result r =
      RunRcal("calibrate " + (d / "missing.csv").string() + " --robot config/robots/grb3016.yaml");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("'x'"), std::string::npos) << r.output;
  {
    std::ofstream f(d / "robot.yaml");
    f << "schema: rcal.robot/1\nname: bad\nconvention: dh\nlinks:\n  - {a: 0.1, alpah: 0, d: 0, "
         "theta: 0, joint: {name: j1, type: revolute, lower: -1, upper: 1}}\n";
  }
  r = RunRcal("identifiability --robot " + (d / "robot.yaml").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("alpah"), std::string::npos) << r.output;
  r = RunRcal("calibrate " + (d / "nope.csv").string() + " --robot config/robots/grb3016.yaml");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("nope.csv"), std::string::npos) << r.output;
}

}  // namespace

// Issue 4: the paper's experiment from raw sensor streams. The full chain (sensor streams → FQA
// + KFs → still windows → online EKF) recovers the identifiable parameters consistently with its
// own covariance (χ² test against the truth expressed on the base set, false-alarm rate 1e-3),
// the set-up frames, and makes peg-in-hole at least 10× more accurate than the nominal model;
// same seed, same numbers.
TEST(RcalCli, ExperimentPaperFromSensorStreams) {
  const fs::path d = TempDir("experiment_sensors");
  const Result r = RunRcal("experiment paper --sensors --no-sweep --out " + (d / "out").string() +
                           " --json " + (d / "a.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "a.json");
  ASSERT_EQ(j["num_cal_windows"].get<int>(), 50);
  ASSERT_EQ(j["num_test_windows"].get<int>(), 50);
  // χ²(k) quantile by Wilson–Hilferty (z the standard normal quantile; relative error < 0.2 %
  // at k = 32, < 1e-4 at k ≥ 240).
  const auto chi2_quantile = [](double z, double k) {
    const double h = 2.0 / (9.0 * k);
    return k * std::pow(1.0 - h + z * std::sqrt(h), 3);
  };
  // The exit code is one χ² test with a stated false-alarm rate (was: every |z| ≤ 3 over 32
  // parameters, which failed honest runs on ~8 % of seeds, e.g. seed 8: imu_rx at 3.97σ):
  // d² = eᵀ P⁻¹ e, e = EKF − truth on the base set, P the EKF's covariance, ~ χ²(32); the run
  // fails above χ²_0.999(32) = 62.5. Seed 1: d² 34.3. Seeds 1–50: mean 35.0, σ 10.3, max 56.4
  // (χ²(32): 32, 8): the EKF's covariance is ≈ 9 % optimistic (the windows' covariances are
  // estimated, NEES 6.32 for 6 below), so the honest false-alarm rate is ≈ 4e-3, not 1e-3. One
  // run of 32 dof catches a covariance 1.6× too small only 18 % of the time; the window NEES
  // band below catches it at the window level.
  const auto& cons = j["ekf"]["consistency"];
  const int k = static_cast<int>(j["parameters"].size());
  EXPECT_EQ(k, 32);
  EXPECT_EQ(cons["dof"].get<int>(), k);
  EXPECT_EQ(cons["false_alarm_rate"].get<double>(), 1e-3);
  EXPECT_NEAR(cons["limit"].get<double>(), chi2_quantile(3.0902, k), 0.3);  // Φ⁻¹(0.999)
  EXPECT_TRUE(cons["passed"].get<bool>());
  EXPECT_LE(cons["d2"].get<double>(), cons["limit"].get<double>());
  // Σz² of the reported parameters is what the report says (the marginal view of the same
  // errors; not the test, the parameters are correlated).
  double sum_z2 = 0;
  for (const auto& p : j["parameters"]) {
    const double z = (p["ekf"].get<double>() - p["true_base_equivalent"].get<double>()) /
                     p["ekf_sigma"].get<double>();
    sum_z2 += z * z;
  }
  EXPECT_NEAR(sum_z2, j["ekf"]["sum_z2"].get<double>(), 1e-9 * sum_z2);
  const auto& f = j["frames"];
  EXPECT_LT(f["base_position_error_m"].get<double>(), 2e-4);
  EXPECT_LT(f["base_rotation_error_rad"].get<double>(), 2e-4);
  EXPECT_LT(f["earth_rotation_error_rad"].get<double>(), 3e-4);  // magnetic north, raw truth
  EXPECT_LT(f["marker_position_error_m"].get<double>(), 2e-4);
  EXPECT_LT(f["imu_rotation_error_rad"].get<double>(), 3e-4);
  const auto& peg = j["peg"];
  EXPECT_EQ(peg["ik_failures"].get<int>(), 0);
  EXPECT_LE(10 * peg["calibrated_mean_position_error_m"].get<double>(),
            peg["nominal_mean_position_error_m"].get<double>());
  EXPECT_LE(10 * peg["calibrated_mean_orientation_error_rad"].get<double>(),
            peg["nominal_mean_orientation_error_rad"].get<double>());
  // Near what the noise allows, and the windows' covariance is honest.
  EXPECT_LT(j["ekf"]["test_truth"]["mean_position_error_m"].get<double>(),
            1.5 * j["crb_test_mean_position_error_m"].get<double>());
  // Window NEES: with a known covariance N·mean ~ χ²(6N), N windows (cal, test, peg-in-hole);
  // two-sided band at a false-alarm rate of 1e-3 (z = ±3.2905), the upper edge × 79/75: each
  // 3-dof block's covariance is estimated from ~80 raw samples, so a window's NEES is
  // Hotelling's T², mean 6·79/75 = 6.32. N = 148: [5.11, 7.35] (was (3, 10)); a covariance
  // 1.6× too small (≈ 10) or too large (≈ 3.9) fails. Seed 1: 6.37.
  const double n_windows = j["num_cal_windows"].get<double>() +
                           j["num_test_windows"].get<double>() +
                           j["num_extra_windows"].get<double>();
  EXPECT_EQ(n_windows, 148);
  EXPECT_GT(j["window_mean_nees"].get<double>(), chi2_quantile(-3.2905, 6 * n_windows) / n_windows);
  EXPECT_LT(j["window_mean_nees"].get<double>(),
            79.0 / 75.0 * chi2_quantile(3.2905, 6 * n_windows) / n_windows);

  // Golden output: every figure of seed 1 the README states (the tables of "From raw sensor
  // streams", frames, windows, peg-in-hole) is this run's JSON, committed in
  // tests/tools/golden/experiment_paper_sensors_seed1.json; every value in it must be reproduced
  // (relative 1e-6: the run is deterministic, the tolerance only absorbs a compiler's rounding).
  // A change that moves a figure must regenerate the file and the README with it:
  //   rcal experiment paper --sensors --no-sweep --json F   (then drop F's "time" object)
  ExpectGolden(
      j, ReadJson(RCAL_SOURCE_DIR "/tests/tools/golden/experiment_paper_sensors_seed1.json"), "");

  const Result again = RunRcal("experiment paper --sensors --no-sweep --out " +
                               (d / "out2").string() + " --json " + (d / "b.json").string());
  ASSERT_EQ(again.exit_code, 0) << again.output;
  json a = j, b = ReadJson(d / "b.json");
  a.erase("time");
  b.erase("time");
  EXPECT_EQ(a, b);
}

// The robustness sweep over seeds (issue 19): a reduced programme (20 + 20 stops), 2 seeds, two
// configurations. Each run has its own seed 10000·k + i (k the configuration's number): a
// configuration's runs are the same alone or beside others and with any number of jobs, and the
// baseline's run i is `rcal experiment paper --sensors --seed i` with the same programme.
TEST(RcalCli, ExperimentPaperSensorSweepOverSeeds) {
  const fs::path d = TempDir("sensor_sweep");
  const std::string programme = " --cal 20 --test 20";
  const Result r = RunRcal("experiment paper --sensors --sweep-seeds 2 --seed 2 --jobs 2" +
                           programme + " --sweep-configs poses-10,baseline --out " +
                           (d / "out").string() + " --json " + (d / "s.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("10th–90th percentile [mm]"), std::string::npos) << r.output;
  const json j = ReadJson(d / "s.json");
  EXPECT_EQ(j["seeds"], 2);
  ASSERT_EQ(j["configurations"].size(), 2u);
  const json& base = j["configurations"][0];
  const json& poses = j["configurations"][1];
  EXPECT_EQ(base["id"], "baseline");
  EXPECT_EQ(poses["id"], "poses-10");
  EXPECT_EQ(poses["settings"]["num_cal_poses"], 10);
  for (const json* c : {&base, &poses}) {
    ASSERT_EQ((*c)["runs"].size(), 2u);
    EXPECT_EQ((*c)["failed_runs"], 0);
    for (size_t i = 0; i < 2; ++i) {
      const json& run = (*c)["runs"][i];
      EXPECT_EQ(run["seed_index"], 2 + i);
      EXPECT_EQ(run["seed"], 10000 * (*c)["number"].get<int>() + 2 + i);
    }
    const json& e = (*c)["test_mean_position_error_m"];
    EXPECT_EQ(e["runs"], 2);
    EXPECT_LE(e["min"].get<double>(), e["p10"].get<double>());
    EXPECT_LE(e["p10"].get<double>(), e["median"].get<double>());
    EXPECT_LE(e["median"].get<double>(), e["p90"].get<double>());
    EXPECT_LE(e["p90"].get<double>(), e["max"].get<double>());
    const double a = (*c)["runs"][0]["test_mean_position_error_m"].get<double>(),
                 b = (*c)["runs"][1]["test_mean_position_error_m"].get<double>();
    EXPECT_DOUBLE_EQ(e["median"].get<double>(), 0.5 * (a + b));
    EXPECT_GT((*c)["crb_test_mean_position_error_m"]["median"].get<double>(), 0.0);
  }
  // Fewer calibration poses, a larger Cramér–Rao figure.
  EXPECT_GT(poses["crb_test_mean_position_error_m"]["median"].get<double>(),
            base["crb_test_mean_position_error_m"]["median"].get<double>());
  for (const char* f : {"report.md", "results.json", "sweep_seeds.png"})
    EXPECT_TRUE(fs::exists(d / "out" / f)) << f;

  const Result alone = RunRcal("experiment paper --sensors --sweep-seeds 2 --seed 2 --jobs 1" +
                               programme + " --sweep-configs poses-10 --out " +
                               (d / "alone").string() + " --json " + (d / "alone.json").string());
  ASSERT_EQ(alone.exit_code, 0) << alone.output;
  json runs_alone = ReadJson(d / "alone.json")["configurations"][0]["runs"],
       runs_beside = poses["runs"];
  for (auto* runs : {&runs_alone, &runs_beside})
    for (auto& run : *runs) {
      run.erase("wall_time_s");  // the only figures that may differ
      run.erase("cpu_time_s");
    }
  EXPECT_EQ(runs_alone, runs_beside);

  const Result single =
      RunRcal("experiment paper --sensors --no-sweep --no-peg --seed 3" + programme + " --out " +
              (d / "single").string() + " --json " + (d / "single.json").string());
  ASSERT_EQ(single.exit_code, 0) << single.output;
  const json js = ReadJson(d / "single.json");
  const json& run3 = base["runs"][1];
  EXPECT_EQ(run3["seed"], 3);
  EXPECT_DOUBLE_EQ(run3["test_mean_position_error_m"].get<double>(),
                   js["test_mean_position_error_m"].get<double>());
  EXPECT_DOUBLE_EQ(run3["crb_test_mean_position_error_m"].get<double>(),
                   js["crb_test_mean_position_error_m"].get<double>());

  const Result unknown = RunRcal(
      "experiment paper --sensors --sweep-seeds 1 --sweep-configs "
      "noise-3 --out " +
      (d / "bad").string());
  EXPECT_NE(unknown.exit_code, 0);
  EXPECT_NE(unknown.output.find("noise-3"), std::string::npos) << unknown.output;
}

// --- rcal calibrate --effects (the model rcal analyze selected) and --log (calibrate-log) ---

TEST(RcalCli, CalibrateFitsTheEffectsAnAnalysisFoundAndJudgesThemOnHeldOutPoses) {
  const fs::path d = TempDir("calibrate_effects");
  const std::string robot = " --robot config/robots/grb3016.yaml";
  const std::string data = (d / "data.csv").string();
  // A truth robot with a hidden compliance of j2, 0.05 mm noise, 30 % test poses.
  Result r = RunRcal("simulate" + robot +
                     " --effect joint_compliance:j2=4e-6 --poses 150 --seed 5 --test-fraction 0.3"
                     " --out " +
                     data + " --truth-json " + (d / "truth.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json truth = ReadJson(d / "truth.json");
  const double c_true = truth["effects"][0]["values"][0]["value"].get<double>();
  r = RunRcal("analyze " + data + robot + " --out " + (d / "analysis").string() + " --json " +
              (d / "analysis.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json analysis = ReadJson(d / "analysis.json");
  ASSERT_EQ(analysis["effects"].size(), 1u) << analysis["effects"].dump();
  ASSERT_EQ(analysis["effects"][0]["cause"], "joint_compliance");

  r = RunRcal("calibrate " + data + robot + " --effects " + (d / "analysis.json").string() +
              " --out " + (d / "cal").string() + " --json " + (d / "cal.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "cal.json");
  ASSERT_EQ(j["effects"].size(), 1u);
  const json& f = j["effects"][0];
  EXPECT_EQ(f["cause"], "joint_compliance");
  EXPECT_EQ(f["joints"], json::array({"j2"}));
  const double c = f["values"][0]["value"].get<double>(), sigma = f["values"][0]["sigma"];
  EXPECT_EQ(f["values"][0]["unit"], "rad/(N*m)");
  EXPECT_GT(sigma, 0.0);
  EXPECT_LT(std::abs(c - c_true), 3 * sigma) << c << " ± " << sigma << ", truth " << c_true;
  EXPECT_LT(sigma, 0.1 * std::abs(c_true));
  // Held-out on the test poses: the extended model at the noise (√3 · 0.05 mm RMS distance),
  // the geometric model well above it; the geometric figure is the plain calibration's.
  const double geo = j["test_geometric_rms_position_error_m"],
               ext = j["test_extended_rms_position_error_m"];
  EXPECT_EQ(j["validation"], "cal/test split");
  EXPECT_DOUBLE_EQ(geo, j["test_rms_position_error_m"].get<double>());
  EXPECT_LT(ext, 1.3 * std::sqrt(3.0) * 5e-5);
  EXPECT_GT(geo, 2.0 * ext);
  EXPECT_NEAR(j["test_extended_relative_gain"].get<double>(), 1.0 - ext / geo, 1e-12);
  // The analysis selected on the 110 cal rows only (selected_on): the test rows are unseen, so
  // this gain is independent of the selection.
  EXPECT_EQ(analysis["selected_on"]["rows"], 150);
  EXPECT_EQ(analysis["selected_on"]["rows_fitted"], 110);
  EXPECT_EQ(analysis["selected_on"]["row_fingerprints"].size(), 110u);
  EXPECT_EQ(j["test_extended_heldout_poses_seen_by_selection"], 0);
  EXPECT_TRUE(j["test_extended_gain_independent_of_selection"].get<bool>());
  EXPECT_EQ(j["extended_parameters"].size(), j["num_identified"].get<size_t>());
  EXPECT_TRUE(fs::exists(d / "cal" / "robot_calibrated_extended.yaml"));
  std::ifstream md(d / "cal" / "report.md");
  const std::string report((std::istreambuf_iterator<char>(md)), std::istreambuf_iterator<char>());
  EXPECT_NE(report.find("## Extended model"), std::string::npos);

  // An analysis that found nothing: the extended model is the geometric one.
  json none = analysis;
  none["effects"] = json::array();
  std::ofstream(d / "none.json") << none.dump();
  r = RunRcal("calibrate " + data + robot + " --effects " + (d / "none.json").string() + " --out " +
              (d / "cal0").string() + " --json " + (d / "cal0.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j0 = ReadJson(d / "cal0.json");
  EXPECT_TRUE(j0["effects"].empty());
  EXPECT_NEAR(j0["test_extended_rms_position_error_m"].get<double>(),
              j0["test_geometric_rms_position_error_m"].get<double>(), 1e-3 * geo);
}

// Issue 12, item 5: the same model read 6.4 % in analyze and 30.6 % in calibrate --effects. The
// analysis' gain is nested (the selection redone in each outer fold: folds that do not select
// the effect gain nothing); calibrate fits the fixed list the selection chose on these same poses
// in each fold, which the choice flatters. Here (GRB3016, periodic error of j3, 60 poses, no
// split): analyze 4.7 % nested, two of five outer folds selecting it; calibrate 14.6 %. Calibrate
// must say its gain is not nested, and the analysis must state the non-nested figure too (the
// same folds: it equals calibrate's up to the linearisation).
TEST(RcalCli, CalibrateEffectsLabelsAGainThatIsNotNested) {
  const fs::path d = TempDir("calibrate_effects_nested");
  const std::string robot = " --robot config/robots/grb3016.yaml";
  const std::string data = (d / "data.csv").string();
  Result r = RunRcal("simulate" + robot +
                     " --effect joint_periodic:j3=2e-4,0 --poses 60 --seed 1 --out " + data);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunRcal("analyze " + data + robot + " --out " + (d / "analysis").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  json analysis = ReadJson(d / "analysis" / "analysis.json");
  ASSERT_EQ(analysis["effects"].size(), 1u) << analysis["effects"].dump();
  const json& gain = analysis["gain"];
  EXPECT_TRUE(gain["nested"].get<bool>());
  EXPECT_EQ(gain["outer_selections"].size(), 5u);
  EXPECT_EQ(analysis["effects"][0]["outer_folds_selecting"], 2);
  EXPECT_EQ(analysis["selected_on"]["rows_fitted"], 60);
  EXPECT_EQ(analysis["selected_on"]["row_fingerprints"].size(), 60u);

  r = RunRcal("calibrate " + data + robot + " --effects " +
              (d / "analysis" / "analysis.json").string() + " --out " + (d / "cal").string() +
              " --json " + (d / "cal.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "cal.json");
  EXPECT_EQ(j["validation"], "5-fold");
  EXPECT_FALSE(j["test_extended_gain_independent_of_selection"].get<bool>());
  EXPECT_EQ(j["test_extended_heldout_poses_seen_by_selection"], 60);
  EXPECT_NE(j["test_extended_gain_note"].get<std::string>().find("NOT NESTED"), std::string::npos);
  EXPECT_DOUBLE_EQ(j["analysis_relative_gain"].get<double>(), gain["relative_gain"].get<double>());
  EXPECT_NE(r.output.find("NOT NESTED"), std::string::npos) << r.output;
  std::ifstream md(d / "cal" / "report.md");
  const std::string report((std::istreambuf_iterator<char>(md)), std::istreambuf_iterator<char>());
  EXPECT_NE(report.find("NOT NESTED"), std::string::npos);
  // The numbers behind the disagreement: the nested gain is well below calibrate's, and the
  // analysis' non-nested figure (same folds, fixed list) is calibrate's within 2 % (the
  // analysis linearises around its base fit, calibrate refits each fold from scratch).
  const double cal_gain = j["test_extended_relative_gain"].get<double>();
  std::printf("analyze nested gain %.3f, calibrate --effects %.3f\n",
              gain["relative_gain"].get<double>(), cal_gain);
  EXPECT_LT(gain["relative_gain"].get<double>(), 0.5 * cal_gain);
  EXPECT_NEAR(gain["heldout_rms_after_not_nested_m"].get<double>(),
              j["test_extended_rms_position_error_m"].get<double>(),
              0.02 * j["test_extended_rms_position_error_m"].get<double>());

  // An analysis.json that does not record what it selected on (older files): not known.
  analysis.erase("selected_on");
  std::ofstream(d / "old.json") << analysis.dump();
  r = RunRcal("calibrate " + data + robot + " --effects " + (d / "old.json").string() + " --out " +
              (d / "cal_old").string() + " --json " + (d / "cal_old.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json jo = ReadJson(d / "cal_old.json");
  EXPECT_FALSE(jo["test_extended_gain_independent_of_selection"].get<bool>());
  EXPECT_EQ(jo["test_extended_heldout_poses_seen_by_selection"], -1);
  EXPECT_NE(jo["test_extended_gain_note"].get<std::string>().find("not known"), std::string::npos);
}

// Issue 12, item 5: an effect the selection chose on the fitted poses but that loses on poses
// it did not fit is listed as rejected with its figures, never under "effects". GRB3016, periodic
// error of j3, 60 poses, seed 9: selected at z 3.8, one outer fold of five selects it, nested
// held-out RMS 0.1122 mm geometric, 0.1130 mm with it (old code: the effect, "gain -0.7 %").
TEST(RcalCli, AnalyzeListsAnEffectThatLosesOnHeldOutPosesAsRejected) {
  const fs::path d = TempDir("analyze_rejected");
  const std::string robot = " --robot config/robots/grb3016.yaml";
  const std::string data = (d / "data.csv").string();
  Result r = RunRcal("simulate" + robot +
                     " --effect joint_periodic:j3=2e-4,0 --poses 60 --seed 9 --out " + data);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunRcal("analyze " + data + robot + " --out " + (d / "a").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "a" / "analysis.json");
  EXPECT_TRUE(j["effects"].empty()) << j["effects"].dump();
  ASSERT_EQ(j["rejected_effects"].size(), 1u);
  const json& rej = j["rejected_effects"][0];
  EXPECT_EQ(rej["cause"], "joint_periodic");
  EXPECT_EQ(rej["joints"], json::array({"j3"}));
  EXPECT_GT(rej["heldout_rms_with_m"].get<double>(), rej["heldout_rms_without_m"].get<double>());
  EXPECT_EQ(rej["outer_folds_selecting"], 1);
  EXPECT_GT(rej["selection_z"].get<double>(), j["selection"][0]["z_critical"].get<double>());
  EXPECT_EQ(j["gain"]["relative_gain"].get<double>(), 0.0);
  EXPECT_NE(r.output.find("rejected joint_periodic j3 h1"), std::string::npos) << r.output;
  std::ifstream md(d / "a" / "report.md");
  const std::string report((std::istreambuf_iterator<char>(md)), std::istreambuf_iterator<char>());
  EXPECT_NE(report.find("Selected, then rejected on held-out poses"), std::string::npos);
}

TEST(RcalCli, CalibrateRefusesEffectFilesItCannotUseNamingTheKey) {
  const fs::path d = TempDir("calibrate_effects_bad");
  const std::string robot = " --robot config/robots/grb3016.yaml";
  const std::string data = (d / "data.csv").string();
  Result r = RunRcal("simulate" + robot + " --poses 40 --seed 6 --out " + data);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  struct Case {
    std::string name, text, expected;
  };
  const std::vector<Case> cases = {
      {"joint", R"({"effects":[{"cause":"joint_scale","joints":["j9"],"values":[{"value":0}]}]})",
       "effects[0].joints: no joint 'j9'"},
      {"imu", R"({"effects":[{"cause":"gyro_bias","joints":[],"values":[]}]})",
       "effects[0].cause: 'gyro_bias' is not a pose-level effect"},
      {"values",
       R"({"effects":[{"cause":"joint_periodic","joints":["j3"],"harmonic":1,"values":[{"value":1e-4}]}]})",
       "effects[0].values: expected 2 entries"},
      {"thermal",
       R"({"effects":[{"cause":"thermal","joints":[],"source":"temperature","reference":20,"values":[{"value":1e-5}]}]})",
       "thermal needs a temperature column"},
      {"nolist", R"({"gain":{}})", "effects: missing"},
      {"json", "{not json", "not JSON"},
  };
  for (const Case& c : cases) {
    const fs::path f = d / (c.name + ".json");
    std::ofstream(f) << c.text;
    r = RunRcal("calibrate " + data + robot + " --effects " + f.string() + " --out " +
                (d / "out").string());
    EXPECT_NE(r.exit_code, 0) << c.name;
    EXPECT_NE(r.output.find(c.expected), std::string::npos) << c.name << ": " << r.output;
  }
  r = RunRcal("calibrate " + data + robot + " --effects " + (d / "missing.json").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--effects: cannot read"), std::string::npos) << r.output;
}

TEST(RcalCli, CalibrateLogIsAnAliasOfCalibrateLog) {
  const fs::path d = TempDir("calibrate_log_alias");
  const Result help = RunRcal("calibrate --help");
  ASSERT_EQ(help.exit_code, 0);
  EXPECT_NE(help.output.find("--log"), std::string::npos);
  EXPECT_NE(help.output.find("calibrate-log"), std::string::npos);
  // The same code path: the same figures from the same (here empty) log, and the same error. A
  // log with no pose accepted is no calibration: exit 3, saying what to check.
  std::ofstream(d / "empty.lcmlog").close();
  const std::string log = (d / "empty.lcmlog").string();
  Result a = RunRcal("calibrate-log " + log + " --json " + (d / "a.json").string());
  Result b = RunRcal("calibrate --log " + log + " --json " + (d / "b.json").string());
  EXPECT_EQ(a.exit_code, 3) << a.output;
  EXPECT_EQ(b.exit_code, 3) << b.output;
  EXPECT_NE(a.output.find("no pose accepted"), std::string::npos) << a.output;
  EXPECT_NE(a.output.find("no pose was given to the fit: nothing was calibrated"),
            std::string::npos)
      << a.output;
  EXPECT_EQ(ReadJson(d / "a.json"), ReadJson(d / "b.json"));
  EXPECT_EQ(ReadJson(d / "b.json")["poses_accepted"], 0);
  EXPECT_EQ(a.output, b.output);
  a = RunRcal("calibrate-log " + (d / "missing.lcmlog").string());
  b = RunRcal("calibrate --log " + (d / "missing.lcmlog").string());
  EXPECT_NE(a.exit_code, 0);
  EXPECT_EQ(a.exit_code, b.exit_code);
  const std::string error = "calibrate-log: cannot read " + (d / "missing.lcmlog").string();
  EXPECT_NE(a.output.find(error), std::string::npos) << a.output;
  EXPECT_NE(b.output.find(error), std::string::npos) << b.output;
  // DATA and --log together, or neither: refused with the reason.
  b = RunRcal("calibrate data.csv --log " + log);
  EXPECT_NE(b.exit_code, 0);
  EXPECT_NE(b.output.find("not both"), std::string::npos) << b.output;
  b = RunRcal("calibrate --robot config/robots/grb3016.yaml");
  EXPECT_NE(b.exit_code, 0);
  EXPECT_NE(b.output.find("DATA is required"), std::string::npos) << b.output;
}

// --- rcal analyze on an IMU stream (BROAD layout, no robot) ---

TEST(RcalCli, AnalyzeImuStreamNamesTheMagneticDisturbanceAndMeasuresItsGain) {
  const fs::path d = TempDir("analyze_imu");
  const std::string csv = (d / "stream.csv").string();
  const Result sim = RunRcal("simulate-imu --out " + csv +
                             " --seed 3 --mag-disturbance 15 --mag-start 25 --mag-end 33");
  ASSERT_EQ(sim.exit_code, 0) << sim.output;
  const Result r = RunRcal("analyze " + csv + " --out " + (d / "sim").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "sim" / "analysis.json");
  EXPECT_EQ(j["kind"], "imu_stream");
  ASSERT_EQ(j["effects"].size(), 1u) << j["effects"].dump();
  EXPECT_EQ(j["effects"][0]["cause"], "magnetic_disturbance");
  EXPECT_EQ(j["effects"][0]["axes"][0], "magnetometer");
  EXPECT_EQ(j["gain"]["metric"], "heading_rmse");
  EXPECT_GT(j["gain"]["relative_gain"].get<double>(), 0.0);
  EXPECT_LT(j["gain"]["heldout_rms_after_rad"].get<double>(),
            j["gain"]["heldout_rms_before_rad"].get<double>());
  EXPECT_TRUE(fs::exists(d / "sim" / "report.md"));

  // Real data: BROAD trial 30 (a magnet near the path) names the disturbance.
  const Result b =
      RunRcal("analyze ../shared/data/broad/broad_30_100hz.csv --out " + (d / "broad30").string());
  ASSERT_EQ(b.exit_code, 0) << b.output;
  const json jb = ReadJson(d / "broad30" / "analysis.json");
  bool named = false;
  for (const auto& e : jb["effects"]) named |= e["cause"] == "magnetic_disturbance";
  EXPECT_TRUE(named) << jb["effects"].dump();
  EXPECT_TRUE(jb["gain"]["measured"].get<bool>());
  // Its positions give the accelerometer's lag, with the position KF's error without and with
  // it in the JSON (SI), the report and a plot.
  const json& lag = jb["candidates"][4];
  EXPECT_EQ(lag["cause"], "accel_lag");
  EXPECT_TRUE(lag["tested"].get<bool>());
  EXPECT_NEAR(lag["values"]["accel_lag_s"]["value"].get<double>(), 2.5e-3, 0.5e-3);
  EXPECT_GT(lag["position_rmse_before_m"].get<double>(), 1e-4);
  EXPECT_GT(lag["position_rmse_after_m"].get<double>(), 1e-4);
  EXPECT_TRUE(fs::exists(d / "broad30" / "position_error.png"));
  std::ifstream report(d / "broad30" / "report.md");
  const std::string text((std::istreambuf_iterator<char>(report)), {});
  EXPECT_NE(text.find("without vs with the lag"), std::string::npos);

  // A stream with a missing column is refused, naming it.
  std::ofstream(d / "bad.csv")
      << "t_s,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y\n0,0,0,0,0,0,9.8,1,2\n";
  const Result bad2 = RunRcal("analyze " + (d / "bad.csv").string());
  EXPECT_NE(bad2.exit_code, 0);
  EXPECT_NE(bad2.output.find("mag_z"), std::string::npos) << bad2.output;
}

// The real UR10 (23 poses, ~2 mm of noise): an honest "no significant effect beyond geometry",
// gain exactly 0 (geometry is the selected model).
TEST(RcalCli, AnalyzeTheRealUr10FindsNoEffectBeyondGeometry) {
  const fs::path d = TempDir("analyze_ur10");
  const Result r = RunRcal("analyze " RCAL_SOURCE_DIR
                           "/data/figaroh_ur10/calibration.csv --robot " RCAL_SOURCE_DIR
                           "/config/robots/ur10.urdf --out " +
                           (d / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "out" / "analysis.json");
  EXPECT_TRUE(j.at("effects").empty()) << j.at("effects").dump();
  EXPECT_EQ(j.at("gain").at("relative_gain").get<double>(), 0.0);
  EXPECT_NEAR(j.at("gain").at("heldout_rms_before_m").get<double>(), 4.3e-3, 0.5e-3);
  EXPECT_TRUE(fs::exists(d / "out" / "report.md"));
}

// The pose-level detection sweep: each (effect, magnitude, seed) cell draws its joint and its
// dataset from its own seed, so a cell's result is the same run alone or inside a larger sweep
// (and on any number of jobs);
// the rates add up (a thermal effect named with the wrong source is a wrong cause, counted in
// wrong_effect_rate and apart in wrong_thermal_source_rate; scoring in test_detection_sweep.cpp).
TEST(RcalCli, DetectionSweepCellsDoNotDependOnTheOtherCells) {
  const fs::path d = TempDir("detection_sweep");
  const Result small =
      RunRcal("detection-sweep --seeds 2 --magnitudes 2 --effects backlash,thermal_time --json " +
              (d / "small.json").string());
  ASSERT_EQ(small.exit_code, 0) << small.output;
  const Result large = RunRcal(
      "detection-sweep --seeds 2 --magnitudes 1,2 --jobs 2 --effects "
      "joint_scale,backlash,thermal_temperature,thermal_time,clean --json " +
      (d / "large.json").string());
  ASSERT_EQ(large.exit_code, 0) << large.output;
  const json a = ReadJson(d / "small.json"), b = ReadJson(d / "large.json");
  const auto row = [](const json& j, const std::string& effect, double k) {
    for (const auto& r : j["rows"])
      if (r["effect"] == effect && r["rms_over_noise"].get<double>() == k) return r;
    ADD_FAILURE() << effect << " " << k << " missing";
    return json();
  };
  ASSERT_EQ(a["rows"].size(), 2u);
  ASSERT_EQ(b["rows"].size(), 8u);
  for (const std::string effect : {"backlash", "thermal (time)"}) {
    const json ra = row(a, effect, 2), rb = row(b, effect, 2);
    ASSERT_EQ(ra["cells"].size(), 2u);
    EXPECT_EQ(ra["cells"], rb["cells"]) << effect;  // joint, seed, effects found, scoring
    EXPECT_EQ(ra["detection_rate"], rb["detection_rate"]);
  }
  EXPECT_EQ(a["clean_runs"], 0);
  EXPECT_EQ(b["clean_runs"], 2);
  for (const auto& r : b["rows"]) {
    const int runs = r["runs"].get<int>();
    EXPECT_EQ(runs, 2);
    EXPECT_LE(r["wrong_thermal_source"].get<int>(), r["wrong"].get<int>());
    EXPECT_LE(r["detected"].get<int>() + r["wrong"].get<int>(), runs);
    if (r["effect"] != "thermal (temperature)" && r["effect"] != "thermal (time)") {
      EXPECT_EQ(r["wrong_thermal_source"], 0);
    }
    for (const auto& c : r["cells"]) {
      // A thermal detection counts only with the hidden source.
      bool right = false;
      for (const auto& f : c["found"])
        right |= f["cause"] == c["hidden"]["cause"] && f["joint"] == c["hidden"]["joint"] &&
                 f.value("thermal_source", "") == c["hidden"].value("thermal_source", "");
      EXPECT_EQ(c["detected"].get<bool>(), right) << c.dump();
    }
  }
}

// The IMU detection sweep, one stream per cell: every cell runs, the clean stream reports
// nothing, and clearly visible effects (8 µT magnet, 0.3 m/s², 10 ms, an accelerometer 4 ms late)
// are named.
TEST(RcalCli, DetectionSweepImuRunsEveryCell) {
  const fs::path d = TempDir("sweep_imu");
  const Result r = RunRcal("detection-sweep-imu --seeds 1 --json " + (d / "s.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "s.json");
  ASSERT_EQ(j.at("rows").size(), 16u);
  for (const auto& row : j.at("rows")) {
    EXPECT_EQ(row.at("other_cause"), 0) << row.dump();
    const std::string label = row.at("label");
    if (label == "magnet 8 µT for 8 s" || label == "linear acceleration 0.30 m/s²" ||
        label == "time offset 10 ms" || label == "accelerometer lag 4 ms (3 m/s²)") {
      EXPECT_EQ(row.at("found"), 1) << label;
    }
  }
  EXPECT_EQ(j.at("rows")[0].at("cause"), "");
}

// position_kf's settings from their sweep, small: the demo cell (8 simulated cases, one seed)
// and BROAD's fast-translation trial 16 and tapping trial 24 (real IMU, optical truth). On the
// simulated cases the minimax is the accelerometer-driven filter with a bias state and a constant
// noise, better than the paper's filter on every case, and it runs off on the real trials; with
// them in, the accelerometer-driven filter's own minimax takes the adaptive accelerometer noise
// (position_kf.hpp), and the bank of both models (position_kf_bank.hpp) is better than the
// paper's filter on every case, the real ones included, and the minimax. (The minimax here has
// moved with the filters: before the rollback the bank, 0.70×; with it the accelerometer-driven
// filter alone, 0.858× against the bank's 0.890×; with the bank's evidence bounded too, the bank
// again, gated at 11.34, 0.846×; with the trapezoid and the held acceleration, the bank gated at
// 16.27, 0.807×, while the accelerometer-driven filter alone is no longer ahead of the paper's on
// every case: 1.235× at worst. The sweep of the banks on 10 seeds, 480 cases with taps and BROAD,
// chooses the bank gated at 11.34: README.)
TEST(RcalCli, PositionKfSweepTakesTheAdaptiveNoiseOnceRealDataRunsTheConstantNoiseOff) {
  const fs::path d = TempDir("pkf_sweep");
  const Result r = RunRcal(
      "position-kf-sweep --seeds 1 --cell grb3016 --broad-trial "
      "../shared/data/broad/broad_16_100hz.csv --broad-trial "
      "../shared/data/broad/broad_24_100hz.csv --json " +
      (d / "s.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "s.json");
  ASSERT_EQ(j.at("cases"), 10);
  const json& sim = j.at("chosen_simulated");
  EXPECT_GT(sim.at("accel_bias_walk").get<double>(), 0.0) << r.output;
  EXPECT_EQ(sim.at("accel_noise_adaptation_tau_s").get<double>(), 0.0) << r.output;
  EXPECT_LT(sim.at("worst_ratio").get<double>(), 0.9) << r.output;
  const json& driven = j.at("chosen_accelerometer_driven");
  EXPECT_GT(driven.at("accel_noise_adaptation_tau_s").get<double>(), 0.0) << r.output;
  EXPECT_LT(j.at("bank").at("worst_ratio").get<double>(), 1.0) << r.output;
  EXPECT_TRUE(j.at("chosen").at("bank").get<bool>()) << r.output;
  EXPECT_LT(j.at("chosen").at("worst_ratio").get<double>(), driven.at("worst_ratio").get<double>())
      << r.output;
  ASSERT_EQ(j.at("groups").size(), 5u);  // two IMU classes × 20 and 100 Hz on the demo cell, BROAD
  for (int g = 0; g < 4; ++g)
    EXPECT_LT(j.at("groups")[g].at("paper_moving_rmse_m").get<double>(), 2e-3);
  // The simulated cases' choice on the real trials: far off (seen: 185× the paper's filter at
  // worst); the choice over all, closer than the paper's (seen: 4.5 against 132 mm, the median
  // of the two trials).
  bool simulated_fold = false;
  for (const json& f : j.at("folds"))
    if (f.at("left_out") == "data = BROAD") {
      simulated_fold = true;
      EXPECT_FALSE(f.at("bank").get<bool>());
      EXPECT_GT(f.at("held_out_worst_ratio").get<double>(), 10.0) << r.output;
    }
  EXPECT_TRUE(simulated_fold);
  const json& broad = j.at("groups")[4];
  EXPECT_EQ(broad.at("imu"), "BROAD");
  EXPECT_LT(broad.at("chosen_moving_rmse_m").get<double>(),
            broad.at("paper_moving_rmse_m").get<double>());
}

// --taps: a tapped copy of every simulated case (sim::ImuTaps: 30–70 m/s², one sample or ringing
// for 80 ms, every 2 s on average), here on the demo cell at 20 Hz, one seed. The taps cost the
// paper's filter about twice its error (seen: 1.16 → 2.34 mm), and the bank of both models stays
// closer than it on every tapped case at every accelerometer gate: since its evidence is bounded
// (PositionKfBank: no model enters a sample more than ln(1/μ_min) behind), a model that a tap
// takes off is left at once (before the bound the bank was 1.08–1.85× the paper's filter at worst
// here, by gate, and 1.6–2.2× on the Panda cell). --rate picks the tracker rates; the tapped
// figures are tables, folds and per-case scores of their own.
TEST(RcalCli, PositionKfSweepTapsEveryCaseAndTheBankStaysAheadOfThePapersFilter) {
  const fs::path d = TempDir("pkf_sweep_taps");
  const Result r = RunRcal("position-kf-sweep --seeds 1 --cell grb3016 --rate 20 --taps --json " +
                           (d / "s.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "s.json");
  ASSERT_EQ(j.at("cases"), 8);  // two IMU classes × two lever arms × tapped or not, at 20 Hz
  ASSERT_EQ(j.at("groups").size(), 4u);
  for (int g = 0; g < 4; ++g) {
    EXPECT_EQ(j.at("groups")[g].at("taps").get<bool>(), g >= 2);
    EXPECT_EQ(j.at("groups")[g].at("tracker_rate_hz").get<double>(), 20.0);
  }
  const json& cases = j.at("case_scores");
  ASSERT_EQ(cases.size(), 8u);
  int tapped = 0;
  for (const json& c : cases) {
    if (!c.at("taps").get<bool>()) continue;
    ++tapped;
    // The same case untapped: same IMU, lever arm and seed.
    const json* clean = nullptr;
    for (const json& o : cases)
      if (!o.at("taps").get<bool>() && o.at("imu") == c.at("imu") &&
          o.at("lever_arm") == c.at("lever_arm") && o.at("seed") == c.at("seed"))
        clean = &o;
    ASSERT_NE(clean, nullptr);
    EXPECT_GT(c.at("paper_moving_rmse_m").get<double>(),
              1.5 * clean->at("paper_moving_rmse_m").get<double>())
        << "the taps should cost the paper's filter: " << c.dump();
    for (const auto& [gate, rmse] : c.at("bank_moving_rmse_m_by_gate").items())
      EXPECT_LT(rmse.get<double>(), c.at("paper_moving_rmse_m").get<double>())
          << "gate " << gate << ": " << c.dump();
  }
  EXPECT_EQ(tapped, 4);
  ASSERT_EQ(j.at("banks").size(), 4u);
  for (const json& b : j.at("banks")) EXPECT_LT(b.at("tapped_worst_ratio").get<double>(), 1.0);
  bool fold = false;
  for (const json& f : j.at("folds")) fold |= f.at("left_out") == "taps = tapped";
  EXPECT_TRUE(fold);
}

// --banks-only: the paper's filter and the bank's four accelerometer gates, nothing else (to settle
// the gate on many seeds at a fraction of the grid's cost), and the bank's choice made seed by
// seed: every seed names one of the four banks.
TEST(RcalCli, PositionKfSweepBanksOnlyChoosesAmongTheGatesSeedBySeed) {
  const fs::path d = TempDir("pkf_sweep_banks");
  const Result r = RunRcal(
      "position-kf-sweep --seeds 2 --cell grb3016 --rate 20 --banks-only "
      "--json " +
      (d / "s.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "s.json");
  ASSERT_EQ(j.at("cases"), 8);  // two IMU classes × two lever arms × two seeds
  ASSERT_EQ(j.at("banks").size(), 4u);
  // Only the paper's filter and banks were run: every choice is one of them.
  EXPECT_TRUE(j.at("chosen").at("bank").get<bool>()) << r.output;
  EXPECT_TRUE(j.at("chosen_simulated").at("bank").get<bool>()) << r.output;
  // No accelerometer-driven candidate of its own was run: no choice among them is claimed.
  EXPECT_TRUE(j.at("chosen_accelerometer_driven").is_null()) << r.output;
  EXPECT_EQ(r.output.find("among its candidates"), std::string::npos) << r.output;
  int seeds = 0;
  for (const auto& [name, n] : j.at("bank_seed_wins").items()) {
    EXPECT_EQ(name.rfind("bank", 0), 0u) << name;
    seeds += n.get<int>();
  }
  EXPECT_EQ(seeds, 2) << r.output;
  EXPECT_NE(r.output.find("seed by seed (2 seeds)"), std::string::npos) << r.output;
}

// The README's table of rcal analyze on IMU streams (trials 02, 07, 10, 15, 30): effects named,
// their evidence, base and extended RMSE, Allan deviations. Deterministic, so every figure of
// tests/tools/golden/analyze_broad.json must be reproduced (relative 1e-6). Each entry is the
// analysis.json of `rcal analyze ../shared/data/broad/broad_TT_100hz.csv` without its "data" path.
TEST(RcalCli, AnalyzeReproducesTheImuStreamTableOnBroad) {
  const fs::path d = TempDir("analyze_broad");
  const json golden = ReadJson(RCAL_SOURCE_DIR "/tests/tools/golden/analyze_broad.json");
  ASSERT_EQ(golden.size(), 5u);
  for (const auto& [t, want] : golden.items()) {
    const Result r =
        RunRcal("analyze ../shared/data/broad/broad_" + t + "_100hz.csv --out " + (d / t).string());
    ASSERT_EQ(r.exit_code, 0) << t << ": " << r.output;
    const json got = ReadJson(d / t / "analysis.json");
    ExpectGolden(got, want, "broad_" + t);
    // Issue 12, item 5: no z clamped to that of p = 1e-300 (37.05, the old accel_motion figure
    // of every trial); a p below 1e-300 carries its bound and its exact log10.
    for (const auto& c : got.at("candidates")) {
      EXPECT_GT(std::abs(c.at("statistic_z").get<double>() - 37.047096), 1e-3) << t;
      if (c.contains("p_value") && c.at("p_value").get<double>() < 1e-300) {
        EXPECT_EQ(c.value("p_value_bound", ""), "< 1e-300") << t << " " << c.at("cause");
        EXPECT_LT(c.at("log10_p_value").get<double>(), -300) << t;
      }
    }
  }
}

// The README's BROAD table: rcal fuse on every real trial in ../shared/data/broad with the shipped
// settings. The filters are deterministic on a file (the simulated position sensor is seeded), so
// every figure of tests/tools/golden/fuse_broad.json must be reproduced (relative 1e-6, counts
// exactly). A change that moves a figure regenerates the file and the README table with it:
//   bash deploy/broad-table --golden tests/tools/golden/fuse_broad.json
TEST(RcalCli, FuseReproducesTheBroadTableOnEveryTrial) {
  const fs::path d = TempDir("fuse_broad");
  const json golden = ReadJson(RCAL_SOURCE_DIR "/tests/tools/golden/fuse_broad.json");
  size_t trials = 0;
  for (const auto& e : fs::directory_iterator(RCAL_SHARED_DIR "/data/broad")) {
    const std::string name = e.path().filename().string();  // broad_TT_100hz.csv
    if (name.rfind("broad_", 0) != 0 || e.path().extension() != ".csv") continue;
    const std::string t = name.substr(6, name.find('_', 6) - 6);
    ASSERT_TRUE(golden.contains(t)) << name << " has no golden figures: regenerate the file";
    const fs::path out = d / ("broad_" + t + ".json");
    const Result r = RunRcal("fuse " + e.path().string() + " --out " + (d / t).string() +
                             " --json " + out.string());
    ASSERT_EQ(r.exit_code, 0) << name << ": " << r.output;
    ExpectGolden(ReadJson(out), golden.at(t), "broad_" + t);
    ++trials;
  }
  EXPECT_EQ(trials, golden.size()) << "a trial of the golden file is missing from the data";
}

// An occluded marker (--pos-occlusion 10 2: the tracker silent for the first 2 s of every 10 s,
// its other samples unchanged) on BROAD's fast translation 16: the INS integrates through each
// occlusion closer to the truth than the bank's accelerometer-driven filter (measured 16.2 mm RMS
// over the movement, occlusions included, against 50.9 mm), takes the tracker back when it returns
// (none re-anchored) and keeps its attitude (0.37° against 0.36° unoccluded). LENGTH must be
// shorter than PERIOD, refused naming the option.
TEST(RcalCli, FuseTheInsBridgesAnOccludedTracker) {
  const fs::path d = TempDir("fuse_occlusion");
  const std::string trial = RCAL_SHARED_DIR "/data/broad/broad_16_100hz.csv";
  const auto run = [&](const std::string& args) {
    const Result r = RunRcal("fuse " + trial + " " + args + " --json " + (d / "f.json").string());
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return ReadJson(d / "f.json");
  };
  const json seen = run("");
  const json occluded = run("--pos-occlusion 10 2");
  const json& sensor = occluded.at("position_sensor");
  EXPECT_EQ(sensor.at("occlusion").at("period_s").get<double>(), 10.0);
  EXPECT_EQ(sensor.at("occlusion").at("length_s").get<double>(), 2.0);
  // About a fifth of the samples are gone (3738 → 2978).
  EXPECT_LT(sensor.at("samples").get<double>(),
            0.85 * seen.at("position_sensor").at("samples").get<double>());
  const json& ins = occluded.at("aided_ins");
  const double marker = ins.at("position_rmse_movement_m");
  const double bank = occluded.at("position_rmse_movement_m");
  std::printf(
      "trial 16 occluded 2 s in 10: INS marker %.2f mm, bank %.2f mm; attitude %.3f° "
      "(unoccluded %.3f°)\n",
      marker * 1e3, bank * 1e3, ins.at("total_rmse_rad").get<double>() * 180.0 / std::numbers::pi,
      seen.at("aided_ins").at("total_rmse_rad").get<double>() * 180.0 / std::numbers::pi);
  EXPECT_LT(marker, 0.5 * bank);
  EXPECT_GT(marker, 3.0 * seen.at("aided_ins").at("position_rmse_movement_m").get<double>());
  EXPECT_EQ(ins.at("reanchored").get<int>(), 0);
  EXPECT_LT(ins.at("total_rmse_rad").get<double>(),
            1.1 * seen.at("aided_ins").at("total_rmse_rad").get<double>());
  const Result bad = RunRcal("fuse " + trial + " --pos-occlusion 2 2");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("--pos-occlusion"), std::string::npos) << bad.output;
}

// BROAD trial 16's violent shaking (55–62 s: the marker swings ±0.39 m at 3 Hz, |f| up to 94
// m/s²) ran the bank's accelerometer-driven filter metres off on some tracker seeds: with the
// adaptation at its cap the prediction was worthless, yet one position sample in a few passed the
// gate, so the consecutive rejections never reached their limit (2.17 m RMS over the movement
// at seed 16 with the second-order low-pass, 0.40 m at seed 11). A gated sample now
// re-initialises the position once the adaptation has given up, its velocity the mean since the
// sample before (PositionKf). And the shaking's onset (20 → 94 m/s² within 40 ms) looked to the
// accelerometer's gate like a tap: refused, its integral missing, both filters ran 20–130 mm off
// for 0.15 s. The positions now reinstate the refused samples. Each filter alone stays within a
// few tracker σ.
TEST(RcalCli, FuseTheShakingOfTrial16NeverRunsAPositionFilterOff) {
  const fs::path d = TempDir("fuse_shaking");
  const std::string trial = RCAL_SHARED_DIR "/data/broad/broad_16_100hz.csv";
  for (const std::string& args :
       {std::string("--seed 11"), std::string("--seed 16 --set accel_lowpass_order=2")}) {
    const Result r = RunRcal("fuse " + trial + " " + args + " --json " + (d / "f.json").string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const json j = ReadJson(d / "f.json");
    const json& paper = j.at("position_paper_model");
    const double driven = j.at("position_accelerometer_driven").at("rmse_movement_m");
    const double white_jerk = paper.at("rmse_movement_m");
    const double bank = j.at("position_rmse_movement_m");
    std::printf(
        "trial 16, %s: accelerometer-driven filter %.2f mm, white-jerk filter %.2f mm (%d "
        "refused accelerometer samples reinstated), bank %.2f mm\n",
        args.c_str(), driven * 1e3, white_jerk * 1e3,
        paper.at("accelerometer_reinstated").get<int>(), bank * 1e3);
    // Measured: 1.80 and 1.69 mm (before the velocity: 5.6 and 5.5; before the re-initialisation:
    // 396 and 2174 mm).
    EXPECT_LT(driven, 0.0025) << args;
    // 2.26 and 2.12 mm (before the reinstatement: 5.47 and 10.63 mm).
    EXPECT_LT(white_jerk, 0.003) << args;
    EXPECT_GT(paper.at("accelerometer_reinstated").get<int>(), 0) << args;
    EXPECT_LT(bank, 0.0022) << args;  // 1.85 and 1.67 mm (before: 3.10 and 2.26 mm)
  }
}

// rcal fuse measures the accelerometer's lag from its simulated tracker and the filter's attitude
// (accel_lag in the JSON) and takes BROAD's, 2.85 ms, out in the position KF. On the fast
// translation trial 16 the measurement must agree with what the optical truth gives, its 100 Hz
// positions and its attitude instead of a 1 mm tracker and the filter's (`rcal analyze`'s
// accel_lag: 2.62 ± 0.02 ms), and taking the lag out must bring the position closer; a lag the
// filter cannot take is refused naming the setting.
TEST(RcalCli, FuseMeasuresTheAccelerometersLagAndTakesItOut) {
  const fs::path d = TempDir("fuse_lag");
  const std::string trial = "../shared/data/broad/broad_16_100hz.csv";
  const Result shipped = RunRcal("fuse " + trial + " --json " + (d / "a.json").string());
  ASSERT_EQ(shipped.exit_code, 0) << shipped.output;
  const Result stamped =
      RunRcal("fuse " + trial + " --json " + (d / "b.json").string() + " --set pos.accel_delay=0");
  ASSERT_EQ(stamped.exit_code, 0) << stamped.output;
  const json a = ReadJson(d / "a.json"), b = ReadJson(d / "b.json");
  EXPECT_EQ(a.at("settings").at("pos.accel_delay_s").get<double>(), 2.85e-3);
  EXPECT_EQ(b.at("settings").at("pos.accel_delay_s").get<double>(), 0.0);
  const json& lag = a.at("accel_lag");
  ASSERT_TRUE(lag.contains("delay_s")) << lag.dump();
  EXPECT_NEAR(lag.at("delay_s").get<double>(), 2.62e-3, 0.5e-3) << lag.dump();
  EXPECT_LT(lag.at("delay_sigma_s").get<double>(), 0.5e-3) << lag.dump();
  EXPECT_GT(lag.at("triplets").get<int>(), 3000) << lag.dump();
  // The measurement does not depend on the lag applied (it reads the accelerometer as stamped).
  EXPECT_EQ(lag.at("delay_s"), b.at("accel_lag").at("delay_s"));
  EXPECT_NE(shipped.output.find("Accelerometer lag measured"), std::string::npos) << shipped.output;
  const double with = a.at("position_rmse_movement_m"), without = b.at("position_rmse_movement_m");
  EXPECT_LT(with, 0.85 * without) << with << " against " << without;
  const Result bad = RunRcal("fuse " + trial + " --json " + (d / "c.json").string() +
                             " --set pos.accel_delay=0.2");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("accel_delay"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(d / "c.json"));
}

// A 5 Hz IMU steps 0.2 s, beyond the filters' 0.1 s silence: before rcal fuse set their longest
// step from the stream's rate, the orientation KF and the INS started again from the sensors at
// every sample, their attitude then the FQA's alone (10.4° on this stream). Trial 02 (slow
// rotation) as a 5 Hz IMU gives it: each row the mean of twenty 100 Hz samples, stamped at the
// last (the rate over the interval ending at the stamp, as the filters read a gyro), with that
// row's truth.
TEST(RcalCli, FuseASlowImuIsNotTakenForASilentOne) {
  const fs::path d = TempDir("fuse_slow_imu");
  {
    std::ifstream in(RCAL_SHARED_DIR "/data/broad/broad_02_100hz.csv");
    std::ofstream out(d / "broad_02_5hz.csv");
    std::string line;
    ASSERT_TRUE(std::getline(in, line));
    out << line << '\n';
    out.precision(10);
    std::array<double, 9> sum{};  // gyr, acc, mag
    for (int row = 1; std::getline(in, line); ++row) {
      std::vector<std::string> cells;
      std::stringstream ss(line);
      for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
      ASSERT_EQ(cells.size(), 18u) << line;
      for (int i = 0; i < 9; ++i) sum[i] += std::stod(cells[1 + i]);
      if (row % 20 != 0) continue;
      out << cells[0];
      for (int i = 0; i < 9; ++i) out << ',' << sum[i] / 20.0;
      for (int i = 10; i < 18; ++i) out << ',' << cells[i];
      out << '\n';
      sum.fill(0.0);
    }
  }
  const Result r =
      RunRcal("fuse " + (d / "broad_02_5hz.csv").string() + " --json " + (d / "f.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "f.json");
  EXPECT_NEAR(j.at("imu_rate_hz").get<double>(), 5.0, 1e-6);
  const json &kf = j.at("orientation_kf"), &ins = j.at("aided_ins");
  EXPECT_NEAR(kf.at("max_step_s").get<double>(), 0.6, 1e-9);
  EXPECT_NEAR(ins.at("max_step_s").get<double>(), 0.6, 1e-9);
  EXPECT_EQ(kf.at("reinitialised").get<int>(), 0);
  EXPECT_EQ(ins.at("reinitialised").get<int>(), 0);
  constexpr double kDeg = 180.0 / std::numbers::pi;
  const double kf_deg = kf.at("total_rmse_rad").get<double>() * kDeg;
  const double fqa_deg = j.at("fqa").at("total_rmse_rad").get<double>() * kDeg;
  const double ins_deg = ins.at("total_rmse_rad").get<double>() * kDeg;
  std::printf("trial 02 as a 5 Hz IMU: orientation KF %.2f°, INS %.2f°, FQA alone %.2f°\n", kf_deg,
              ins_deg, fqa_deg);
  // Measured: 4.22°, 3.49° and 10.39° (at 100 Hz: 1.23° and 1.11°).
  EXPECT_LT(kf_deg, 0.5 * fqa_deg);
  EXPECT_LT(ins_deg, 0.5 * fqa_deg);
  EXPECT_NE(r.output.find("IMU: 5.0 Hz"), std::string::npos) << r.output;
}

// rcal fuse --trace: one row per fused sample with the estimates and their errors, from which the
// JSON's scores follow: the RMSE of the trace's errors over the movement rows is the JSON's total,
// heading, inclination and position RMSE; each quaternion is a unit one (w x y z); the position's
// error is |p_WM_W − p_truth| with the file's truth.
TEST(RcalCli, FuseTraceIsEverySampleTheScoresComeFrom) {
  const fs::path d = TempDir("fuse_trace");
  const std::string trial = "../shared/data/broad/broad_05_100hz.csv";
  const Result r = RunRcal("fuse " + trial + " --json " + (d / "f.json").string() + " --trace " +
                           (d / "trace.csv").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "f.json");
  std::ifstream in(d / "trace.csv");
  std::string line;
  ASSERT_TRUE(std::getline(in, line));
  std::vector<std::string> header;
  {
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) header.push_back(c);
  }
  ASSERT_EQ(header.size(), 30u);
  EXPECT_EQ(header[0], "t_s");
  EXPECT_EQ(header[2], "q_EB_w");
  EXPECT_EQ(header[12], "position_error_m");
  EXPECT_EQ(header[19], "ins_q_EB_w");
  EXPECT_EQ(header[23], "ins_total_error_rad");
  EXPECT_EQ(header[29], "ins_position_error_m");
  // The file's rows: t_s and pos_x, pos_y, pos_z (columns 0 and 14–16; "nan" where occluded).
  std::vector<std::array<double, 4>> truth;
  {
    std::ifstream f(fs::path(RCAL_SOURCE_DIR) / trial);
    std::string row;
    std::getline(f, row);
    while (std::getline(f, row)) {
      std::vector<double> v;
      std::stringstream ss(row);
      for (std::string c; std::getline(ss, c, ',');) v.push_back(std::stod(c));
      ASSERT_EQ(v.size(), 18u);
      truth.push_back({v[0], v[14], v[15], v[16]});
    }
  }
  double se[4] = {}, se_ins[4] = {};
  int n[4] = {}, n_ins[4] = {}, rows = 0;
  while (std::getline(in, line)) {
    std::vector<std::string> c;
    std::stringstream ss(line);
    for (std::string v; std::getline(ss, v, ',');) c.push_back(v);
    c.resize(header.size());  // trailing empty cells
    const auto at = [&](int k) { return c[k].empty() ? std::nan("") : std::stod(c[k]); };
    ASSERT_LT(rows, static_cast<int>(truth.size()));
    const auto& [t, px, py, pz] = truth[rows];
    ASSERT_NEAR(t, at(0), 1e-9) << "row " << rows;  // no sample refused here
    EXPECT_NEAR(std::sqrt(at(2) * at(2) + at(3) * at(3) + at(4) * at(4) + at(5) * at(5)), 1.0,
                1e-8);
    const double e =
        std::sqrt(std::pow(at(9) - px, 2) + std::pow(at(10) - py, 2) + std::pow(at(11) - pz, 2));
    if (std::isfinite(e)) {
      EXPECT_NEAR(e, at(12), 1e-8);
    }
    // The tracker-aided INS's columns: its quaternion, errors, marker position and its error.
    const double e_ins =
        std::sqrt(std::pow(at(26) - px, 2) + std::pow(at(27) - py, 2) + std::pow(at(28) - pz, 2));
    if (std::isfinite(e_ins)) {
      EXPECT_NEAR(e_ins, at(29), 1e-8);
      EXPECT_NEAR(std::sqrt(at(19) * at(19) + at(20) * at(20) + at(21) * at(21) + at(22) * at(22)),
                  1.0, 1e-8);
    }
    if (at(1) == 1) {
      for (int k = 0; k < 4; ++k) {
        const double err = at(k < 3 ? 6 + k : 12);
        if (std::isfinite(err)) se[k] += err * err, ++n[k];
        const double err_ins = at(k < 3 ? 23 + k : 29);
        if (std::isfinite(err_ins)) se_ins[k] += err_ins * err_ins, ++n_ins[k];
      }
    }
    ++rows;
  }
  EXPECT_EQ(rows, static_cast<int>(truth.size()));
  const json& o = j.at("orientation_kf");
  const double want[4] = {o.at("total_rmse_rad"), o.at("heading_rmse_rad"),
                          o.at("inclination_rmse_rad"), j.at("position_rmse_movement_m")};
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(std::sqrt(se[k] / n[k]), want[k], 1e-6 * want[k]) << k;
  EXPECT_EQ(n[0], o.at("samples").get<int>());
  const json& a = j.at("aided_ins");
  const double want_ins[4] = {a.at("total_rmse_rad"), a.at("heading_rmse_rad"),
                              a.at("inclination_rmse_rad"), a.at("position_rmse_movement_m")};
  for (int k = 0; k < 4; ++k)
    EXPECT_NEAR(std::sqrt(se_ins[k] / n_ins[k]), want_ins[k], 1e-6 * want_ins[k]) << "INS " << k;
  EXPECT_EQ(n_ins[0], a.at("samples").get<int>());
}

// The tracker-aided INS's settings chosen by leave-one-trial-out (rcal fuse-loo --ins, its
// shipped grid of 36, each candidate's cost on a trial the worst of its total, heading and
// inclination as fractions of VQF's). In-sample it chooses what ships (BroadInsSettings:
// magnetometer heading σ 0.6 rad, accelerometer noise 0.02 m/s²/√Hz adapted with τ 3 s, the shock
// hypothesis at κ = 2), and its figures are rcal fuse's (the same tracker draws); only trial 15's
// inclination is then above VQF's. A candidate whose marker runs off a trial (beyond 3× the
// tracker's own error) has failed it: in-sample the INS's marker stays within 2× the tracker's on
// every trial, the taps of 24 and the vibration of 27 included, and held out none runs off. Held
// out, one fold chooses otherwise (measured): the one without 27, the only trial whose vibration
// the adaptation holds, leaves it off. The INS is at or below VQF in total on every trial held
// out, its mean under half of VQF's (the orientation KF alone: 0.94×). VQF is an IMU-only filter:
// the INS has the tracker too (README).
TEST(RcalCli, FuseLooChoosesTheTrackerAidedInsSettingsHeldOut) {
  const fs::path d = TempDir("fuse_loo_ins");
  const Result r =
      RunRcal("fuse-loo ../shared/data/broad --ins --jobs 2 --json " + (d / "loo.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = ReadJson(d / "loo.json");
  EXPECT_EQ(j.at("estimator"), "tracker-aided INS");
  EXPECT_EQ(j.at("objective"), "vqf-ratio");
  const std::vector<std::string> shipped = {
      "ins.mag_heading_sigma=0.6", "ins.accel_noise_density=0.02",
      "ins.accel_noise_adaptation_tau=3", "ins.accel_change_sigma=0.1"};
  EXPECT_EQ(j.at("in_sample_settings").get<std::vector<std::string>>(), shipped);
  const json golden = ReadJson(RCAL_SOURCE_DIR "/tests/tools/golden/fuse_broad.json");
  // VQF's total, heading and inclination per trial [deg], from the data's README (as fuse-loo
  // reads it).
  std::map<std::string, std::array<double, 3>> vqf3;
  {
    std::ifstream in(RCAL_SHARED_DIR "/data/broad/README.md");
    const std::regex row(R"(^\| (\d\d) \| ([0-9.]+) / ([0-9.]+) / ([0-9.]+) \|)");
    for (std::string line; std::getline(in, line);) {
      std::smatch m;
      if (std::regex_search(line, m, row))
        vqf3[m[1]] = {std::stod(m[2]), std::stod(m[3]), std::stod(m[4])};
    }
  }
  std::map<std::string, double> vqf;
  for (const auto& [t, v] : vqf3) vqf[t] = v[0];
  double sum = 0.0, sum_vqf = 0.0;
  int folds_shipped = 0;
  // Trial and figure above VQF's, in-sample and held out.
  std::vector<std::string> above_vqf, above_vqf_held_out;
  for (const auto& [t, f] : j.at("trials").items()) {
    const char* figures[] = {"total_rmse_rad", "heading_rmse_rad", "inclination_rmse_rad"};
    for (int k = 0; k < 3; ++k) {
      if (f.at("in_sample").at(figures[k]).get<double>() * 180.0 / std::numbers::pi > vqf3.at(t)[k])
        above_vqf.push_back(t + " " + figures[k]);
      if (f.at("leave_one_out").at(figures[k]).get<double>() * 180.0 / std::numbers::pi >
          vqf3.at(t)[k])
        above_vqf_held_out.push_back(t + " " + figures[k]);
    }
    folds_shipped += f.at("leave_one_out_settings").get<std::vector<std::string>>() == shipped;
    const json& in = f.at("in_sample");
    EXPECT_NEAR(in.at("total_rmse_rad").get<double>(),
                golden.at(t).at("aided_ins").at("total_rmse_rad").get<double>(), 1e-9)
        << t;
    EXPECT_NEAR(in.at("marker_rmse_m").get<double>(),
                golden.at(t).at("aided_ins").at("position_rmse_movement_m").get<double>(), 1e-9)
        << t;
    EXPECT_LT(in.at("marker_rmse_m").get<double>(), 2.0 * in.at("tracker_rmse_m").get<double>())
        << t;  // at most 1.8× (27, 3.2 mm against 1.8 mm); 29× on 24 before the hypothesis
    const double held_out = f.at("leave_one_out").at("total_rmse_rad");
    ASSERT_TRUE(vqf.count(t)) << t;
    EXPECT_LE(held_out * 180.0 / std::numbers::pi, vqf.at(t)) << t;
    sum += held_out * 180.0 / std::numbers::pi;
    sum_vqf += vqf.at(t);
  }
  EXPECT_EQ(j.at("trials").size(), 16u);
  EXPECT_GE(folds_shipped, 15);  // measured: 15 (the fold without 27 leaves the adaptation off)
  EXPECT_TRUE(j.at("leave_one_out_marker_run_off").empty());
  EXPECT_NEAR(j.at("leave_one_out_mean_total_rmse_rad").get<double>() * 180.0 / std::numbers::pi,
              sum / 16.0, 1e-9);
  EXPECT_LT(sum / sum_vqf, 0.5);  // measured: 0.44
  // In-sample and held out, only trial 15's inclination is above VQF's (0.54° against 0.42°):
  // held out, 27's fold leaves the adaptation off, and the weighting by motion keeps its
  // inclination at 0.75° against VQF's 0.77° (1.00° without it, stop 56).
  EXPECT_EQ(above_vqf, std::vector<std::string>{"15 inclination_rmse_rad"});
  EXPECT_EQ(above_vqf_held_out, std::vector<std::string>{"15 inclination_rmse_rad"});
}

// rcal fuse --set NAME=VALUE: the whole value must be one finite number (std::stod took "0.1abc"
// as 0.1 and "nan" as NaN), refused naming the setting; the settings in the JSON carry their unit
// in the key, and --set takes the name with or without it.
TEST(RcalCli, FuseSetTakesOnlyWholeFiniteNumbersAndTheJsonNamesUnits) {
  const fs::path d = TempDir("fuse_set");
  {
    // One second at rest, IMU aligned with ENU (truth identity), north on +y, field dipping down.
    std::ofstream f(d / "trial.csv");
    f << "t_s,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z,q_w,q_x,q_y,q_z,pos_x,pos_y,"
         "pos_z,movement\n";
    for (int k = 0; k < 100; ++k)
      f << k * 0.01 << ",0,0,0,0,0,9.81,0,20,-40,1,0,0,0,0.1,0.2,0.3," << (k >= 50) << "\n";
  }
  const std::string fuse = "fuse " + (d / "trial.csv").string() + " ";
  for (const char* bad : {"0.1abc", "nan", "NaN", "inf", "-inf", "1e999", "", "abc", " 0.1", "0.1 ",
                          "0x1p-3", "0.1.2"}) {
    const Result r = RunRcal(fuse + "--set 'tilt_sigma=" + bad + "'");
    EXPECT_NE(r.exit_code, 0) << "'" << bad << "': " << r.output;
    EXPECT_NE(r.output.find("tilt_sigma"), std::string::npos) << "'" << bad << "': " << r.output;
  }
  // A whole-number setting takes a whole number in its range.
  for (const char* bad : {"3", "0", "1.5", "-1", "2e9"}) {
    const Result r = RunRcal(fuse + "--set accel_lowpass_order=" + bad);
    EXPECT_NE(r.exit_code, 0) << "'" << bad << "': " << r.output;
    EXPECT_NE(r.output.find("accel_lowpass_order"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("whole number from 1 to 2"), std::string::npos) << r.output;
  }
  // A switch takes 0 or 1; the hard iron's settings are checked by the library's own rule.
  for (const char* bad : {"2", "0.5", "-1"}) {
    const Result r = RunRcal(fuse + "--set mag_hard_iron=" + bad);
    EXPECT_NE(r.exit_code, 0) << "'" << bad << "': " << r.output;
    EXPECT_NE(r.output.find("mag_hard_iron: '"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("is not 0 or 1"), std::string::npos) << r.output;
  }
  for (const char* bad : {"mag_hard_iron_floor=-0.1", "mag_hard_iron_noise=0"}) {
    const Result r = RunRcal(fuse + "--set " + bad);
    EXPECT_NE(r.exit_code, 0) << bad << ": " << r.output;
    EXPECT_NE(r.output.find("mag_hard_iron."), std::string::npos) << r.output;
  }
  const Result ok = RunRcal(fuse +
                            "--set tilt_sigma=0.02 --set pos.accel_sigma_m_s2=2 --set "
                            "heading_sigma_rad=5e-2 --set accel_lowpass_order=2 --set "
                            "mag_hard_iron=0 --json " +
                            (d / "f.json").string());
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  const json j = ReadJson(d / "f.json");
  const json& s = j.at("settings");
  EXPECT_EQ(s.at("tilt_sigma_rad").get<double>(), 0.02);
  EXPECT_EQ(s.at("heading_sigma_rad").get<double>(), 0.05);
  EXPECT_EQ(s.at("pos.accel_sigma_m_s2").get<double>(), 2.0);
  EXPECT_EQ(s.at("gravity_m_s2").get<double>(), 9.81);
  EXPECT_EQ(s.at("accel_lowpass_order").get<int>(), 2);
  EXPECT_EQ(s.at("mag_hard_iron_flag").get<int>(), 0);
  // Every key ends in its unit; the dimensionless ones say what they are.
  for (const auto& [key, value] : s.items()) {
    bool named = false;
    for (const char* end : {"_m_s2", "_rad", "_s", "_rad_s", "_sqrt_hz", "_sqrt_s", "_chi2",
                            "_fraction", "_m", "_factor", "_order", "_flag", "_count"})
      named |= key.size() > std::string(end).size() &&
               key.compare(key.size() - std::string(end).size(), std::string::npos, end) == 0;
    EXPECT_TRUE(named) << key;
  }
  EXPECT_TRUE(j.at("mag_reference").contains("norm_uT")) << j.at("mag_reference").dump();
}
