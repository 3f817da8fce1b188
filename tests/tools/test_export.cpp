// `rcal export` (tools/rcal/cmd_export.cpp) as a user runs it, from each input it accepts: the
// folder of `rcal calibrate` (URDF and YAML robots), an ekf_identifier checkpoint and the last
// KINEMATIC_PARAMS of an LCM log on a cell. The exported parameters are compared with the source
// they came from (the calibrate JSON, the identifier's own state, the logged message), the parity
// report must pass at 1 000 joint vectors, and bad input exits non-zero naming the field.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <lcm/lcm-cpp.hpp>

#include "rcal/cell/online_identification.hpp"
#include "rcal/io/calibration_export.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/checkpoint_json.hpp"
#include "rcal_cli.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;
using testing::ReadJson;
using testing::Result;
using testing::RunRcal;
using testing::TempDir;
constexpr const char* kCell = "config/cells/grb3016.yaml";

std::string Slurp(const fs::path& p) {
  std::ifstream in(p);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

// The parameters calibration.yaml lists, by name: error and σ (NaN: null).
std::map<std::string, std::pair<double, double>> YamlParameters(const fs::path& file) {
  std::map<std::string, std::pair<double, double>> out;
  const YAML::Node y = YAML::LoadFile(file.string());
  for (const YAML::Node& n : y["parameters"])
    out[n["name"].as<std::string>()] = {
        n["error"].as<double>(), n["sigma"].IsNull() ? std::nan("") : n["sigma"].as<double>()};
  return out;
}

void ExpectParityPassed(const fs::path& out) {
  const nlohmann::json p = ReadJson(out / "parity.json");
  EXPECT_TRUE(p["passed"].get<bool>());
  EXPECT_EQ(p["samples"].get<int>(), 1000);
  EXPECT_LT(p["max_position_error_m"].get<double>(), 1e-9);
  EXPECT_LT(p["max_orientation_error_rad"].get<double>(), 1e-9);
  const std::string hash = p["calibration_hash"];
  for (const char* f : {"robot_calibrated.urdf", "calibration.yaml", "parity.md"})
    EXPECT_NE(Slurp(out / f).find(hash), std::string::npos) << f;
}

class ExportFromCalibrate : public ::testing::TestWithParam<const char*> {};

TEST_P(ExportFromCalibrate, ParametersAreTheFittedOnesAndParityHolds) {
  const std::string robot = GetParam();
  const fs::path d = TempDir("export", fs::path(robot).stem().string());
  Result r = RunRcal("simulate --robot " + robot + " --poses 40 --seed 3 --out " +
                     (d / "data.csv").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunRcal("calibrate " + (d / "data.csv").string() + " --robot " + robot + " --out " +
              (d / "cal").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunRcal("export --calibration " + (d / "cal").string() + " --out " + (d / "x").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("PASSED"), std::string::npos) << r.output;
  ExpectParityPassed(d / "x");
  // Every identified parameter of results.json, value and σ, as exported (bit for bit: the
  // values pass through JSON and YAML at full precision).
  const nlohmann::json res = ReadJson(d / "cal" / "results.json");
  const auto exported = YamlParameters(d / "x" / "calibration.yaml");
  ASSERT_FALSE(res["parameters"].empty());
  for (const auto& p : res["parameters"]) {
    const auto e = exported.find(p["name"].get<std::string>());
    ASSERT_NE(e, exported.end()) << p["name"];
    EXPECT_EQ(e->second.first, p["value"].get<double>()) << p["name"];
    if (p["sigma"].is_null()) {  // calibrate's σ may be unknown (NaN, written null)
      EXPECT_TRUE(std::isnan(e->second.second)) << p["name"];
    } else {
      EXPECT_EQ(e->second.second, p["sigma"].get<double>()) << p["name"];
    }
  }
  EXPECT_EQ(exported.size(), res["calibration"]["parameters"].size());
  const YAML::Node y = YAML::LoadFile((d / "x" / "calibration.yaml").string());
  // Identified: exactly the parameters results.json lists (also where σ is unknown).
  size_t identified = 0;
  for (const YAML::Node& n : y["parameters"]) identified += n["identified"].as<bool>() ? 1 : 0;
  EXPECT_EQ(identified, res["parameters"].size());
  EXPECT_EQ(y["data"].as<std::string>(), (d / "data.csv").string());
  EXPECT_EQ(y["calibration_hash"].as<std::string>(), res["calibration"]["calibration_hash"]);
  // A URDF robot keeps its own file's links; a YAML robot gets one written from its links.
  const std::string urdf = Slurp(d / "x" / "robot_calibrated.urdf");
  EXPECT_NE(urdf.find("rcal_world_joint"), std::string::npos);
  // The UR10 chain gets a marker (--frames auto); the GRB3016 is measured at its D–H tool, the
  // frame after the written flange joint.
  EXPECT_NE(urdf.find(robot.ends_with(".urdf") ? "rcal_marker_joint" : "\"flange_joint\""),
            std::string::npos);

  // A results.json edited by hand (a value moved) no longer matches its hash: refused, named.
  nlohmann::json bad = res;
  bad["calibration"]["parameters"][0]["value"] = 0.25;
  { std::ofstream(d / "bad.json") << bad.dump(); }
  r = RunRcal("export --calibration " + (d / "bad.json").string() + " --out " +
              (d / "bad").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("calibration_hash"), std::string::npos) << r.output;
  bad = res;
  bad["calibration"]["parameters"][1]["value"] = "NaN";
  { std::ofstream(d / "bad.json") << bad.dump(); }
  r = RunRcal("export --calibration " + (d / "bad.json").string() + " --out " +
              (d / "bad").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("calibration.parameters[1].value: not a number"), std::string::npos)
      << r.output;
}

INSTANTIATE_TEST_SUITE_P(Robots, ExportFromCalibrate,
                         ::testing::Values("config/robots/ur10.urdf",
                                           "config/robots/grb3016.yaml"));

/// The cell's identifier after `n` simulated poses of an arm with seeded errors.
cell::OnlineIdentification Identified(int n) {
  io::BuiltCell cell = io::LoadCell(fs::path(RCAL_SOURCE_DIR) / kCell);
  const kinematics::KinematicModel model = cell.model;
  cell::OnlineIdentification id(std::move(cell));
  sim::Rng rng(5);
  Eigen::VectorXd x_true = Eigen::VectorXd::Zero(model.num_params());
  for (int i = 0; i < x_true.size(); ++i) x_true(i) = 1e-4 * std::sin(1.0 + i);
  const auto ms = sim::MeasurePoses(model, x_true, sim::SampleJoints(model, n, rng), {}, rng);
  for (int k = 0; k < n; ++k) id.Add({ms[k], 1'000'000 + 100'000 * k, k, {}});
  return id;
}

TEST(Export, FromTheIdentifiersCheckpoint) {
  const fs::path d = TempDir("export", "checkpoint");
  const cell::OnlineIdentification id = Identified(60);
  ASSERT_TRUE(id.started());
  transport::SaveCheckpoint(d / "ekf.json",
                            {transport::ModelId(id.model()), id.last_utime(), id.last_pose_index(),
                             id.ekf().Checkpoint(), id.held()});
  Result r = RunRcal("export --checkpoint " + (d / "ekf.json").string() + " --cell " + kCell +
                     " --out " + (d / "x").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ExpectParityPassed(d / "x");
  const auto exported = YamlParameters(d / "x" / "calibration.yaml");
  const Eigen::VectorXd x = id.ekf().x(), sigma = id.ekf().sigma();
  ASSERT_EQ(static_cast<int>(exported.size()), id.model().num_params());
  for (int i : id.ekf().identified()) {
    const auto& e = exported.at(id.model().parameters()[i].name);
    EXPECT_EQ(e.first, x(i));
    EXPECT_EQ(e.second, sigma(i));
  }
  // On another robot's cell: refused, naming the model id.
  r = RunRcal("export --checkpoint " + (d / "ekf.json").string() +
              " --cell config/cells/panda.yaml --out " + (d / "panda").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("model_id"), std::string::npos) << r.output;
  r = RunRcal("export --checkpoint " + (d / "ekf.json").string() + " --out " + (d / "y").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("needs --cell"), std::string::npos) << r.output;
}

void WriteParams(lcm::LogFile& log, const kinematic_params_t& msg, int64_t t) {
  std::vector<unsigned char> buf(msg.getEncodedSize());
  msg.encode(buf.data(), 0, static_cast<int>(buf.size()));
  lcm::LogEvent e;
  e.eventnum = 0;
  e.timestamp = t;
  e.channel = transport::channels::kKinematicParams;
  e.datalen = static_cast<int>(buf.size());
  e.data = buf.data();
  ASSERT_EQ(log.writeEvent(&e), 0);
}

TEST(Export, FromTheLastKinematicParamsOfALog) {
  const fs::path d = TempDir("export", "log");
  const cell::OnlineIdentification id = Identified(60);
  const kinematic_params_t first = transport::ToKinematicParams(id.ekf(), "grb3016", 5);
  kinematic_params_t last = first;
  last.utime = 9;
  for (double& v : last.values) v *= 2;  // the last one is what is exported
  {
    lcm::LogFile log((d / "run.lcmlog").string(), "w");
    ASSERT_TRUE(log.good());
    WriteParams(log, first, 5);
    WriteParams(log, last, 9);
  }
  Result r = RunRcal("export --log " + (d / "run.lcmlog").string() + " --cell " + kCell +
                     " --out " + (d / "x").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ExpectParityPassed(d / "x");
  const auto exported = YamlParameters(d / "x" / "calibration.yaml");
  for (size_t i = 0; i < last.names.size(); ++i) {
    EXPECT_EQ(exported.at(last.names[i]).first, last.values[i]);
    EXPECT_EQ(std::isnan(exported.at(last.names[i]).second), !last.identified[i]);
  }
  // A message with a value that is not finite: refused, naming the field.
  last.values[3] = std::nan("");
  {
    lcm::LogFile log((d / "nan.lcmlog").string(), "w");
    WriteParams(log, last, 9);
  }
  r = RunRcal("export --log " + (d / "nan.lcmlog").string() + " --cell " + kCell + " --out " +
              (d / "nan").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("kinematic_params.values"), std::string::npos) << r.output;
}

TEST(Export, RefusesMissingOrAmbiguousInput) {
  const fs::path d = TempDir("export", "bad");
  Result r = RunRcal("export --out " + (d / "x").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("give one of"), std::string::npos) << r.output;
  r = RunRcal("export --calibration " + (d / "none.json").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("none.json"), std::string::npos) << r.output;
  { std::ofstream(d / "old.json") << R"({"data": "x.csv", "parameters": []})"; }
  r = RunRcal("export --calibration " + (d / "old.json").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("calibration: missing"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace rcal::tool
