// `rcal plan-poses` as a user runs it (issue 16): the stops file drives a run (q1..qN, SI, inside
// the limits and the cell's constraints), more informative than random stops, and bad input is
// refused naming the option or the key. Also tools/rcal/plan_poses' stops file format.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "plan_poses.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal_cli.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;
using testing::RunRcal;

TEST(PlanPoses, WritesStopsInsideTheLimitsThatRaiseTheInformation) {
  const fs::path out = testing::TempDir("plan_poses", "stops") / "P.csv";
  const auto r = RunRcal(
      "plan-poses --robot tests/data/arms/kr6_like.urdf --count 12 "
      "--candidates 1500 --position-only --seed 3 --out " +
          out.string(),
      120);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const io::CsvTable t = io::CsvTable::Load(out);
  ASSERT_EQ(t.rows(), 12);
  ASSERT_EQ(t.header(), (std::vector<std::string>{"q1", "q2", "q3", "q4", "q5", "q6"}));
  io::UrdfOptions uo;
  const auto model = io::LoadRobotUrdf(RCAL_SOURCE_DIR "/tests/data/arms/kr6_like.urdf", uo);
  for (int i = 0; i < t.rows(); ++i) {
    Eigen::VectorXd q(6);
    for (int j = 0; j < 6; ++j) q(j) = t.At(i, t.header()[j]);
    EXPECT_TRUE(model.WithinLimits(q)) << "row " << i;
  }
  // The planned log det is above the random stops' median it prints beside it.
  const auto at = r.output.find("log det information: planned ");
  ASSERT_NE(at, std::string::npos) << r.output;
  double planned = 0, random = 0;
  ASSERT_EQ(std::sscanf(r.output.c_str() + at,
                        "log det information: planned %lf, 12 random stops median %lf", &planned,
                        &random),
            2)
      << r.output;
  EXPECT_GT(planned, random + 1.0);
  // The file drives a simulated run: rcal simulate measures at exactly these stops.
  const fs::path data = out.parent_path() / "data.csv";
  const auto sim = RunRcal("simulate --robot tests/data/arms/kr6_like.urdf --joints " +
                               out.string() + " --out " + data.string(),
                           120);
  ASSERT_EQ(sim.exit_code, 0) << sim.output;
  const io::CsvTable d = io::CsvTable::Load(data);
  ASSERT_EQ(d.rows(), 12);
  for (int i = 0; i < 12; ++i)
    for (const auto& column : t.header()) EXPECT_EQ(d.At(i, column), t.At(i, column));
  // A stop outside the limits is refused naming the row and the column.
  std::string text = io::ReadFile(out);
  std::ofstream(out.parent_path() / "bad.csv") << text << "0,0,99,0,0,0\n";
  const auto bad = RunRcal("simulate --robot tests/data/arms/kr6_like.urdf --joints " +
                           (out.parent_path() / "bad.csv").string() + " --out " + data.string());
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("row 13, column q3"), std::string::npos) << bad.output;
}

TEST(PlanPoses, BadInputIsRefusedNamingIt) {
  const fs::path dir = testing::TempDir("plan_poses", "bad");
  EXPECT_NE(RunRcal("plan-poses --robot tests/data/arms/kr6_like.urdf --count 0 --out " +
                    (dir / "P.csv").string())
                .output.find("--count: at least 1"),
            std::string::npos);
  const auto none = RunRcal("plan-poses --count 5 --out " + (dir / "P.csv").string());
  EXPECT_NE(none.exit_code, 0);
  EXPECT_NE(none.output.find("--robot or --cell"), std::string::npos) << none.output;
  // A cell whose task region no configuration reaches, asked for task weighting.
  std::string cell = io::ReadFile(RCAL_SOURCE_DIR "/config/cells/ur10.yaml");
  cell.replace(cell.find("../robots/ur10.urdf"), 19, RCAL_SOURCE_DIR "/config/robots/ur10.urdf");
  cell += "constraints: {task_region: {min: [20, 20, 20], max: [21, 21, 21]}}\n";
  std::ofstream(dir / "far.yaml") << cell;
  const auto far =
      RunRcal("plan-poses --cell " + (dir / "far.yaml").string() +
              " --count 5 --candidates 200 --task-weighting --out " + (dir / "P.csv").string());
  EXPECT_NE(far.exit_code, 0);
  EXPECT_NE(far.output.find("constraints.task_region"), std::string::npos) << far.output;
  EXPECT_FALSE(fs::exists(dir / "P.csv"));
  // The report's cell mode: a sim file that is not there, no programmes, a negative noise.
  const std::string report = "plan-poses-report --out " + (dir / "report").string();
  const auto missing = RunRcal(report + " --sim " + (dir / "none.sim.yaml").string());
  EXPECT_NE(missing.exit_code, 0);
  EXPECT_NE(missing.output.find("none.sim.yaml"), std::string::npos) << missing.output;
  const auto no_seeds = RunRcal(report + " --sim config/cells/grb3016.sim.yaml --seeds 0");
  EXPECT_NE(no_seeds.exit_code, 0);
  EXPECT_NE(no_seeds.output.find("--seeds"), std::string::npos) << no_seeds.output;
  const auto negative =
      RunRcal(report + " --sim config/cells/grb3016.sim.yaml --orientation-sigma-mrad -1");
  EXPECT_NE(negative.exit_code, 0);
  EXPECT_NE(negative.output.find("--orientation-sigma-mrad"), std::string::npos) << negative.output;
  EXPECT_FALSE(fs::exists(dir / "report" / "report.json"));
}

