// `rcal track DATA --robot R --trace T --json F` on a simulated dataset whose arm changes: rows
// out of time order are taken in time order, the trace has one row per data row, the JSON names
// the change.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "rcal/io/atomic_file.hpp"
#include "rcal/io/pose_dataset.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal_cli.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;

TEST(Track, TraceAndJsonOfAStepInTimeOrder) {
  const fs::path dir = fs::temp_directory_path() / "rcal_track_test";
  fs::remove_all(dir);
  fs::create_directories(dir);
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

}  // namespace
}  // namespace rcal::tool
