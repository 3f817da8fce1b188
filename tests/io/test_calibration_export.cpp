// rcal export's library (io/calibration_export.hpp, robot_urdf.hpp SpecUrdfText, UrdfChain): the
// exported URDF, reloaded through liburdfdom, is the identified model at 1 000 joint vectors for
// every arm rcal ships, YAML and URDF, with and without set-up frames; the parity check fails by
// the amount a model is moved; the record and parameter readers refuse hostile input by name.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "io_test_util.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/calibration_export.hpp"
#include "rcal/io/robot_urdf.hpp"

namespace rcal::io {
namespace {

using testing::ErrorOf;
using testing::SourceDir;

/// Seeded parameter errors: 2 mm and 10 mrad scale (a badly built arm), σ on every other one.
ModelParameters RandomParameters(const kinematics::KinematicModel& model, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  ModelParameters p;
  p.x.resize(model.num_params());
  p.sigma.resize(model.num_params());
  for (int i = 0; i < model.num_params(); ++i) {
    p.x(i) = n(rng) * (model.parameters()[i].is_angle ? 0.01 : 0.002);
    p.sigma(i) = i % 2 ? std::nan("") : 1e-5 * (1 + i);
  }
  return p;
}

/// A robot file with or without the four set-up frames (world ← base, two markers, IMU, earth).
struct Arm {
  std::string file;
  LoadedRobot robot;
  std::string urdf_xml;  ///< empty for YAML robots
};

Arm LoadArm(const std::filesystem::path& path, bool setup) {
  UrdfOptions uo;
  uo.add_base_frame = setup;
  uo.add_marker = setup;
  uo.base_xyz = {0.8, -0.3, 0.05};
  uo.base_rpy = {0.02, -0.01, 1.2};
  uo.marker_xyz = {0.01, -0.02, 0.12};
  Arm a{path.filename().string(), LoadRobot(path, uo), {}};
  RobotSpec& s = a.robot.spec;
  if (setup) {
    if (!s.base) s.base = FrameSpec{uo.base_xyz, uo.base_rpy, true};
    if (s.markers.empty()) s.markers.push_back({0, uo.marker_xyz, true});
    s.markers.push_back({3, {-0.03, 0.04, 0.09}, true});
    s.imu = FrameSpec{{0, 0, 0}, {0.1, -0.2, 0.3}, true};
    s.earth = FrameSpec{{0, 0, 0}, {0.01, 0.02, -2.0}, true};
  } else {
    s.base.reset();
    s.markers.clear();
    s.imu.reset();
    s.earth.reset();
  }
  a.robot.model = BuildModel(s);
  if (a.robot.from_urdf) a.urdf_xml = ReadFile(path);
  return a;
}

std::vector<std::filesystem::path> AllArms() {
  std::vector<std::filesystem::path> out;
  for (const char* dir : {"tests/data/arms", "config/robots"})
    for (const auto& e : std::filesystem::directory_iterator(SourceDir() / dir)) {
      const std::string ext = e.path().extension().string();
      if (ext == ".urdf" || ext == ".yaml") out.push_back(e.path());
    }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(CalibrationExport, ParityAtThousandJointVectorsForEveryArm) {
  const std::vector<std::filesystem::path> arms = AllArms();
  ASSERT_GE(arms.size(), 8u);  // 5 test arms, 2 YAML and 1 URDF robot in config/robots
  int urdf_sources = 0, yaml_sources = 0;
  std::vector<double> max_p, max_o;  // per arm and route, for the README's figures
  for (const auto& path : arms) {
    for (bool setup : {false, true}) {
      const Arm a = LoadArm(path, setup);
      const auto& model = a.robot.model;
      const ModelParameters p = RandomParameters(model, 7);
      // A URDF robot both ways: its own file calibrated, and written from its spec.
      std::vector<std::string> sources = {""};
      if (!a.urdf_xml.empty()) sources.push_back(a.urdf_xml);
      for (const std::string& xml : sources) {
        SCOPED_TRACE(a.file + (setup ? " with" : " without") + " set-up frames, " +
                     (xml.empty() ? "URDF written from the spec" : "its own URDF calibrated"));
        const std::string urdf = RobotDescriptionUrdf(a.robot.spec, model, p.x, xml, a.file);
        if (xml.empty()) {
          EXPECT_NE(urdf.find("  <!-- Written by rcal"), std::string::npos);
        }
        const ParityReport r = CheckUrdfParity(urdf, a.robot.spec, model, p.x);
        EXPECT_TRUE(r.passed);
        EXPECT_EQ(r.samples, 1000);
        EXPECT_LT(r.max_position_m, 1e-9);
        EXPECT_LT(r.max_orientation_rad, 1e-9);
        // Position of every marker and the tool orientation, plus R_EI with an IMU.
        const size_t expected = std::max<size_t>(1, model.markers().size()) + 1 + (setup ? 1 : 0);
        EXPECT_EQ(r.checks.size(), expected);
        for (const ParityCheck& c : r.checks) EXPECT_EQ(c.errors.size(), 1000u) << c.what;
        max_p.push_back(r.max_position_m);
        max_o.push_back(r.max_orientation_rad);
        (xml.empty() ? yaml_sources : urdf_sources) += 1;
      }
    }
  }
  EXPECT_GE(urdf_sources, 12);  // 6 URDF arms × with/without
  EXPECT_GE(yaml_sources, 16);  // every arm written from its spec too
  std::sort(max_p.begin(), max_p.end());
  std::sort(max_o.begin(), max_o.end());
  std::printf(
      "%zu exports: largest error over 1000 joint vectors, median over exports %.3g m / "
      "%.3g rad, worst %.3g m / %.3g rad\n",
      max_p.size(), max_p[max_p.size() / 2], max_o[max_o.size() / 2], max_p.back(), max_o.back());
}

// The check can fail, and fails by exactly what moved: the world frame shifted by 3 µm after the
// URDF was written moves every marker by 3 µm and turns nothing.
TEST(CalibrationExport, ParityFailsByTheShiftOfTheWorldFrame) {
  const Arm a = LoadArm(SourceDir() / "config/robots/grb3016.yaml", true);
  const ModelParameters p = RandomParameters(a.robot.model, 3);
  const std::string urdf = RobotDescriptionUrdf(a.robot.spec, a.robot.model, p.x);
  Eigen::VectorXd moved = p.x;
  moved(a.robot.model.FindParameter("base_y")) += 3e-6;
  ParityOptions o;
  o.samples = 200;
  const ParityReport r = CheckUrdfParity(urdf, a.robot.spec, a.robot.model, moved, o);
  EXPECT_FALSE(r.passed);
  EXPECT_NEAR(r.max_position_m, 3e-6, 1e-12);
  EXPECT_NEAR(r.median_position_m, 3e-6, 1e-12);
  EXPECT_LT(r.max_orientation_rad, 1e-12);
  // A yaw of the earth frame by 2 µrad turns R_EI by 2 µrad, nothing else.
  moved = p.x;
  moved(a.robot.model.FindParameter("earth_rz")) += 2e-6;
  const ParityReport e = CheckUrdfParity(urdf, a.robot.spec, a.robot.model, moved, o);
  EXPECT_FALSE(e.passed);
  EXPECT_NEAR(e.max_orientation_rad, 2e-6, 1e-12);
  EXPECT_LT(e.max_position_m, 1e-12);
}

// UrdfChain against the closed form of a planar two-link arm with a prismatic wrist.
TEST(CalibrationExport, UrdfChainIsTheClosedFormOfAPlanarArm) {
  const std::string xml = R"(<robot name="planar">
  <link name="b"/><link name="l1"/><link name="l2"/><link name="t"/>
  <joint name="q1" type="revolute"><parent link="b"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="q2" type="continuous"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 0 1"/></joint>
  <joint name="q3" type="prismatic"><parent link="l2"/><child link="t"/>
    <origin xyz="0.3 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.2" effort="1" velocity="1"/></joint>
</robot>)";
  const UrdfChain c(xml, "planar.urdf", "b", "t");
  ASSERT_EQ(c.joint_names(), (std::vector<std::string>{"q1", "q2", "q3"}));
  const double q1 = 0.7, q2 = -1.1, q3 = 0.05;
  const Eigen::Isometry3d T = c.Pose(Eigen::Vector3d(q1, q2, q3));
  EXPECT_NEAR(T.translation().x(), 0.5 * std::cos(q1) + (0.3 + q3) * std::cos(q1 + q2), 1e-15);
  EXPECT_NEAR(T.translation().y(), 0.5 * std::sin(q1) + (0.3 + q3) * std::sin(q1 + q2), 1e-15);
  EXPECT_NEAR(T.translation().z(), 0.1, 1e-15);
  EXPECT_NEAR(Eigen::AngleAxisd(T.linear()).angle(), std::abs(q1 + q2), 1e-15);
  EXPECT_NE(ErrorOf([&] { UrdfChain(xml, "planar.urdf", "t", "b"); }).find("not below"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { UrdfChain(xml, "planar.urdf", "b", "x"); }).find("link 'x'"),
            std::string::npos);
}

TEST(CalibrationExport, HashFollowsTheParametersAndTheModel) {
  const Arm a = LoadArm(SourceDir() / "config/robots/grb3016.yaml", true);
  const ModelParameters p = RandomParameters(a.robot.model, 1);
  const std::string h = CalibrationHash(a.robot.model, p.x);
  EXPECT_EQ(h.rfind("fnv1a64:", 0), 0u);
  EXPECT_EQ(h.size(), 8u + 16u);
  EXPECT_EQ(h, CalibrationHash(BuildModel(a.robot.spec), p.x));
  Eigen::VectorXd y = p.x;
  y(4) = std::nextafter(y(4), 1.0);
  EXPECT_NE(h, CalibrationHash(a.robot.model, y));
  const Arm b = LoadArm(SourceDir() / "config/robots/grb3016.yaml", false);
  EXPECT_NE(CalibrationHash(b.robot.model, Eigen::VectorXd::Zero(b.robot.model.num_params())),
            CalibrationHash(a.robot.model, Eigen::VectorXd::Zero(a.robot.model.num_params())));
}

TEST(CalibrationExport, ParametersByNameRefusesHostileLists) {
  const Arm a = LoadArm(SourceDir() / "config/robots/grb3016.yaml", true);
  const auto& m = a.robot.model;
  std::vector<std::string> names;
  std::vector<double> values, sigmas;
  for (int i = 0; i < m.num_params(); ++i) {
    names.push_back(m.parameters()[i].name);
    values.push_back(1e-4 * i);
    sigmas.push_back(i % 3 ? 1e-6 : std::nan(""));
  }
  // Order does not matter: names map.
  std::vector<std::string> rn(names.rbegin(), names.rend());
  std::vector<double> rv(values.rbegin(), values.rend()), rs(sigmas.rbegin(), sigmas.rend());
  const ModelParameters p = ParametersByName(m, rn, rv, rs, "f");
  for (int i = 0; i < m.num_params(); ++i) EXPECT_EQ(p.x(i), values[i]);
  EXPECT_TRUE(std::isnan(p.sigma(0)));
  EXPECT_EQ(p.sigma(1), 1e-6);

  auto err = [&](std::vector<std::string> n, std::vector<double> v, std::vector<double> s) {
    return ErrorOf([&] { ParametersByName(m, n, v, s, "f.parameters"); });
  };
  auto n2 = names;
  n2[2] = "shoulder_pan_joint_dx";
  EXPECT_NE(err(n2, values, sigmas)
                .find("f.parameters[2] 'shoulder_pan_joint_dx': not a "
                      "parameter of robot 'grb3016'"),
            std::string::npos);
  n2 = names;
  n2[2] = names[1];
  EXPECT_NE(err(n2, values, sigmas).find("given twice"), std::string::npos);
  auto v2 = values;
  v2[5] = std::nan("");
  EXPECT_NE(err(names, v2, sigmas).find("[5] '" + names[5] + "': value is not finite"),
            std::string::npos);
  auto s2 = sigmas;
  s2[4] = -1;
  EXPECT_NE(err(names, values, s2).find("sigma must be finite"), std::string::npos);
  s2[4] = std::numeric_limits<double>::infinity();
  EXPECT_NE(err(names, values, s2).find("sigma must be finite"), std::string::npos);
  EXPECT_NE(err({names.begin(), names.end() - 1}, {values.begin(), values.end() - 1}, {})
                .find("parameter '" + names.back() + "' of robot 'grb3016' is missing"),
            std::string::npos);
  EXPECT_NE(err(names, {values.begin(), values.end() - 1}, sigmas).find("values"),
            std::string::npos);
}

TEST(CalibrationExport, RecordRoundTripsToTheSameModel) {
  for (const char* file : {"config/robots/grb3016.yaml", "config/robots/ur10.urdf",
                           "config/robots/seven_dof.yaml", "tests/data/arms/panda_like.urdf"}) {
    SCOPED_TRACE(file);
    const Arm a = LoadArm(SourceDir() / file, true);
    const ModelParameters p = RandomParameters(a.robot.model, 5);
    const std::string text =
        CalibrationRecordJson(a.robot.spec, a.robot.model, p, file, "poses.csv", "2026-12-02")
            .dump();
    const CalibrationRecord r = ParseCalibrationRecord(text, "results.json");
    const kinematics::KinematicModel model = BuildModel(r.spec);
    const ModelParameters back = ParametersByName(model, r.names, r.values, r.sigmas, "p");
    EXPECT_EQ(CalibrationHash(model, back.x), r.calibration_hash);
    EXPECT_EQ(r.calibration_hash, CalibrationHash(a.robot.model, p.x));
    EXPECT_EQ(r.spec.base_link, a.robot.spec.base_link);
    EXPECT_EQ(r.data, "poses.csv");
    for (int i = 0; i < model.num_params(); ++i) {
      EXPECT_EQ(std::isnan(back.sigma(i)), std::isnan(p.sigma(i)));
      EXPECT_EQ(back.Identified(i), p.Identified(i));
    }
    // Identified with an unknown σ (null) stays identified.
    ModelParameters unknown = p;
    unknown.identified.assign(model.num_params(), true);
    const CalibrationRecord u = ParseCalibrationRecord(
        CalibrationRecordJson(a.robot.spec, a.robot.model, unknown, file, "d", "t").dump(), "u");
    const ModelParameters ub =
        ParametersByName(model, u.names, u.values, u.sigmas, "u", u.identified);
    EXPECT_TRUE(std::isnan(ub.sigma(1)));
    EXPECT_TRUE(ub.Identified(1));
  }
}

TEST(CalibrationExport, RecordParserNamesTheField) {
  const Arm a = LoadArm(SourceDir() / "config/robots/grb3016.yaml", true);
  const ModelParameters p = RandomParameters(a.robot.model, 5);
  const nlohmann::json good =
      CalibrationRecordJson(a.robot.spec, a.robot.model, p, "g.yaml", "d.csv", "2026-12-02");
  auto err = [](const nlohmann::json& j) {
    return ErrorOf([&] { ParseCalibrationRecord(j.dump(), "r.json"); });
  };
  auto j = good;
  j.erase("tip_link");
  EXPECT_NE(err(j).find("r.json: tip_link: missing"), std::string::npos);
  j = good;
  j["schema"] = "rcal.calibration/9";
  EXPECT_NE(err(j).find("schema: 'rcal.calibration/9'"), std::string::npos);
  j = good;
  j["parameters"][3]["value"] = "0.1";
  EXPECT_NE(err(j).find("parameters[3].value: not a number"), std::string::npos);
  j = good;
  j["parameters"][2]["sigma"] = "x";
  EXPECT_NE(err(j).find("parameters[2].sigma"), std::string::npos);
  j = good;
  j["robot"] = "ur10";
  EXPECT_NE(err(j).find("robot: 'ur10', robot_yaml names 'grb3016'"), std::string::npos);
  j = good;
  j["robot_yaml"] = "schema: rcal.robot/1\nname: x\n";
  EXPECT_NE(err(j).find("robot_yaml"), std::string::npos);
  EXPECT_NE(err(nlohmann::json{{"calibration", {{"schema", 3}}}}).find("calibration.schema"),
            std::string::npos);
  EXPECT_NE(err(nlohmann::json{{"data", "x"}}).find("calibration: missing"), std::string::npos);
  EXPECT_NE(ErrorOf([] { ParseCalibrationRecord("{\"a\": [1,", "r.json"); }).find("not JSON"),
            std::string::npos);
  // Nested under `calibration` (a results.json) it reads the same.
  const CalibrationRecord r =
      ParseCalibrationRecord(nlohmann::json{{"calibration", good}}.dump(), "results.json");
  EXPECT_EQ(r.calibration_hash, good["calibration_hash"]);
}

TEST(CalibrationExport, SpecUrdfRefusesWhatItCannotWrite) {
  const Arm a = LoadArm(SourceDir() / "config/robots/grb3016.yaml", true);
  Eigen::VectorXd x = a.robot.model.Nominal();
  x(a.robot.model.FindParameter("d3")) = std::nan("");
  EXPECT_NE(ErrorOf([&] {
              SpecUrdfText(a.robot.spec, a.robot.model, x);
            }).find("parameter 'd3' is not finite"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] {
              SpecUrdfText(a.robot.spec, a.robot.model, Eigen::VectorXd(2));
            }).find("x has 2 values"),
            std::string::npos);
}

TEST(CalibrationExport, ExportWritesEveryFileWithHashDateDataAndSigma) {
  testing::ScratchDir dir;
  const Arm a = LoadArm(SourceDir() / "config/robots/ur10.urdf", true);
  ExportInput in;
  in.spec = a.robot.spec;
  in.model = a.robot.model;
  in.parameters = RandomParameters(a.robot.model, 11);
  in.source_urdf_xml = a.urdf_xml;
  in.robot_file = "config/robots/ur10.urdf";
  in.data = "poses.csv";
  in.from = "results.json";
  in.date = "2026-12-02T14:00:00Z";
  const ExportResult r = ExportCalibration(in, dir.path());
  EXPECT_TRUE(r.parity.passed);
  const std::string hash = CalibrationHash(in.model, in.parameters.x);
  EXPECT_EQ(r.hash, hash);
  for (const char* f : {"robot_calibrated.urdf", "calibration.yaml", "calibration.json",
                        "parity.json", "parity.md"}) {
    SCOPED_TRACE(f);
    const std::string text = ReadFile(dir / f);
    EXPECT_NE(text.find(hash), std::string::npos);
    EXPECT_NE(text.find("2026-12-02T14:00:00Z"), std::string::npos);
    EXPECT_NE(text.find("poses.csv"), std::string::npos);
  }
  // The URDF keeps its meshes-and-all source and names σ; the parity report reloads it.
  const std::string urdf = ReadFile(dir / "robot_calibrated.urdf");
  EXPECT_NE(urdf.find("sigma [m | rad]: base_x=1e-05"), std::string::npos);
  EXPECT_NE(urdf.find("rcal_world_joint"), std::string::npos);
  EXPECT_TRUE(CheckUrdfParity(urdf, in.spec, in.model, in.parameters.x).passed);
  // The YAML: every parameter, its σ (null: not identified), in SI with its frame.
  const YAML::Node y = YAML::LoadFile((dir / "calibration.yaml").string());
  EXPECT_EQ(y["calibration_hash"].as<std::string>(), hash);
  ASSERT_EQ(static_cast<int>(y["parameters"].size()), in.model.num_params());
  for (int i = 0; i < in.model.num_params(); ++i) {
    const YAML::Node n = y["parameters"][i];
    EXPECT_EQ(n["name"].as<std::string>(), in.model.parameters()[i].name);
    EXPECT_EQ(n["error"].as<double>(), in.parameters.x(i));
    if (std::isnan(in.parameters.sigma(i))) {
      EXPECT_TRUE(n["sigma"].IsNull());
      EXPECT_FALSE(n["identified"].as<bool>());
    } else {
      EXPECT_EQ(n["sigma"].as<double>(), in.parameters.sigma(i));
    }
    EXPECT_FALSE(n["frame"].as<std::string>().empty());
  }
  EXPECT_EQ(y["setup_frames"]["world_from_base"]["parent"].as<std::string>(), "rcal_world");
  EXPECT_EQ(y["setup_frames"]["tip_to_markers"].size(), 2u);
  // The record reads back into the same calibration.
  const CalibrationRecord rec =
      ParseCalibrationRecord(ReadFile(dir / "calibration.json"), "calibration.json");
  EXPECT_EQ(rec.calibration_hash, hash);
  const nlohmann::json pj = nlohmann::json::parse(ReadFile(dir / "parity.json"));
  EXPECT_TRUE(pj["passed"].get<bool>());
  EXPECT_EQ(pj["samples"].get<int>(), 1000);
  EXPECT_LT(pj["max_position_error_m"].get<double>(), 1e-9);
}

}  // namespace
}  // namespace rcal::io
