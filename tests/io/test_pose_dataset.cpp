#include "rcal/io/pose_dataset.hpp"

#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <numbers>
#include <random>
#include <sstream>

#include "io_test_util.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::io {
namespace {

using testing::ErrorOf;
using testing::ScratchDir;

std::filesystem::path FigarohCsv() {
  return testing::SourceDir() / "data/figaroh_ur10/calibration.csv";
}

/// Captures what spdlog logs while it lives.
class LogCapture {
 public:
  LogCapture() : previous_(spdlog::default_logger()) {
    auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out_);
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("capture", sink));
  }
  ~LogCapture() { spdlog::set_default_logger(previous_); }
  std::string text() const { return out_.str(); }

 private:
  std::shared_ptr<spdlog::logger> previous_;
  std::ostringstream out_;
};

PoseDataset RichDataset() {
  std::mt19937 rng(21);
  std::normal_distribution<double> n(0.0, 1.0);
  PoseDataset d;
  d.num_joints = 3;
  d.comments = {" made by a test", " second line"};
  for (int i = 0; i < 7; ++i) {
    PoseSample p;
    p.q = sim::Draw3(n, rng);
    p.p_WM_W = sim::Draw3(n, rng) * 0.5;
    p.has_orientation = i != 3;  // one pose without orientation
    if (p.has_orientation) {
      p.q_EI_wxyz = sim::Draw4(n, rng).normalized();
    }
    p.marker = i % 2;
    p.temperature = i == 2 ? PoseSample::kAbsent : 20.0 + i * 0.1;
    p.payload = 1.5;
    p.time = 0.1 * i;
    if (i != 4) p.dq_sign = Eigen::Vector3i(1, -1, i % 2);
    p.set = i < 3 ? PoseSample::kCal : i < 6 ? PoseSample::kTest : PoseSample::kUnspecified;
    d.samples.push_back(p);
  }
  return d;
}

bool SameNumber(double a, double b) {
  return (std::isnan(a) && std::isnan(b)) || a == b;
}

TEST(PoseDataset, RoundTripIsExact) {
  ScratchDir dir;
  const PoseDataset d = RichDataset();
  SavePoseDataset(dir / "poses.csv", d);
  const PoseDataset e = LoadPoseDataset(dir / "poses.csv", 3);
  EXPECT_EQ(e.num_joints, 3);
  EXPECT_FALSE(e.has_orientation);  // one sample has none
  EXPECT_TRUE(e.ignored_columns.empty());
  EXPECT_EQ(e.comments, d.comments);
  ASSERT_EQ(e.samples.size(), d.samples.size());
  for (size_t i = 0; i < d.samples.size(); ++i) {
    const PoseSample &a = d.samples[i], &b = e.samples[i];
    EXPECT_EQ(a.q, b.q) << i;
    EXPECT_EQ(a.p_WM_W, b.p_WM_W) << i;
    EXPECT_EQ(a.has_orientation, b.has_orientation) << i;
    if (a.has_orientation) {
      EXPECT_EQ(a.q_EI_wxyz, b.q_EI_wxyz) << i;
    }
    EXPECT_EQ(a.marker, b.marker) << i;
    EXPECT_TRUE(SameNumber(a.temperature, b.temperature)) << i;
    EXPECT_TRUE(SameNumber(a.payload, b.payload)) << i;
    EXPECT_TRUE(SameNumber(a.time, b.time)) << i;
    EXPECT_EQ(a.dq_sign, b.dq_sign) << i;
    EXPECT_EQ(a.set, b.set) << i;
  }
  // Minimal data writes only the required columns.
  PoseDataset m;
  m.num_joints = 2;
  PoseSample p;
  p.q = Eigen::Vector2d(0.1, 0.2);
  p.p_WM_W = {1, 2, 3};
  m.samples = {p};
  EXPECT_EQ(PoseDatasetText(m), "q1,q2,x,y,z\n0.1,0.2,1,2,3\n");
}

