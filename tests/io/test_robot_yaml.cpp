#include "rcal/io/robot_yaml.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "../kinematics/test_robots.hpp"
#include "io_test_util.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/io/atomic_file.hpp"

namespace rcal::io {
namespace {

using kinematics::JointType;
using kinematics::KinematicModel;
using kinematics::ModelBuilder;
using testing::ErrorOf;
using testing::ScratchDir;
constexpr double kPi = std::numbers::pi;

std::filesystem::path Grb3016Path() {
  return testing::SourceDir() / "config/robots/grb3016.yaml";
}

/// Table 1 of the paper as read in NOTES.md, typed in here from that table (mm → m), standard
/// D–H, plus the 4-parameter D–H tool with the generic values.
KinematicModel Table1() {
  const double a[6] = {150, 570, 150, 0, 0, 0};
  const double alpha[6] = {-kPi / 2, -kPi, kPi / 2, -kPi / 2, kPi / 2, 0};
  const double d[6] = {250, 0, 0, 645, 0, -200};
  const double theta[6] = {0, -kPi / 2, 0, 0, -kPi / 2, 0};
  ModelBuilder b("table1");
  for (int i = 0; i < 6; ++i)
    b.DhLink(a[i] / 1000, alpha[i], d[i] / 1000, theta[i],
             {"j" + std::to_string(i + 1), JointType::kRevolute, -kPi, kPi});
  b.ToolDh(0.010, 0.1, 0.050, 0.2);
  return b.Build();
}

Eigen::VectorXd RandomQ(const KinematicModel& m, std::mt19937& rng) {
  return kinematics::testing::RandomJoints(m, rng);
}

/// Largest difference of marker position [m] and IMU orientation [rad], and of the tool frame.
double PoseDifference(const KinematicModel& a, const Eigen::VectorXd& xa, const KinematicModel& b,
                      const Eigen::VectorXd& xb, const Eigen::VectorXd& q) {
  const auto pa = a.Forward(q, xa), pb = b.Forward(q, xb);
  const Eigen::Isometry3d Ta = a.ToolFrame(q, xa), Tb = b.ToolFrame(q, xb);
  return std::max({(pa.p_WM_W - pb.p_WM_W).norm(), (pa.R_EI - pb.R_EI).norm(),
                   (Ta.matrix() - Tb.matrix()).norm()});
}

TEST(RobotYaml, Grb3016MatchesTable1) {
  const KinematicModel file = LoadRobotYaml(Grb3016Path());
  const KinematicModel table = Table1();
  ASSERT_EQ(file.num_joints(), 6);
  ASSERT_EQ(file.num_params(), table.num_params());
  EXPECT_EQ(file.num_params(), 28);  // 4 per link and 4 for the tool, as the paper
  for (int i = 0; i < file.num_params(); ++i)
    EXPECT_EQ(file.parameters()[i].name, table.parameters()[i].name);
  std::mt19937 rng(3);
  for (int k = 0; k < 50; ++k) {
    const Eigen::VectorXd q = RandomQ(file, rng);
    EXPECT_LT(PoseDifference(file, file.Nominal(), table, table.Nominal(), q), 1e-12);
  }
  // The zero pose, by hand: with q = 0 the arm of Table 1 puts the flange where the products of
  // the D–H matrices put it; this checks the loader against the table, not against the builder.
  const Eigen::Isometry3d T0 = file.ToolFrame(Eigen::VectorXd::Zero(6), file.Nominal());
  EXPECT_LT(
      (T0.matrix() - table.ToolFrame(Eigen::VectorXd::Zero(6), table.Nominal()).matrix()).norm(),
      1e-12);
  // Joint limits (assumed in the file): j1 ±170°, j2 −90°…+150°.
  EXPECT_DOUBLE_EQ(file.joints()[0].lower, -170.0 / 180.0 * kPi);
  EXPECT_DOUBLE_EQ(file.joints()[0].upper, 170.0 / 180.0 * kPi);
  EXPECT_DOUBLE_EQ(file.joints()[1].lower, -kPi / 2);
  EXPECT_DOUBLE_EQ(file.joints()[1].upper, 150.0 / 180.0 * kPi);
  EXPECT_EQ(file.joints()[5].name, "j6");
}

TEST(RobotYaml, SevenDofMatchesTestRobot) {
  const KinematicModel file = LoadRobotYaml(testing::SourceDir() / "config/robots/seven_dof.yaml");
  const KinematicModel ref = kinematics::testing::SevenJointSetup();
  ASSERT_EQ(file.num_joints(), 7);
  ASSERT_EQ(file.num_params(), ref.num_params());
  for (int i = 0; i < file.num_params(); ++i)
    EXPECT_EQ(file.parameters()[i].name, ref.parameters()[i].name);
  for (int j = 0; j < 7; ++j) {
    EXPECT_DOUBLE_EQ(file.joints()[j].lower, ref.joints()[j].lower);
    EXPECT_DOUBLE_EQ(file.joints()[j].upper, ref.joints()[j].upper);
  }
  std::mt19937 rng(4);
  for (int k = 0; k < 50; ++k) {
    const Eigen::VectorXd q = RandomQ(file, rng);
    const Eigen::VectorXd x = kinematics::testing::RandomErrors(file, rng);
    EXPECT_LT(PoseDifference(file, x, ref, x, q), 1e-12);
  }
}

TEST(RobotYaml, ParseAngleReadsMultiplesOfPi) {
  EXPECT_EQ(ParseAngle("pi"), kPi);
  EXPECT_EQ(ParseAngle("-pi/2"), -kPi / 2);
  EXPECT_EQ(ParseAngle("2*pi/3"), 2 * kPi / 3);
  EXPECT_EQ(ParseAngle(" 0.5 * pi "), 0.5 * kPi);
  EXPECT_EQ(ParseAngle("-17*pi/18"), -(17 * kPi / 18));
  EXPECT_EQ(ParseAngle("1e-3"), 1e-3);
  EXPECT_EQ(ParseAngle("+0.25"), 0.25);
  for (const char* bad : {"", "abc", "pi/", "2pi", "pi**2", "--pi", "pi 2", "deg"})
    EXPECT_FALSE(ParseAngle(bad).has_value()) << bad;
}

/// A calibrated spec, saved and loaded, is at x = 0 the original model at x.
void ExpectCalibratedRoundTrip(const RobotSpec& spec, unsigned seed, double sigma_length = 0.003,
                               double sigma_angle = 0.01) {
  ScratchDir dir;
  const KinematicModel model = BuildModel(spec);
  std::mt19937 rng(seed);
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::VectorXd x =
        kinematics::testing::RandomErrors(model, rng, sigma_length, sigma_angle);
    const auto path = dir / "calibrated.yaml";
    SaveCalibratedRobotYaml(path, spec, model, x, {"calibrated in a test"});
    const KinematicModel loaded = LoadRobotYaml(path);
    ASSERT_EQ(loaded.num_params(), model.num_params());
    for (int k = 0; k < 20; ++k) {
      const Eigen::VectorXd q = RandomQ(model, rng);
      EXPECT_LT(PoseDifference(loaded, loaded.Nominal(), model, x, q), 1e-12)
          << spec.name << " trial " << trial;
    }
  }
}

// Several markers (a list, one per id): each calibrated offset comes back on its own id, and the
// text names them under markers:.
TEST(RobotYaml, CalibratedMarkersRoundTripPerId) {
  RobotSpec spec = LoadRobotSpec(Grb3016Path());
  spec.tool.reset();
  spec.base = FrameSpec{};
  spec.markers = {
      {0, {0.0, 0.0, 0.1}, true}, {4, {0.05, 0.0, 0.1}, true}, {7, {0, 0.05, 0.1}, false}};
  ExpectCalibratedRoundTrip(spec, 17);
  const KinematicModel model = BuildModel(spec);
  ASSERT_EQ(model.markers().size(), 3u);
  EXPECT_EQ(model.markers()[2].param[0], -1);  // identify: false
  Eigen::VectorXd x = model.Nominal();
  x(model.FindParameter("marker4_y")) = 0.02;
  const RobotSpec cal = CalibratedSpec(spec, model, x);
  EXPECT_EQ(cal.markers[1].id, 4);
  EXPECT_DOUBLE_EQ(cal.markers[1].xyz.y(), 0.02);
  const std::string text = RobotYamlText(cal);
  EXPECT_NE(
      text.find("markers:\n  - {id: 0, xyz: [0, 0, 0.1]}\n  - {id: 4, xyz: [0.05, 0.02, 0.1]}\n"
                "  - {id: 7, xyz: [0, 0.05, 0.1], identify: false}\n"),
      std::string::npos)
      << text;
  EXPECT_EQ(ParseRobotYaml(text).markers.size(), 3u);
}

TEST(RobotYaml, CalibratedGrb3016RoundTrips) {
  ExpectCalibratedRoundTrip(LoadRobotSpec(Grb3016Path()), 5);
}

TEST(RobotYaml, CalibratedHayatiRoundTripsWithNominalBeta) {
  RobotSpec spec = LoadRobotSpec(Grb3016Path());
  spec.links[1].hayati = true;
  const KinematicModel model = BuildModel(spec);
  EXPECT_GE(model.FindParameter("beta2"), 0);
  EXPECT_LT(model.FindParameter("d2"), 0);
  ExpectCalibratedRoundTrip(spec, 6);
  // The calibrated file carries the identified β as a nominal value.
  Eigen::VectorXd x = model.Nominal();
  x(model.FindParameter("beta2")) = 0.003;
  const RobotSpec cal = CalibratedSpec(spec, model, x);
  EXPECT_DOUBLE_EQ(cal.links[1].beta, 0.003);
  EXPECT_NE(RobotYamlText(cal).find("beta: 0.003"), std::string::npos);
}

TEST(RobotYaml, CalibratedModifiedDhBetaRoundTrips) {
  // An identified modified D–H β becomes the nominal β of the calibrated file, and that file
  // reproduces the calibrated kinematics.
  RobotSpec spec = LoadRobotSpec(testing::SourceDir() / "config/robots/seven_dof.yaml");
  spec.links[2].hayati = true;
  const KinematicModel model = BuildModel(spec);
  Eigen::VectorXd x = model.Nominal();
  x(model.FindParameter("beta3")) = 0.001;
  const RobotSpec cal = CalibratedSpec(spec, model, x);
  EXPECT_DOUBLE_EQ(cal.links[2].beta, 0.001);
  const KinematicModel reloaded = BuildModel(ParseRobotYaml(RobotYamlText(cal)));
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(7, 0.4);
  EXPECT_LT(
      (reloaded.ToolFrame(q, reloaded.Nominal()).matrix() - model.ToolFrame(q, x).matrix()).norm(),
      1e-12);
  ExpectCalibratedRoundTrip(spec, 8);
}

TEST(RobotYaml, CalibratedSevenDofWithAllFramesRoundTrips) {
  ExpectCalibratedRoundTrip(LoadRobotSpec(testing::SourceDir() / "config/robots/seven_dof.yaml"),
                            7);
}

TEST(RobotYaml, CalibratedUrdfConventionRoundTrips) {
  RobotSpec spec;
  spec.name = "ur_like";
  spec.convention = Convention::kUrdf;
  spec.base = FrameSpec{{0.1, 0.2, 0.0}, {0.0, 0.0, 0.5}, true};
  const double lim = kPi;
  auto joint = [&](const std::string& name, Eigen::Vector3d xyz, Eigen::Vector3d rpy,
                   Eigen::Vector3d axis) {
    LinkSpec l;
    l.xyz = xyz;
    l.rpy = rpy;
    l.axis = axis;
    l.joint = kinematics::Joint{name, JointType::kRevolute, -lim, lim};
    spec.links.push_back(l);
  };
  joint("shoulder_pan", {0, 0, 0.1273}, {0, 0, 0}, {0, 0, 1});
  joint("shoulder_lift", {0, 0.220941, 0}, {0, kPi / 2, 0}, {0, 1, 0});
  joint("elbow", {0, -0.1719, 0.612}, {0, 0, 0}, {0, 1, 0});
  LinkSpec fixed;
  fixed.name = "a_fixed_joint";
  fixed.xyz = {0.01, 0.0, 0.0};
  fixed.rpy = {0.3, kPi / 2, -0.2};  // at gimbal lock on purpose
  fixed.identify = false;
  spec.links.push_back(fixed);
  joint("wrist_1", {0, 0, 0.5723}, {0, kPi / 2 - 1e-9, 0}, {0, 1, 0});  // near gimbal lock
  joint("wrist_2", {0, 0.1149, 0}, {0, 0, 0}, {0, 0, 1});
  joint("wrist_3", {0, 0, 0.1157}, {0, 0, 0}, {0, 1, 0});
  spec.links.back().identify = false;
  spec.markers = {MarkerSpec{0, {0.0, 0.15, 0.05}, true}};
  ExpectCalibratedRoundTrip(spec, 8);
  ExpectCalibratedRoundTrip(spec, 9, 0.05, 0.5);  // large errors too
}

TEST(RobotYaml, TextRoundTripIsExact) {
  const RobotSpec spec = LoadRobotSpec(testing::SourceDir() / "config/robots/seven_dof.yaml");
  const std::string text = RobotYamlText(spec, {"a header line"});
  EXPECT_EQ(text.rfind("# a header line\n", 0), 0u);
  EXPECT_NE(text.find("alpha: -pi/2"), std::string::npos) << text;
  const RobotSpec again = ParseRobotYaml(text, "again.yaml");
  EXPECT_EQ(RobotYamlText(again), RobotYamlText(spec));
  ASSERT_EQ(again.links.size(), spec.links.size());
  for (size_t i = 0; i < spec.links.size(); ++i) {
    EXPECT_EQ(again.links[i].a, spec.links[i].a);
    EXPECT_EQ(again.links[i].alpha, spec.links[i].alpha);
    EXPECT_EQ(again.links[i].joint->name, spec.links[i].joint->name);
    EXPECT_EQ(again.links[i].joint->upper, spec.links[i].joint->upper);
  }
  EXPECT_EQ(again.base->rpy, spec.base->rpy);
  EXPECT_EQ(again.earth->rpy, spec.earth->rpy);
}

TEST(RobotYaml, NamesNeedingQuotesSurvive) {
  RobotSpec spec = LoadRobotSpec(Grb3016Path());
  spec.name = "robot: \"one\"";
  spec.links[0].joint->name = "yes";
  const RobotSpec again = ParseRobotYaml(RobotYamlText(spec));
  EXPECT_EQ(again.name, spec.name);
  EXPECT_EQ(again.links[0].joint->name, "yes");
}

TEST(RobotYaml, CalibratedSpecRejectsAForeignModel) {
  const RobotSpec spec = LoadRobotSpec(Grb3016Path());
  const KinematicModel other = kinematics::testing::SevenJointSetup();
  EXPECT_NE(ErrorOf([&] {
              CalibratedSpec(spec, other, other.Nominal());
            }).find("not built from this robot description"),
            std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Bad input: every error names the file and the key path.

struct BadCase {
  std::string replace;  ///< text in grb3016.yaml to replace (must occur)
  std::string with;
  std::string expected;  ///< substring of the error message
};

void PrintTo(const BadCase& c, std::ostream* os) {
  *os << "'" << c.with << "'";
}

class RobotYamlBadInput : public ::testing::TestWithParam<BadCase> {};

TEST_P(RobotYamlBadInput, ErrorNamesFileAndKey) {
  const BadCase& c = GetParam();
  std::string text = ReadFile(Grb3016Path());
  const auto at = text.find(c.replace);
  ASSERT_NE(at, std::string::npos) << "test case text not found: " << c.replace;
  text.replace(at, c.replace.size(), c.with);
  ScratchDir dir;
  const auto path = dir / "grb3016.yaml";
  AtomicWriteFile(path, text);
  const std::string msg = ErrorOf([&] { LoadRobotYaml(path); });
  EXPECT_NE(msg.find("grb3016.yaml: "), std::string::npos) << msg;
  EXPECT_NE(msg.find(c.expected), std::string::npos) << msg;
}

INSTANTIATE_TEST_SUITE_P(
    Cases, RobotYamlBadInput,
    ::testing::Values(
        // unknown keys
        BadCase{"{a: 0.150, alpha: pi/2,", "{a: 0.150, alpah: pi/2,",
                "grb3016.yaml: links[2].alpah: unknown key"},
        BadCase{"tool: {a: 0.010, alpha", "tool: {a: 0.010, alfa", "tool.alfa: unknown key"},
        BadCase{"name: j4, type", "name: j4, kind: revolute, type", "links[3].joint.kind: unknown"},
        BadCase{"schema: rcal.robot/1", "schema: rcal.robot/1\nunits: mm", "units: unknown key"},
        BadCase{"name: grb3016", "name: grb3016\nnmae: x", "nmae: unknown key"},
        // missing keys
        BadCase{"{a: 0.570, alpha: -pi, d: 0,", "{a: 0.570, alpha: -pi,",
                "links[1].d: missing key"},
        BadCase{"name: j1, type: revolute, lower: -17*pi/18, ", "name: j1, type: revolute, ",
                "links[0].joint.lower: missing key"},
        BadCase{"schema: rcal.robot/1\n", "", "schema: missing key"},
        BadCase{"convention: dh\n", "", "convention: missing key"},
        BadCase{"tool: {a: 0.010, ", "tool: {", "tool.a: missing key"},
        BadCase{"tool: {a",
                "markers: [{id: 1, xyz: [0, 0, 0.1]}, {id: 1, xyz: [0, 0, 0]}]\ntool: {a",
                "markers[1].id: marker id 1 twice"},
        BadCase{"tool: {a", "markers: [{id: -1, xyz: [0, 0, 0.1]}]\ntool: {a",
                "markers[0].id: expected an integer id from 0 to 1000000, got '-1'"},
        BadCase{"tool: {a", "markers: [{id: 2, xyz: [0, 0, 0.1], size: 3}]\ntool: {a",
                "markers[0].size: unknown key"},
        BadCase{"tool: {a",
                "marker: {xyz: [0, 0, 0]}\nmarkers: [{id: 2, xyz: [0, 0, 0.1]}]\ntool: {a",
                "markers: give marker (one, id 0) or markers (a list), not both"},
        // wrong types and values
        BadCase{"{a: 0.150, alpha: -pi/2, d: 0.250", "{a: [0.150, 1], alpha: -pi/2, d: 0.250",
                "links[0].a: expected a number"},
        BadCase{"{a: 0.150, alpha: -pi/2, d: 0.250", "{a: pi, alpha: -pi/2, d: 0.250",
                "links[0].a: expected a number [m]"},
        BadCase{"alpha: -pi, d: 0,", "alpha: half, d: 0,", "links[1].alpha: expected an angle"},
        BadCase{"name: j5, type: revolute", "name: j5, type: rotary", "links[4].joint.type"},
        BadCase{"convention: dh", "convention: denavit", "convention: expected dh, mdh or urdf"},
        BadCase{"schema: rcal.robot/1", "schema: rcal.robot/2", "schema: expected rcal.robot/1"},
        BadCase{"tool: {a: 0.010,", "tool: {a: 0.010, identify: maybe,",
                "tool.identify: expected true or false"},
        BadCase{"upper: 5*pi/6", "upper: -5*pi/6", "links[1].joint: lower limit"},
        BadCase{"name: j6,", "name: j5,", "links[5].joint.name: joint name 'j5' used twice"},
        BadCase{"{a: 0.150, alpha: pi/2,", "{a: 0.150, beta: 0.1, alpha: pi/2,",
                "links[2].beta: only with hayati"},
        // non-finite
        BadCase{"{a: 0, alpha: -pi/2, d: 0.645", "{a: 0, alpha: -pi/2, d: .nan",
                "links[3].d: value is not finite"},
        BadCase{"{a: 0, alpha: -pi/2, d: 0.645", "{a: 0, alpha: -pi/2, d: nan",
                "links[3].d: value is not finite"},
        BadCase{"tool: {a: 0.010, alpha: 0.1", "tool: {a: 0.010, alpha: inf",
                "tool.alpha: value is not finite"},
        // absurd values (were accepted: a 1e6 m link, a 1e9 rad limit, a 1 km tool)
        BadCase{"{a: 0, alpha: -pi/2, d: 0.645", "{a: 0, alpha: -pi/2, d: 1e6",
                "links[3].d: '1e6' is beyond 100 m: not an arm's dimension"},
        BadCase{"tool: {a: 0.010,", "tool: {a: -1000,",
                "tool.a: '-1000' is beyond 100 m: not an arm's dimension"},
        BadCase{"upper: 5*pi/6", "upper: 1e9",
                "links[1].joint.upper: '1e9' rad is beyond two turns (4π) (line"},
        BadCase{"{a: 0.150, alpha: -pi/2,", "{a: 0.150, alpha: 1e300,",
                "links[0].alpha: '1e300' rad is beyond a turn (2π) (line"},
        BadCase{"lower: -17*pi/18, upper: 17*pi/18", "lower: 1, upper: 1",
                "links[0].joint: lower limit must be below upper limit"},
        // duplicate key, malformed YAML
        BadCase{"tool: {a: 0.010,", "tool: {a: 0.010, a: 0.02,", "tool.a: duplicate key"},
        BadCase{"links:\n", "links: [\n", "malformed YAML"},
        BadCase{"tool: {a: 0.010,", "tool: {a: 0.010,,]", "malformed YAML"}));

// `text` with every value of the keys `keys` (a: 0.150, d: 0.645, ...) multiplied by `factor`.
std::string ScaleKeys(std::string text, const std::vector<std::string>& keys, double factor) {
  for (const std::string& k : keys) {
    const std::string tag = "{" + k + ": ", tag2 = " " + k + ": ";
    for (size_t at = 0; (at = text.find(k + ": ", at)) != std::string::npos; at += k.size()) {
      if (at == 0 || (text.compare(at - 1, tag.size(), tag) != 0 &&
                      text.compare(at - 1, tag2.size(), tag2) != 0))
        continue;
      const size_t start = at + k.size() + 2, end = text.find_first_of(",}", start);
      std::ostringstream v;
      v << std::stod(text.substr(start, end - start)) * factor;
      text.replace(start, end - start, v.str());
    }
  }
  return text;
}

// `text` with every occurrence of `from` replaced by `to`.
std::string ReplaceAll(std::string text, const std::string& from, const std::string& to) {
  for (size_t at = 0; (at = text.find(from, at)) != std::string::npos; at += to.size())
    text.replace(at, from.size(), to);
  return text;
}

// Issue 13, item 4: a robot file in millimetres, refused naming the unit. The GRB3016's lengths
// in mm: its first length beyond 100 m names millimetres. A small arm in mm with every length
// below 100 (each one alone passes the bound of one length) is refused by the sum. Was: the same
// refusal without the unit, and the small arm accepted as a 169 m arm.
TEST(RobotYaml, LengthsInMillimetresAreRefusedNamingTheUnit) {
  const std::string text = ReadFile(Grb3016Path());
  std::string msg = ErrorOf([&] { ParseRobotYaml(ScaleKeys(text, {"a", "d"}, 1000), "mm.yaml"); });
  EXPECT_EQ(msg,
            "mm.yaml: links[0].a: '150' is beyond 100 m: not an arm's dimension: millimetres? "
            "rcal files are in metres (line 15)")
      << msg;
  // Table 1: 0.150 + 0.250 + 0.570 + 0.150 + 0.645 + 0.200 = 1.965 m, tool 0.010 + 0.050: 2.025 m
  // in all, 168.75 "m" at 1000/12.
  std::string small = ScaleKeys(text, {"a", "d"}, 1000.0 / 12.0);
  msg = ErrorOf([&] { ParseRobotYaml(small, "small.yaml"); });
  EXPECT_EQ(msg,
            "small.yaml: links: the arm's lengths add up to 168.75 m, beyond 100 m: no arm is "
            "that long (the largest industrial arms reach about 4 m): millimetres? rcal files are "
            "in metres")
      << msg;
}

// Issue 13, item 4: angles in degrees, refused naming the unit and the value in radians, also
// where the old bound (100 rad) let them through: a D–H alpha of -90, limits of ±90, a base yaw
// of 180. A constant angle lies within a turn, a limit within two (UR ±2π, a wrist's ±450°).
// Was: alpha -90 rad and limits ±90 rad accepted, the arm calibrated, exit 0.
TEST(RobotYaml, AnglesInDegreesAreRefusedNamingTheUnit) {
  const std::string text = ReadFile(Grb3016Path());
  // Every alpha in degrees: the first one named.
  std::string deg = ReplaceAll(text, "alpha: -pi/2", "alpha: -90");
  deg = ReplaceAll(deg, "alpha: pi/2", "alpha: 90");
  deg = ReplaceAll(deg, "alpha: -pi,", "alpha: -180,");
  EXPECT_EQ(ErrorOf([&] { ParseRobotYaml(deg, "deg.yaml"); }),
            "deg.yaml: links[0].alpha: '-90' rad is beyond a turn (2π): degrees? rcal files are "
            "in radians: -90° is -pi/2 (line 15)");
  // A theta offset.
  deg = ReplaceAll(text, "theta: -pi/2,\n     joint: {name: j2",
                   "theta: -90,\n     joint: {name: j2");
  EXPECT_EQ(ErrorOf([&] { ParseRobotYaml(deg, "deg.yaml"); }),
            "deg.yaml: links[1].theta: '-90' rad is beyond a turn (2π): degrees? rcal files are "
            "in radians: -90° is -pi/2 (line 17)");
  // Limits of 170° and of ±90° (below the 100 rad bound of any angle).
  deg = ReplaceAll(text, "upper: 17*pi/18}", "upper: 170}");
  EXPECT_EQ(ErrorOf([&] { ParseRobotYaml(deg, "deg.yaml"); }),
            "deg.yaml: links[0].joint.upper: '170' rad is beyond two turns (4π): degrees? rcal "
            "files are in radians: 170° is 17*pi/18 (line 16)");
  deg = ReplaceAll(text, "lower: -2*pi/3, upper: 2*pi/3", "lower: -90, upper: 90");
  EXPECT_EQ(ErrorOf([&] { ParseRobotYaml(deg, "deg.yaml"); }),
            "deg.yaml: links[4].joint.lower: '-90' rad is beyond two turns (4π): degrees? rcal "
            "files are in radians: -90° is -pi/2 (line 24)");
  // A frame's roll-pitch-yaw; a limit of 137.5° has no multiple of pi to name.
  deg = text + "base: {xyz: [1, 0, 0], rpy: [0, 0, 180]}\n";
  EXPECT_EQ(ErrorOf([&] { ParseRobotYaml(deg, "deg.yaml"); }),
            "deg.yaml: base.rpy[2]: '180' rad is beyond a turn (2π): degrees? rcal files are in "
            "radians: 180° is pi (line 32)");
  deg = ReplaceAll(text, "upper: 17*pi/18}", "upper: 137.5}");
  EXPECT_NE(ErrorOf([&] { ParseRobotYaml(deg, "deg.yaml"); })
                .find("'137.5' rad is beyond two turns (4π): degrees? rcal files are in radians: "
                      "137.5° is 2.39983"),
            std::string::npos);
  // Within the bounds, rounding included: a 2π written 6.2832, limits of two turns (UR's ±2π
  // from a URDF, ±720°) and ±450°.
  std::string fine = ReplaceAll(text, "alpha: 0, d: -0.200", "alpha: 6.2832, d: -0.200");
  fine = ReplaceAll(fine, "lower: -2*pi, upper: 2*pi", "lower: -4*pi, upper: 7.8539816");
  const RobotSpec spec = ParseRobotYaml(fine, "fine.yaml");
  EXPECT_DOUBLE_EQ(spec.links[5].alpha, 6.2832);
  EXPECT_DOUBLE_EQ(spec.links[5].joint->lower, -4 * kPi);
}

TEST(RobotYaml, EmptyAndMissingFilesAreErrors) {
  ScratchDir dir;
  AtomicWriteFile(dir / "empty.yaml", "# nothing\n");
  EXPECT_NE(ErrorOf([&] { LoadRobotYaml(dir / "empty.yaml"); }).find("empty.yaml: empty file"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { LoadRobotYaml(dir / "absent.yaml"); }).find("absent.yaml"),
            std::string::npos);
}

}  // namespace
}  // namespace rcal::io