// `rcal plan-poses-report --sim` on the demo's cell (issue 16's "online next-best reaches the
// 50-random-stop accuracy of the demo's cell in ≤ 20 stops"): the live identifier's logic on the
// programmes of seeds 1–8, poses with a still window's noise, against the simulator's truth at
// the programmes' test stops. The report's two claims hold: linearised, no 20 stops from the
// candidates predict the error 50 random stops predict (the certified relaxation bound); and
// measured, 20 stops of online next-best are short of 50 random stops, while 50 of them beat 20
// random ones.
TEST(PlanPoses, OnTheDemoCellNoTwentyStopsReachFiftyRandomOnes) {
  const fs::path dir = testing::TempDir("plan_poses", "cell");
  const auto r = RunRcal(
      "plan-poses-report --sim config/cells/grb3016.sim.yaml --seeds 8 --counts 20,50 --jobs 2 "
      "--out " +
          dir.string(),
      300);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(dir / "report.md"));
  const auto j = nlohmann::json::parse(io::ReadFile(dir / "report.json"));
  EXPECT_EQ(j.at("cell"), "grb3016_demo");
  EXPECT_EQ(j.at("position_noise_m"), 5.1e-5);
  const double bound20 = j.at("predicted_rms_any20_at_least_m");
  const double random50_predicted = j.at("predicted_rms_random50_m");
  EXPECT_GT(bound20, 1.2 * random50_predicted);
  const auto median = [&](size_t row, const char* strategy) {
    return j.at("by_count").at(row).at(strategy).at("median_m").get<double>();
  };
  const char* random = kStrategyNames[kRandom];
  const char* next_best = kStrategyNames[kNextBest];
  std::printf(
      "demo cell: random %.1f / %.1f µm, next-best %.1f / %.1f µm at 20 / 50 stops; any "
      "20 stops predict ≥ %.1f µm, 50 random %.1f µm\n",
      median(0, random) * 1e6, median(1, random) * 1e6, median(0, next_best) * 1e6,
      median(1, next_best) * 1e6, bound20 * 1e6, random50_predicted * 1e6);
  EXPECT_GT(median(0, next_best), median(1, random));
  EXPECT_LT(median(1, next_best), median(0, random));
  EXPECT_NE(j.at("next_best_stops_to_random50").get<std::string>(), "20");
}

TEST(PlanPoses, StopsFileIsSiWithSeventeenDigits) {
  const std::vector<Eigen::VectorXd> stops = {Eigen::Vector2d(0.1, -1.0 / 3.0),
                                              Eigen::Vector2d(2.0, 1e-17)};
  const std::string text = JointsCsv(stops, {"made by a test"});
  const io::CsvTable t = io::CsvTable::Parse(text, "P.csv");
  ASSERT_EQ(t.rows(), 2);
  EXPECT_EQ(t.comments().size(), 1u);
  EXPECT_EQ(t.At(0, "q2"), -1.0 / 3.0);  // exactly: 17 significant digits round-trip
  EXPECT_EQ(t.At(1, "q2"), 1e-17);
}

}  // namespace
}  // namespace rcal::tool