TEST(PoseDataset, CommentsAndColumnsInAnyOrder) {
  const std::string text =
      "# measured on a Tuesday\n"
      "#   laser tracker, SI units\n"
      "set,z,q2,qz,x,qy,q1,qw,y,qx,time,marker\n"
      "cal,0.3,0.2,0,0.1,0,0.5,1,0.2,0,1.5,2\n"
      "# a comment between rows is skipped\n"
      "test,0.6,-0.2,0.7071067811865476,0.4,0,-0.5,0.7071067811865476,0.5,0,2.5,0\n";
  const PoseDataset d = ParsePoseDataset(text, "mem.csv", 2);
  ASSERT_EQ(d.samples.size(), 2u);
  EXPECT_EQ(d.comments,
            (std::vector<std::string>{" measured on a Tuesday", "   laser tracker, SI units"}));
  EXPECT_TRUE(d.has_orientation);
  EXPECT_EQ(d.samples[0].q, Eigen::Vector2d(0.5, 0.2));
  EXPECT_EQ(d.samples[0].p_WM_W, Eigen::Vector3d(0.1, 0.2, 0.3));
  EXPECT_EQ(d.samples[0].marker, 2);
  EXPECT_EQ(d.samples[0].set, PoseSample::kCal);
  EXPECT_EQ(d.samples[1].set, PoseSample::kTest);
  EXPECT_DOUBLE_EQ(d.samples[1].time, 2.5);
  EXPECT_TRUE(std::isnan(d.samples[1].temperature));
  EXPECT_LT((d.samples[1].q_EI_wxyz - Eigen::Vector4d(std::sqrt(0.5), 0, 0, std::sqrt(0.5))).norm(),
            1e-15);
  // The joint count comes from the columns when not given.
  EXPECT_EQ(ParsePoseDataset(text, "mem.csv").num_joints, 2);
}

TEST(PoseDataset, UnknownColumnsAreIgnoredWithAWarning) {
  LogCapture log;
  const PoseDataset d =
      ParsePoseDataset("q1,operator,x,y,z,q3_extra\n0.1,anna,1,2,3,7\n", "mem.csv", 1);
  EXPECT_EQ(d.ignored_columns, (std::vector<std::string>{"operator", "q3_extra"}));
  EXPECT_NE(log.text().find("mem.csv: ignoring unknown column(s) 'operator', 'q3_extra'"),
            std::string::npos)
      << log.text();
  EXPECT_EQ(d.samples.size(), 1u);
}

struct BadCsv {
  std::string text;
  std::string expected;
};

void PrintTo(const BadCsv& c, std::ostream* os) {
  *os << c.expected;
}

class PoseDatasetBadInput : public ::testing::TestWithParam<BadCsv> {};

TEST_P(PoseDatasetBadInput, ErrorNamesColumnAndRow) {
  ScratchDir dir;
  AtomicWriteFile(dir / "poses.csv", GetParam().text);
  const std::string msg = ErrorOf([&] { LoadPoseDataset(dir / "poses.csv", 2); });
  EXPECT_NE(msg.find("poses.csv"), std::string::npos) << msg;
  EXPECT_NE(msg.find(GetParam().expected), std::string::npos) << msg;
}

