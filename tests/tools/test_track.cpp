// `rcal track DATA --robot R --trace T --json F` on a simulated dataset whose arm changes: rows
// out of time order are taken in time order, the trace has one row per data row, the JSON names
// the change.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/cell/discrepancy_watch.hpp"
#include "rcal/cell/online_identification.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/effects_json.hpp"
#include "rcal/io/pose_dataset.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/sim/effects.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal_cli.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;

// `rcal track --sweep --random-arms N` runs the sweep on arms nothing was tuned on: each random
// D–H arm as full poses (with an IMU frame to identify) and as positions only, the arm named in
// the JSON; --arm with --random-arms, and seeds past 999, are refused naming the option.
TEST(Track, TheSweepRunsOnRandomArmsAndFurtherSeeds) {
  const fs::path dir = testing::TempDir("track", "sweep_random");
  const auto r = testing::RunRcal(
      "track --sweep --random-arms 1 --first-arm 7 --seeds 1 "
      "--first-seed 3 --quiet-poses 0 --jobs 2 --out " +
      dir.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto j = nlohmann::json::parse(io::ReadFile(dir / "track_sweep.json"));
  ASSERT_EQ(j["results"].size(), 4u);  // full pose, positions × joint offset, link length
  for (size_t i = 0; i < 4; ++i) {
    const auto& res = j["results"][i];
    EXPECT_EQ(res["arm"], "random_dh_7");
    EXPECT_EQ(res["full_pose"], i < 2);
    EXPECT_EQ(res["first_seed"], 3);
    EXPECT_EQ(res["seeds"], 1);
  }
  // Seed 3 steps joint 3 % 6 of the arm.
  EXPECT_EQ(j["results"][0]["stepped"][0], "j4");
  const auto both = testing::RunRcal(
      "track --sweep --random-arms 1 --arm config/robots/ur10.urdf --out " + dir.string());
  EXPECT_NE(both.exit_code, 0);
  EXPECT_NE(both.output.find("--random-arms"), std::string::npos) << both.output;
  const auto late =
      testing::RunRcal("track --sweep --first-seed 995 --seeds 10 --out " + dir.string());
  EXPECT_NE(late.exit_code, 0);
  EXPECT_NE(late.output.find("--first-seed"), std::string::npos) << late.output;
}

TEST(Track, TraceAndJsonOfAStepInTimeOrder) {
  const fs::path dir = testing::TempDir("track", "test");
  // The KR6-like arm with the frames `--frames auto` gives it (world ← base, marker 0).
  io::UrdfOptions uo;
  uo.add_base_frame = true;
  uo.add_marker = true;
  const auto model =
      io::LoadRobotUrdf(std::string(RCAL_SOURCE_DIR) + "/tests/data/arms/kr6_like.urdf", uo);
  sim::Rng rng(81);
  sim::PoseNoise noise;
  noise.orientation = false;
  io::PoseDataset data;
  data.num_joints = model.num_joints();
  Eigen::VectorXd x_true = model.Nominal();
  for (int i = 0; i < model.num_params(); ++i)
    x_true(i) += model.parameters()[i].is_angle ? 0.0 : 2e-4 * ((i % 3) - 1);
  for (int k = 0; k < 420; ++k) {
    const Eigen::VectorXd q = sim::SampleJoints(model, 1, rng)[0];
    Eigen::VectorXd q_arm = q;
    if (k >= 350) q_arm(1) += 1e-3;  // joint 2 reads 1 mrad off from t = 350 s
    io::PoseSample s;
    s.q = q;
    s.p_WM_W = sim::MeasurePose(model, x_true, q_arm, noise, rng).p_WM_W;
    s.time = k;
    s.set = k % 7 == 6 ? io::PoseSample::kTest : io::PoseSample::kCal;
    data.samples.push_back(s);
  }
  std::swap(data.samples[10], data.samples[11]);  // file order is not time order
  io::SavePoseDataset(dir / "poses.csv", data);
  const testing::Result r = testing::RunRcal(
      "track " + (dir / "poses.csv").string() + " --robot tests/data/arms/kr6_like.urdf --trace " +
      (dir / "trace.csv").string() + " --json " + (dir / "track.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream trace(dir / "trace.csv");
  std::string line;
  std::getline(trace, line);
  EXPECT_EQ(line, "time,set,prediction_error_m,status,changed,nis");
  std::vector<std::string> lines;
  while (std::getline(trace, line)) lines.push_back(line);
  ASSERT_EQ(lines.size(), 420u);
  EXPECT_EQ(lines[10].substr(0, 10), "10.000000,");  // sorted by time
  EXPECT_EQ(lines[6].find("6.000000,test,"), 0u) << lines[6];
  const auto j = nlohmann::json::parse(io::ReadFile(dir / "track.json"));
  ASSERT_EQ(j["changes"].size(), 1u) << j.dump(1);
  const auto& c = j["changes"][0];
  EXPECT_GE(c["time_s"].get<double>(), 350);
  EXPECT_LE(c["time_s"].get<double>(), 357);
  // The joint's offset, as a direction or as the rotation parameter about its axis.
  const std::string name = c["changed"][0]["name"].get<std::string>();
  EXPECT_TRUE(name == "offset of joint joint_a2" || name.rfind("joint_a2_dr", 0) == 0) << c.dump();
  EXPECT_EQ(j["segments"].size(), 2u);
  fs::remove_all(dir);
}

// `rcal track LOG --cell CELL` runs the process's logic on the process's input: each logged pose
// with the covariance its still window gave, in the order logged. Independent truth: the cell's
// OnlineIdentification (what ekf_identifier runs) on the same messages, pose by pose NIS. Before,
// a log's poses took the fixed --position-sigma-mm: on the live demo's log the replayed NIS
// differed from the live identifier's from the first poses on, and so did the change it found.
TEST(Track, AnLcmLogRunsWithEachPosesOwnCovarianceAsTheIdentifierDoes) {
  const fs::path dir = testing::TempDir("track", "log_test");
  const std::string cell_file = std::string(RCAL_SOURCE_DIR) + "/config/cells/grb3016.yaml";
  const io::BuiltCell built = io::LoadCell(cell_file);
  sim::Rng rng(83);
  Eigen::VectorXd x_true = built.model.Nominal();
  for (int i = 0; i < built.model.num_params(); ++i)
    x_true(i) += built.model.parameters()[i].is_angle ? 2e-4 : 2e-4 * ((i % 3) - 1);
  std::vector<pose_measurement_t> msgs;
  {
    lcm::LogFile log((dir / "run.lcmlog").string(), "w");
    ASSERT_TRUE(log.good());
    for (int k = 0; k < 40; ++k) {
      auto z = sim::MeasurePose(built.model, x_true, sim::SampleJoints(built.model, 1, rng)[0],
                                sim::PoseNoise{}, rng);
      z.covariance *= 1.0 + (k % 4);  // each window its own σ, none the default
      msgs.push_back(transport::ToMessage(z, (k + 1) * 1'000'000, k));
      std::vector<unsigned char> buf(msgs.back().getEncodedSize());
      msgs.back().encode(buf.data(), 0, static_cast<int>(buf.size()));
      lcm::LogEvent e{0, (k + 1) * 1'000'000, transport::channels::kPoseMeasurement,
                      static_cast<int32_t>(buf.size()), buf.data()};
      ASSERT_EQ(log.writeEvent(&e), 0);
    }
  }
  const testing::Result r =
      testing::RunRcal("track " + (dir / "run.lcmlog").string() + " --cell " + cell_file +
                       " --trace " + (dir / "trace.csv").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::map<int64_t, double> nis;  // pose_index → NIS, as the identifier computes it
  cell::OnlineIdentification id(built);
  for (const auto& m : msgs) {
    std::string error;
    const auto z = transport::FromMessage(m, &error, &built.model);
    ASSERT_TRUE(z) << error;
    for (const auto& u : id.Add({*z, m.utime, m.pose_index, {}}).updates)
      nis[u.pose_index] = u.result.nis;
  }
  std::ifstream trace(dir / "trace.csv");
  std::string line;
  std::getline(trace, line);
  int compared = 0;
  for (int64_t k = 0; std::getline(trace, line); ++k) {
    const std::string last = line.substr(line.rfind(',') + 1);
    if (last.empty()) continue;  // held for the set-up guess at that row
    ASSERT_TRUE(nis.count(k)) << line;
    EXPECT_NEAR(std::stod(last), nis[k], 1e-5 * std::max(1.0, nis[k])) << "row " << k + 1;
    ++compared;
  }
  EXPECT_GE(compared, 30);
  fs::remove_all(dir);
}

// A log of 80 poses of the pose-level GRB3016 cell's arm with `effect` hidden (each pose logged
// with its context) at dir/run.lcmlog; the poses as a reader of the log gets them back.
std::vector<cell::TimedPose> WriteEffectLog(const fs::path& dir, const io::BuiltCell& built,
                                            const std::string& effect) {
  const cell::CellSimSpec sim_spec =
      cell::LoadCellSimSpec(std::string(RCAL_SOURCE_DIR) + "/config/cells/grb3016_poses.sim.yaml");
  const Eigen::VectorXd x_true = cell::TrueErrors(built, sim_spec);
  const sim::EffectTruth truth =
      sim::MakeEffectTruth(built.model, {sim::ParseEffectSpec(effect, built.model)});
  sim::PoseNoise noise;
  noise.position_sigma = built.spec.position.sigma.maxCoeff();
  noise.orientation_sigma = built.spec.position.orientation_sigma;
  sim::Rng rng(97), context_rng(98);
  std::vector<cell::TimedPose> poses;
  lcm::LogFile log((dir / "run.lcmlog").string(), "w");
  EXPECT_TRUE(log.good());
  Eigen::VectorXd q_before;
  const auto qs = sim::SampleJoints(built.model, 80, rng);
  for (int k = 0; k < 80; ++k) {
    const auto c = sim::StopContext(10.0 * k, qs[k], q_before, {}, context_rng);
    q_before = qs[k];
    const auto z = sim::MeasurePoseWithEffects(truth, x_true, qs[k], c, noise, rng);
    const pose_measurement_t m = transport::ToMessage(z, (k + 1) * 1'000'000, k, 0, c);
    std::vector<unsigned char> buf(m.getEncodedSize());
    m.encode(buf.data(), 0, static_cast<int>(buf.size()));
    lcm::LogEvent e{k, (k + 1) * 1'000'000, transport::channels::kPoseMeasurement,
                    static_cast<int32_t>(buf.size()), buf.data()};
    EXPECT_EQ(log.writeEvent(&e), 0);
    std::string error;  // what a reader of the log gets back
    const auto back = transport::FromMessage(m, &error, &built.model);
    EXPECT_TRUE(back) << error;
    if (back) poses.push_back({*back, m.utime, k, *transport::ContextFromMessage(m, &error)});
  }
  return poses;
}

// `rcal track LOG --cell CELL --discrepancy-every 50 --discrepancy-switch` on a log of an arm with
// one hidden effect: the watch names it after 50 poses and switches it in; the JSON's watch, the
// changes the switch withdrew and the final effect are what the library gives for the same poses
// run the same way: joint 2 bending (2e-6 rad/(N·m)), and 4e-4 rad of backlash on joint 2, on which
// the geometric identifier raises changes that the switch withdraws.
TEST(Track, TheDiscrepancyWatchRunsOverALogAsTheIdentifierRunsIt) {
  struct Case {
    std::string effect, named;
    double truth;
    bool raises_changes;  // the geometric identifier raises changes on it, so some are withdrawn
  };
  for (const Case& k : {Case{"joint_compliance:j2=2e-6", "joint_compliance j2", 2e-6, false},
                        Case{"backlash:j2=4e-4", "backlash j2", 4e-4, true}}) {
    SCOPED_TRACE(k.effect);
    const fs::path dir = testing::TempDir("track", "watch_test");
    const std::string cell_file = std::string(RCAL_SOURCE_DIR) + "/config/cells/grb3016_poses.yaml";
    const io::BuiltCell built = io::LoadCell(cell_file);
    const std::vector<cell::TimedPose> poses = WriteEffectLog(dir, built, k.effect);
    ASSERT_EQ(poses.size(), 80u);
    const testing::Result r = testing::RunRcal(
        "track " + (dir / "run.lcmlog").string() + " --cell " + cell_file +
        " --discrepancy-every 50 --discrepancy-switch --json " + (dir / "track.json").string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    nlohmann::json j;
    std::ifstream(dir / "track.json") >> j;
    ASSERT_EQ(j["discrepancy_watch"].size(), 1u) << j.dump(1);
    const auto& w = j["discrepancy_watch"][0];
    EXPECT_EQ(w["taken"], 50);  // accepted or refused by the gate
    EXPECT_LE(w["accepted"], 50);
    ASSERT_GE(w["suspects"].size(), 1u);
    EXPECT_EQ(w["suspects"][0]["effect"], k.named);
    EXPECT_EQ(w["switched_in"], nlohmann::json::array({k.named}));
    ASSERT_EQ(j["effects"].size(), 1u);
    // The library, the same poses, the same way.
    cell::OnlineIdentification id(built);
    cell::DiscrepancyWatchSettings s;
    std::vector<cell::WithdrawnChange> withdrawn;
    int window_steps = -1;
    for (const auto& p : poses) {
      const auto out = id.Add(p);
      if (!out.updates.empty() && cell::WatchDue(id, s)) {
        const cell::DiscrepancyReport report = cell::WatchForDiscrepancy(id, s);
        window_steps = report.window_steps;
        id.SwitchIn(report.NewEffects());
        withdrawn = id.withdrawn();
      }
    }
    // The changes released inside the window, fitted as steps by the watch.
    EXPECT_EQ(w["window_steps"], window_steps);
    ASSERT_EQ(id.ekf().num_effect_params(), 1);
    const double value = id.ekf().e()(0), sigma = id.ekf().sigma_e()(0);
    const io::AnalysisEffects tracked = io::ParseAnalysisEffects(j, built.model);
    ASSERT_EQ(tracked.values.size(), 1);
    std::printf("rcal track: %s %.6g; library %.6g ± %.2g (truth %.3g); %zu changes withdrawn\n",
                k.named.c_str(), tracked.values(0), value, sigma, k.truth, withdrawn.size());
    EXPECT_NEAR(value, k.truth, 3 * sigma);
    EXPECT_NEAR(tracked.values(0), value, 1e-9 * sigma);
    if (k.raises_changes) {
      EXPECT_FALSE(withdrawn.empty());
      EXPECT_GT(window_steps, 0);
    }
    ASSERT_EQ(w["withdrawn_changes"].size(), withdrawn.size());
    for (size_t i = 0; i < withdrawn.size(); ++i) {
      EXPECT_EQ(w["withdrawn_changes"][i]["onset_row"], withdrawn[i].onset_pose_index + 1)
          << "rows numbered from 1 for the first pose read";
      EXPECT_EQ(w["withdrawn_changes"][i]["changed"], withdrawn[i].names);
    }
    fs::remove_all(dir);
  }
}

}  // namespace
}  // namespace rcal::tool