INSTANTIATE_TEST_SUITE_P(
    Cases, PoseDatasetBadInput,
    ::testing::Values(
        BadCsv{"q1,x,y,z\n0,1,2,3\n", "missing column 'q2'"},
        BadCsv{"q1,q2,q3,x,y,z\n0,0,0,1,2,3\n", "has joint columns q1..q3, expected q1..q2"},
        BadCsv{"q1,q2,x,z\n0,0,1,3\n", "missing column 'y'"},
        BadCsv{"q1,q2,x,y,z\n0,0,1,2,3\n0,nan,1,2,3\n", "row 2 column 'q2' is 'nan'"},
        BadCsv{"q1,q2,x,y,z\n0,0,1,2,3\n0,0,,2,3\n", "row 2 column 'x' is empty"},
        BadCsv{"q1,q2,x,y,z\n0,0,1,two,3\n", "row 1 column 'y' is not a number: 'two'"},
        BadCsv{"q1,q2,x,y,z,qw,qx,qy\n0,0,1,2,3,1,0,0\n",
               "columns 'qw,qx,qy,qz' come together: missing column 'qz'"},
        BadCsv{"q1,q2,x,y,z,qw,qx,qy,qz\n0,0,1,2,3,0,0,0,0\n", "row 1 columns 'qw,qx,qy,qz': zero"},
        BadCsv{"q1,q2,x,y,z,qw,qx,qy,qz\n0,0,1,2,3,1,1,0,0\n",
               "row 1 columns 'qw,qx,qy,qz': not a unit quaternion"},
        BadCsv{"q1,q2,x,y,z,qw,qx,qy,qz\n0,0,1,2,3,1,,0,0\n", "row 1 column 'qx' is empty"},
        BadCsv{"q1,q2,x,y,z,set\n0,0,1,2,3,cal\n0,0,1,2,3,train\n",
               "row 2 column 'set' must be cal or test (or empty), got 'train'"},
        BadCsv{"q1,q2,x,y,z,marker\n0,0,1,2,3,1.5\n", "row 1 column 'marker' must be an integer"},
        BadCsv{"q1,q2,x,y,z,marker\n0,0,1,2,3,-2\n",
               "row 1 column 'marker' must be an integer id from 0"},
        BadCsv{"q1,q2,x,y,z,dq1\n0,0,1,2,3,1\n", "missing column 'dq2'"},
        BadCsv{"q1,q2,x,y,z,dq1,dq2\n0,0,1,2,3,1,2\n", "row 1 column 'dq2' must be -1, 0 or 1"},
        BadCsv{"q1,q2,x,y,z\n0,0,1,2\n", "line 2 has 4 cells, the header has 5"},
        BadCsv{"# only a comment\n", "no header row"},
        BadCsv{"x1,y1,z1,phix1,phiy1,j1,j2\n1,2,3,0,0,0,0\n",
               "columns 'phix1,phiy1,phiz1' come together"},
        BadCsv{"x1,y1,phix1,phiy1,phiz1,j1,j2\n1,2,0,0,0,0,0\n", "missing column 'z1'"},
        BadCsv{"x1,y1,z1,j1,j2,j3\n1,2,3,0,0,0\n", "has 3 joint columns, expected 2"},
        BadCsv{"x1,y1,z1,j1,j2\n1,2,3,0,\n", "row 1 column 'j2' is empty"},
        // Values no measurement has (were read: q1 = 1e308 calibrated a robot, held-out 116 m).
        BadCsv{"q1,q2,x,y,z\n0,0,1,2,3\n1e308,0,1,2,3\n",
               "row 2 column 'q1' is 1e308: outside [-1000, 1000] rad or m"},
        BadCsv{"q1,q2,x,y,z\n0,0,1e12,2,3\n",
               "row 1 column 'x' is 1e12: outside [-1e+06, 1e+06] m"},
        BadCsv{"q1,q2,x,y,z\n0,0,1,2,inf\n", "row 1 column 'z' is 'inf': a number is required"},
        BadCsv{"q1,q2,x,y,z,temperature\n0,0,1,2,3,-300\n",
               "row 1 column 'temperature' is -300: outside [-273.15, 1000] °C"},
        BadCsv{"q1,q2,x,y,z,payload\n0,0,1,2,3,-1\n",
               "row 1 column 'payload' is -1: outside [0, 10000] kg"},
        BadCsv{"q1,q2,x,y,z,time\n0,0,1,2,3,1e300\n",
               "row 1 column 'time' is 1e300: outside [-1e+10, 1e+10] s"},
        BadCsv{"x1,y1,z1,phix1,phiy1,phiz1,j1,j2\n1,2,3,0,1e9,0,0,0\n",
               "row 1 column 'phiy1' is 1e9: outside [-100, 100] rad"}));

LoadedRobot Grb3016(bool unknown_base) {
  LoadedRobot r = LoadRobot(testing::SourceDir() / "config/robots/grb3016.yaml");
  if (unknown_base) {
    r.spec.base = FrameSpec{};
    r.model = BuildModel(r.spec);
  }
  return r;
}

// The GRB3016 at its zero pose with the marker 0.1 m in front of the origin, as a dataset row.
PoseSample SampleAt(const Eigen::VectorXd& q, const Eigen::Vector3d& p, int row) {
  PoseSample s;
  s.q = q;
  s.p_WM_W = p;
  s.row = row;
  return s;
}

TEST(PosePlausibility, ArmReachIsTheSumOfTheDrawingsTranslations) {
  // Independent truth: the D–H lengths of config/robots/grb3016.yaml, summed by hand (links
  // a + d, tool a + d); the unknown base adds nothing.
  const LoadedRobot r = Grb3016(true);
  double by_hand = r.spec.tool->a + r.spec.tool->d;
  for (const auto& l : r.spec.links) by_hand += std::abs(l.a) + std::abs(l.d);
  EXPECT_NEAR(ArmReach(r.model, false), by_hand, 1e-12);
  EXPECT_NEAR(ArmReach(r.model, true), by_hand, 1e-12);
  // A known base 2 m away counts with include_base.
  LoadedRobot moved = Grb3016(false);
  moved.spec.base = FrameSpec{Eigen::Vector3d(2.0, 0, 0), Eigen::Vector3d::Zero(), false};
  moved.model = BuildModel(moved.spec);
  EXPECT_NEAR(ArmReach(moved.model, true), by_hand + 2.0, 1e-12);
  // Every pose of the arm lies within it.
  std::mt19937 rng(3);
  for (int k = 0; k < 200; ++k) {
    Eigen::VectorXd q(6);
    for (int j = 0; j < 6; ++j) {
      const auto& jt = r.model.joints()[j];
      q(j) = std::uniform_real_distribution<double>(jt.lower, jt.upper)(rng);
    }
    EXPECT_LE(r.model.Forward(q, r.model.Nominal()).p_WM_W.norm(), by_hand);
  }
}

TEST(PosePlausibility, JointsBeyondTheirLimitsAreRefusedNamingRowAndColumn) {
  const LoadedRobot r = Grb3016(false);
  PoseDataset d;
  d.num_joints = 6;
  Eigen::VectorXd q = Eigen::VectorXd::Zero(6);
  d.samples = {SampleAt(q, {0.5, 0, 0.5}, 1)};
  EXPECT_EQ(ErrorOf([&] { CheckPosesPlausible(d, r.model, "p.csv"); }), "<no error>");
  // j2's limits are [-pi/2, 5pi/6]: 0.05 rad beyond passes (the margin is 0.1 rad), 0.2 does not.
  q(1) = -std::numbers::pi / 2 - 0.05;
  d.samples.push_back(SampleAt(q, {0.5, 0, 0.5}, 2));
  EXPECT_EQ(ErrorOf([&] { CheckPosesPlausible(d, r.model, "p.csv"); }), "<no error>");
  q(1) = -std::numbers::pi / 2 - 0.2;
  d.samples.push_back(SampleAt(q, {0.5, 0, 0.5}, 3));
  EXPECT_EQ(ErrorOf([&] { CheckPosesPlausible(d, r.model, "p.csv"); }),
            "p.csv: row 3 column 'q2' (joint 'j2') is -1.7708 rad: beyond its limits "
            "[-1.5708, 2.61799] by more than 0.1 rad (PosePlausibility::joint_limit_margin_rad)");
  PosePlausibility loose;
  loose.joint_limit_margin_rad = 0.3;
  EXPECT_EQ(ErrorOf([&] { CheckPosesPlausible(d, r.model, "p.csv", loose); }), "<no error>");
  // q1 = 1e6 rad on j1 (limits ±17pi/18); j6 spans ±2pi, a full turn: bounded at ±100 rad only.
  d.samples.resize(1);
  d.samples[0].q(0) = 1e6;
  EXPECT_NE(ErrorOf([&] {
              CheckPosesPlausible(d, r.model, "p.csv");
            }).find("p.csv: row 1 column 'q1' (joint 'j1') is 1e+06 rad: beyond its limits"),
            std::string::npos);
  d.samples[0].q(0) = 0.0;
  d.samples[0].q(5) = 20.0;
  EXPECT_EQ(ErrorOf([&] { CheckPosesPlausible(d, r.model, "p.csv"); }), "<no error>");
  d.samples[0].q(5) = 1e6;
  EXPECT_EQ(ErrorOf([&] { CheckPosesPlausible(d, r.model, "p.csv"); }),
            "p.csv: row 1 column 'q6' (joint 'j6') is 1e+06 rad: beyond ±100 rad "
            "(PosePlausibility::wrapping_joint_bound_rad)");
}

TEST(PosePlausibility, PositionsBeyondTheArmsReachAreRefused) {
  // The GRB3016 with its base unknown (rcal's --frames auto): positions are judged against
  // their median. x = 1000 m in one row of 5.
  const LoadedRobot r = Grb3016(true);
  PoseDataset d;
  d.num_joints = 6;
  for (int k = 0; k < 5; ++k)
    d.samples.push_back(SampleAt(Eigen::VectorXd::Zero(6), {10.0 + 0.3 * k, -5.0, 1.0}, k + 1));
  EXPECT_EQ(ErrorOf([&] { CheckPosesPlausible(d, r.model, "p.csv"); }), "<no error>");
  d.samples[3].p_WM_W.x() = 1000.0;
  const std::string msg = ErrorOf([&] { CheckPosesPlausible(d, r.model, "p.csv"); });
  EXPECT_NE(msg.find("p.csv: row 4 column 'x' is 1000 m: the marker is 989.4 m from the median "
                     "of the measured positions, beyond the arm's reach"),
            std::string::npos)
      << msg;
  // With the base known (world = base), |p| itself is bounded: 10 m is out of reach.
  const LoadedRobot fixed = Grb3016(false);
  d.samples[3].p_WM_W.x() = 10.9;
  EXPECT_NE(ErrorOf([&] { CheckPosesPlausible(d, fixed.model, "p.csv"); })
                .find("p.csv: row 1 column 'x' is 10 m: the marker is 11.225 m from the world "
                      "origin"),
            std::string::npos);
}

TEST(PosePlausibility, TheRealUr10DataPassesAndOnePositionOf1e12DoesNot) {
  UrdfOptions o;
  o.add_base_frame = true;
  o.add_marker = true;
  const LoadedRobot r = LoadRobot(testing::SourceDir() / "config/robots/ur10.urdf", o);
  PoseDataset d = LoadFigarohUr10(FigarohCsv());
  EXPECT_EQ(ErrorOf([&] { CheckPosesPlausible(d, r.model, "ur10.csv"); }), "<no error>");
  d.samples[7].p_WM_W.z() = 1e12;
  EXPECT_NE(ErrorOf([&] {
              CheckPosesPlausible(d, r.model, "ur10.csv");
            }).find("ur10.csv: row 8 column 'z1' is 1e+12 m"),
            std::string::npos);
}

// A user's dataset of `arm` (tests/data/arms) with its base unknown: n poses uniform within the
// joint limits (seeded), each marker position the drawing's forward kinematics with a marker
// 0.1 m off the flange and the base 1.5 m away: the truth the unit mistakes below are made from.
struct ArmData {
  LoadedRobot robot;
  PoseDataset data;
};
ArmData ArmDataset(const std::string& arm, int n, unsigned seed) {
  UrdfOptions o;
  o.add_base_frame = true;
  o.add_marker = true;
  ArmData a{LoadRobot(testing::SourceDir() / "tests/data/arms" / (arm + ".urdf"), o), {}};
  const kinematics::KinematicModel& m = a.robot.model;
  Eigen::VectorXd errors = Eigen::VectorXd::Zero(m.num_params());
  for (int i = 0; i < m.num_params(); ++i) {
    const auto& P = m.parameters()[i];
    if (P.group == "marker") errors(i) = 0.1;
    if (P.group == "base" && !P.is_angle) errors(i) = 1.5;
  }
  std::mt19937 rng(seed);
  a.data.num_joints = m.num_joints();
  for (int k = 0; k < n; ++k) {
    Eigen::VectorXd q(m.num_joints());
    for (int j = 0; j < m.num_joints(); ++j) {
      const auto& jt = m.joints()[j];
      q(j) = std::uniform_real_distribution<double>(jt.lower, jt.upper)(rng);
    }
    a.data.samples.push_back(SampleAt(q, m.Forward(q, errors).p_WM_W, k + 1));
  }
  return a;
}

// Joints in degrees (issue 13, item 4): every arm's data passes in radians and is refused in
// degrees with the likely cause named; a single corrupted cell or a reading just beyond a limit
// is refused without that guess.
TEST(PosePlausibility, JointsInDegreesAreRefusedNamingTheLikelyCause) {
  for (const std::string arm : {"grb3016", "kr6_like", "ur5e_like", "irb120_like", "panda_like"}) {
    SCOPED_TRACE(arm);
    ArmData a = ArmDataset(arm, 60, 5);
    EXPECT_EQ(ErrorOf([&] { CheckPosesPlausible(a.data, a.robot.model, "p.csv"); }), "<no error>");
    PoseDataset deg = a.data;
    for (auto& p : deg.samples) p.q *= 180.0 / std::numbers::pi;
    const std::string msg = ErrorOf([&] { CheckPosesPlausible(deg, a.robot.model, "p.csv"); });
    EXPECT_NE(msg.find("every revolute joint's readings × π/180 lie within its limits: joints in "
                       "degrees? rcal reads radians"),
              std::string::npos)
        << msg;
    EXPECT_NE(msg.find("p.csv: row "), std::string::npos) << msg;
    EXPECT_EQ(msg.find("is this the robot"), std::string::npos) << msg;
  }
  // The example on the GRB3016: q2 at 170 (degrees) in one row of a radian file is a
  // corrupted cell, not a file in degrees; q2 up to 170 with every joint in degrees is.
  ArmData a = ArmDataset("grb3016", 30, 6);
  PoseDataset one = a.data;
  one.samples[4].q(1) = 170.0;
  std::string msg = ErrorOf([&] { CheckPosesPlausible(one, a.robot.model, "p.csv"); });
  EXPECT_NE(msg.find("p.csv: row 5 column 'q2' (joint 'j2') is 170 rad: beyond its limits"),
            std::string::npos)
      << msg;
  EXPECT_EQ(msg.find("degrees"), std::string::npos) << msg;
  PoseDataset deg = a.data;
  for (auto& p : deg.samples) p.q *= 180.0 / std::numbers::pi;
  msg = ErrorOf([&] { CheckPosesPlausible(deg, a.robot.model, "p.csv"); });
  // The first reading beyond its limits is row 1's q1; the message gives that column's range.
  double lo = 1e9, hi = -1e9;
  for (const auto& p : deg.samples) {
    lo = std::min(lo, p.q(0));
    hi = std::max(hi, p.q(0));
  }
  std::ostringstream range;
  range << "column 'q1' reads from " << lo << " to " << hi
        << ", and every revolute joint's readings × π/180";
  EXPECT_NE(msg.find("p.csv: row 1 column 'q1' (joint 'j1') is "), std::string::npos) << msg;
  EXPECT_NE(msg.find(range.str()), std::string::npos) << msg;
  // A degree file with one cell that no unit explains (1e6): no guess.
  deg.samples[3].q(0) = 1e6;
  msg = ErrorOf([&] { CheckPosesPlausible(deg, a.robot.model, "p.csv"); });
  EXPECT_NE(msg.find("beyond its limits"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("degrees"), std::string::npos) << msg;
  // Radians just beyond a limit (0.2 rad on j2, margin 0.1 rad), one row: no guess either.
  PoseDataset near = a.data;
  near.samples[2].q(1) = a.robot.model.joints()[1].upper + 0.2;
  msg = ErrorOf([&] { CheckPosesPlausible(near, a.robot.model, "p.csv"); });
  EXPECT_NE(msg.find("p.csv: row 3 column 'q2'"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("degrees"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("is this the robot"), std::string::npos) << msg;
}

// Another arm's robot file: the KR6's poses judged against the GRB3016's limits put many rows
// beyond them, which one corrupted cell never does.
TEST(PosePlausibility, ManyRowsBeyondTheLimitsAskWhetherThisIsTheRobotThatWasMeasured) {
  const ArmData kr6 = ArmDataset("kr6_like", 60, 7);
  const ArmData grb = ArmDataset("grb3016", 1, 7);
  const std::string msg =
      ErrorOf([&] { CheckPosesPlausible(kr6.data, grb.robot.model, "kr6.csv"); });
  EXPECT_NE(msg.find("kr6.csv: row "), std::string::npos) << msg;
  EXPECT_NE(msg.find(" of 60 poses have a joint beyond the limits of robot 'grb3016': is this the "
                     "robot that was measured?"),
            std::string::npos)
      << msg;
  EXPECT_EQ(msg.find("degrees"), std::string::npos) << msg;
  // The UR5e's readings span up to two turns (±2π joints): against the KR6's narrower limits they
  // lie beyond them by more than the KR6 joints' travel, yet they are radians, not degrees.
  const ArmData ur5e = ArmDataset("ur5e_like", 60, 7);
  const std::string ur =
      ErrorOf([&] { CheckPosesPlausible(ur5e.data, kr6.robot.model, "ur5e.csv"); });
  EXPECT_NE(ur.find("poses have a joint beyond the limits of robot 'kr6_like': is this the robot "
                    "that was measured?"),
            std::string::npos)
      << ur;
  EXPECT_EQ(ur.find("degrees"), std::string::npos) << ur;
}

// Positions in millimetres: the bulk of the positions beyond the reach and, × 1e-3, all within.
TEST(PosePlausibility, PositionsInMillimetresAreRefusedNamingTheLikelyCause) {
  for (const std::string arm : {"grb3016", "ur5e_like", "irb120_like"}) {
    SCOPED_TRACE(arm);
    const ArmData a = ArmDataset(arm, 40, 8);
    PoseDataset mm = a.data;
    for (auto& p : mm.samples) p.p_WM_W *= 1e3;
    const std::string msg = ErrorOf([&] { CheckPosesPlausible(mm, a.robot.model, "p.csv"); });
    EXPECT_NE(msg.find("beyond the arm's reach"), std::string::npos) << msg;
    EXPECT_NE(msg.find("× the arm's reach of "), std::string::npos) << msg;
    EXPECT_NE(msg.find("and × 1e-3 every one lies within it: positions in millimetres? rcal "
                       "reads metres"),
              std::string::npos)
        << msg;
    // The spread / reach ratio is the unit's 1000 within what the workspace allows: the marker
    // spreads over a sizeable part of the reach, never beyond (1 + √3) of it.
    const size_t at = msg.find("m or more from their median, ");
    ASSERT_NE(at, std::string::npos) << msg;
    const double ratio = std::stod(msg.substr(at + 29));
    EXPECT_GT(ratio, 100.0) << msg;
    EXPECT_LT(ratio, 2733.0) << msg;
  }
  // One row 1000 m off: refused, no unit guessed (the median of the others is within reach).
  ArmData a = ArmDataset("grb3016", 40, 9);
  a.data.samples[6].p_WM_W.x() += 1000.0;
  const std::string msg = ErrorOf([&] { CheckPosesPlausible(a.data, a.robot.model, "p.csv"); });
  EXPECT_NE(msg.find("p.csv: row 7 column 'x'"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("millimetres"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("half the positions"), std::string::npos) << msg;
}

TEST(PoseDataset, FigarohUr10LoadsWithOrientation) {
  const PoseDataset d = LoadPoseDataset(FigarohCsv(), 6);  // layout detected from x1/phix1
  ASSERT_EQ(d.samples.size(), 23u);
  EXPECT_EQ(d.num_joints, 6);
  EXPECT_TRUE(d.has_orientation);
  EXPECT_EQ(d.joint_names.front(), "shoulder_pan_joint");
  EXPECT_EQ(d.joint_names.back(), "wrist_3_joint");

  // The first data row, read here as plain text.
  std::ifstream in(FigarohCsv());
  std::string header, row;
  std::getline(in, header);
  std::getline(in, row);
  std::vector<double> v;
  std::stringstream ss(row);
  for (std::string cell; std::getline(ss, cell, ',');) v.push_back(std::stod(cell));
  ASSERT_EQ(v.size(), 12u);
  const PoseSample& p = d.samples[0];
  EXPECT_EQ(p.p_WM_W, Eigen::Vector3d(v[0], v[1], v[2]));
  for (int j = 0; j < 6; ++j) EXPECT_EQ(p.q(j), v[6 + j]) << j;
  EXPECT_EQ(p.marker, 0);
  ASSERT_TRUE(p.has_orientation);
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(v[5], Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(v[4], Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(v[3], Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  const Eigen::Quaterniond q(p.q_EI_wxyz(0), p.q_EI_wxyz(1), p.q_EI_wxyz(2), p.q_EI_wxyz(3));
  EXPECT_NEAR(q.norm(), 1.0, 1e-15);
  EXPECT_LT((q.toRotationMatrix() - R).norm(), 1e-12);

  const PoseDataset u = LoadFigarohUr10(FigarohCsv());
  ASSERT_EQ(u.samples.size(), 23u);
  EXPECT_EQ(u.samples[22].q, d.samples[22].q);
  EXPECT_EQ(u.samples[22].q_EI_wxyz, d.samples[22].q_EI_wxyz);
}

TEST(PoseDataset, FigarohJointNamesPickAndOrderColumns) {
  const PoseDataset d = LoadPoseDataset(FigarohCsv(), -1, {"wrist_3_joint", "shoulder_pan_joint"});
  const PoseDataset all = LoadPoseDataset(FigarohCsv());
  ASSERT_EQ(d.num_joints, 2);
  EXPECT_EQ(d.samples[4].q(0), all.samples[4].q(5));
  EXPECT_EQ(d.samples[4].q(1), all.samples[4].q(0));
  EXPECT_EQ(d.ignored_columns.size(), 4u);
  EXPECT_NE(ErrorOf([&] {
              LoadPoseDataset(FigarohCsv(), -1, {"elbow"});
            }).find("missing column 'elbow' (joint)"),
            std::string::npos);
}

TEST(PoseDataset, FigarohTwoMarkersGiveTwoSamplesPerRow) {
  const PoseDataset d = ParsePoseDataset("j1,x1,y1,z1,x2,y2,z2\n0.5,1,2,3,4,5,6\n", "two.csv", 1);
  ASSERT_EQ(d.samples.size(), 2u);
  EXPECT_EQ(d.samples[1].marker, 1);
  EXPECT_EQ(d.samples[1].p_WM_W, Eigen::Vector3d(4, 5, 6));
  EXPECT_EQ(d.samples[1].q(0), 0.5);
  EXPECT_FALSE(d.has_orientation);
}

}  // namespace
}  // namespace rcal::io
