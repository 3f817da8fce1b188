// Files people bring that rcal must refuse, not crash on, stall on or fit as if true (issue 11):
// each case runs the real `rcal` command on a file made from a real one with one defect, and
// asserts a non-zero exit, a message naming the defect (joint, column, row), and that no
// calibrated robot was written. Each of these exited 0 (or crashed) before the fix.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "rcal_cli.hpp"

namespace {

namespace fs = std::filesystem;
using rcal::tool::testing::Result;
// Under a 30 s CPU limit: a runaway walk fails the test instead of stalling it.
Result RunRcal(const std::string& args) {
  return rcal::tool::testing::RunRcal(args, 30);
}
std::filesystem::path TempDir(const std::string& name) {
  return rcal::tool::testing::TempDir("bad_files", name);
}

std::string Read(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void Write(const fs::path& p, const std::string& text) {
  std::ofstream(p) << text;
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

std::string Join(const std::vector<std::string>& lines) {
  std::string s;
  for (const auto& l : lines) s += l + "\n";
  return s;
}

// The CSV line with cell `column` (0-based) replaced.
std::string SetCell(const std::string& line, int column, const std::string& value) {
  std::vector<std::string> cells;
  std::stringstream in(line);
  for (std::string c; std::getline(in, c, ',');) cells.push_back(c);
  cells.at(column) = value;
  std::string s;
  for (size_t i = 0; i < cells.size(); ++i) s += (i ? "," : "") + cells[i];
  return s;
}

// The real UR10 (FIGAROH) shipped in the repository: its poses and its robot.
const std::string kUr10Data = RCAL_SOURCE_DIR "/data/figaroh_ur10/calibration.csv";
const std::string kUr10 = RCAL_SOURCE_DIR "/config/robots/ur10.urdf";

// The UR10 data with one cell of data row `row` (1 = first) in `column` replaced.
fs::path Ur10With(const fs::path& dir, int row, int column, const std::string& value) {
  std::vector<std::string> lines = Lines(Read(kUr10Data));
  lines.at(row) = SetCell(lines.at(row), column, value);
  const fs::path p = dir / "poses.csv";
  Write(p, Join(lines));
  return p;
}

// `rcal ARGS` run from the source tree with stdout and stderr apart: exit code, stdout, stderr.
struct SplitResult {
  int exit_code = -1;
  std::string out, err;
};
SplitResult RunRcalSplit(const std::string& args, const fs::path& dir) {
  const std::string cmd = std::string("cd ") + RCAL_SOURCE_DIR + " && ulimit -t 30 && " + RCAL_EXE +
                          " " + args + " > " + (dir / "stdout.txt").string() + " 2> " +
                          (dir / "stderr.txt").string();
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, Read(dir / "stdout.txt"),
          Read(dir / "stderr.txt")};
}

void ExpectRefused(const Result& r, const std::string& message, const fs::path& out) {
  EXPECT_GT(r.exit_code, 0) << r.output;  // refused, not crashed (-1) and not accepted (0)
  EXPECT_NE(r.output.find(message), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out / "robot_calibrated.yaml")) << "a calibrated robot was written";
}

TEST(BadFiles, CalibrateRefusesAnAbsurdJointValueNamingRowAndColumn) {
  // Column 6 of the FIGAROH file is shoulder_pan_joint. Was: exit 0, held-out error 116 m.
  const fs::path d = TempDir("q");
  for (const std::string v : {"1e308", "1e6"}) {
    const Result r = RunRcal("calibrate " + Ur10With(d, 3, 6, v).string() + " --robot " + kUr10 +
                             " --out " + (d / "out").string());
    ExpectRefused(r, "row 3 column 'shoulder_pan_joint'", d / "out");
  }
}

TEST(BadFiles, CalibrateRefusesAPositionBeyondTheArmsReach) {
  // x1 = 1000 m (was: exit 0, held-out 172 mm... mean of metres) and z1 = 1e12 m (σ = null).
  const fs::path d = TempDir("x");
  Result r = RunRcal("calibrate " + Ur10With(d, 3, 0, "1000").string() + " --robot " + kUr10 +
                     " --out " + (d / "out").string());
  ExpectRefused(r, "row 3 column 'x1' is 1000 m: the marker is", d / "out");
  EXPECT_NE(r.output.find("beyond the arm's reach"), std::string::npos) << r.output;
  r = RunRcal("calibrate " + Ur10With(d, 5, 2, "1e12").string() + " --robot " + kUr10 + " --out " +
              (d / "out").string());
  ExpectRefused(r, "row 5 column 'z1' is 1e12", d / "out");
}

// The UR10 data with every cell of columns [first, last] (0-based) multiplied by `factor`: the
// file as a user who wrote another unit gives it.
fs::path Ur10Scaled(const fs::path& dir, int first, int last, double factor) {
  std::vector<std::string> lines = Lines(Read(kUr10Data));
  for (size_t r = 1; r < lines.size(); ++r) {
    if (lines[r].empty()) continue;
    for (int c = first; c <= last; ++c) {
      std::stringstream in(lines[r]);
      std::string cell;
      for (int k = 0; k <= c; ++k) std::getline(in, cell, ',');
      std::ostringstream v;
      v.precision(17);
      v << std::stod(cell) * factor;
      lines[r] = SetCell(lines[r], c, v.str());
    }
  }
  const fs::path p = dir / "poses.csv";
  Write(p, Join(lines));
  return p;
}

// Issue 13, item 4: units where users trip, refused with the likely cause named. Was: the same
// refusal with no cause (a joint "beyond its limits", a marker "beyond the arm's reach").
TEST(BadFiles, CalibrateRefusesJointsInDegreesSayingSo) {
  // Columns 6-11 of the FIGAROH file are the six joints.
  const fs::path d = TempDir("degrees");
  const Result r =
      RunRcal("calibrate " + Ur10Scaled(d, 6, 11, 180 / 3.14159265358979323846).string() +
              " --robot " + kUr10 + " --out " + (d / "out").string());
  ExpectRefused(r, "row 1 column 'wrist_2_joint' (joint 'wrist_2_joint') is 102.226 rad",
                d / "out");
  EXPECT_NE(r.output.find("every revolute joint's readings × π/180 lie within its limits: joints "
                          "in degrees? rcal reads radians"),
            std::string::npos)
      << r.output;
}

TEST(BadFiles, CalibrateRefusesPositionsInMillimetresSayingSo) {
  // Columns 0-2 are the marker position x1, y1, z1.
  const fs::path d = TempDir("millimetres");
  const Result r = RunRcal("calibrate " + Ur10Scaled(d, 0, 2, 1000).string() + " --robot " + kUr10 +
                           " --out " + (d / "out").string());
  ExpectRefused(r, "beyond the arm's reach", d / "out");
  EXPECT_NE(r.output.find("and × 1e-3 every one lies within it: positions in millimetres? rcal "
                          "reads metres"),
            std::string::npos)
      << r.output;
}

// Data measured on one arm calibrated with another arm's file of the same joint count: the
// UR5e's ±2π joints take the KR6's readings, so nothing before the fit tells them apart. Was:
// exit 0 and a "calibrated" UR5e (held-out 168 mm mean, parameters moved by 0.54 m and 3.2 rad).
// Now refused after the fit, exit 3, no calibrated robot (an earlier run's is removed), the
// report and results.json saying why.
TEST(BadFiles, CalibrateRefusesAnotherArmsRobotFile) {
  const fs::path d = TempDir("wrong_robot");
  Result r = RunRcal("simulate --robot tests/data/arms/kr6_like.urdf --poses 60 --out " +
                     (d / "kr6.csv").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // The right file calibrates (and leaves a calibrated robot in --out).
  r = RunRcal("calibrate " + (d / "kr6.csv").string() +
              " --robot tests/data/arms/kr6_like.urdf --out " + (d / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(d / "out/robot_calibrated.yaml"));
  r = RunRcal("calibrate " + (d / "kr6.csv").string() +
              " --robot tests/data/arms/ur5e_like.urdf --out " + (d / "out").string());
  EXPECT_EQ(r.exit_code, 3) << r.output;
  ExpectRefused(r, "calibration REJECTED, no calibrated robot written", d / "out");
  EXPECT_NE(r.output.find("the drawing with only the set-up frames fitted misses the measured "
                          "positions by "),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("is this the robot that was measured "
                          "('tests/data/arms/ur5e_like.urdf')?"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(d / "out/robot_calibrated.urdf"));
  EXPECT_NE(Read(d / "out/report.md").find("**REJECTED**"), std::string::npos);
  const std::string results = Read(d / "out/results.json");
  EXPECT_NE(results.find("\"rejected\": true"), std::string::npos) << results;
}

// The refusals above as a user's terminal shows them: the likely cause on stderr, apart from the
// figures on stdout (was: on stdout with them).
TEST(BadFiles, CalibrateNamesTheLikelyCauseOnStderr) {
  const fs::path d = TempDir("stderr");
  SplitResult r =
      RunRcalSplit("calibrate " + Ur10Scaled(d, 6, 11, 180 / 3.14159265358979323846).string() +
                       " --robot " + kUr10 + " --out " + (d / "out").string(),
                   d);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("joints in degrees? rcal reads radians"), std::string::npos) << r.err;
  ASSERT_EQ(RunRcal("simulate --robot tests/data/arms/kr6_like.urdf --poses 60 --out " +
                    (d / "kr6.csv").string())
                .exit_code,
            0);
  r = RunRcalSplit("calibrate " + (d / "kr6.csv").string() +
                       " --robot tests/data/arms/ur5e_like.urdf --out " + (d / "out").string(),
                   d);
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("calibration REJECTED, no calibrated robot written"), std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("is this the robot that was measured"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find("held-out, calibrated"), std::string::npos) << r.out;  // the figures
  EXPECT_EQ(r.out.find("REJECTED"), std::string::npos) << r.out;
}

// The same for `rcal analyze`: was exit 0, "no significant effect beyond geometry" and an
// analysis.json for `calibrate --effects`; now exit 3 and no analysis.json.
TEST(BadFiles, AnalyzeRefusesAnotherArmsRobotFile) {
  const fs::path d = TempDir("wrong_robot_analyze");
  Result r = RunRcal("simulate --robot tests/data/arms/kr6_like.urdf --poses 60 --out " +
                     (d / "kr6.csv").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunRcal("analyze " + (d / "kr6.csv").string() +
              " --robot tests/data/arms/kr6_like.urdf --out " + (d / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(d / "out/analysis.json"));
  r = RunRcal("analyze " + (d / "kr6.csv").string() +
              " --robot tests/data/arms/ur5e_like.urdf --out " + (d / "out").string());
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("analysis REJECTED, no analysis.json written"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("is this the robot that was measured "
                          "('tests/data/arms/ur5e_like.urdf')?"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(d / "out/analysis.json"));
}

// A `marker` column that is not marker ids (here a row counter: 150 distinct values) would give
// the model 3 parameters per value: refused, naming the column. Was (before several markers were
// fitted): refused for any id but 0.
TEST(BadFiles, CalibrateRefusesAMarkerColumnOfTooManyIds) {
  const fs::path d = TempDir("markers");
  Result r =
      RunRcal("simulate --robot " + kUr10 + " --poses 150 --out " + (d / "sim.csv").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::vector<std::string> lines = Lines(Read(d / "sim.csv"));
  int row = 0;
  for (std::string& l : lines) {
    if (l.empty() || l[0] == '#') continue;
    l += row == 0 ? ",marker" : "," + std::to_string(row);
    ++row;
  }
  Write(d / "poses.csv", Join(lines));
  r = RunRcal("calibrate " + (d / "poses.csv").string() + " --robot " + kUr10 + " --out " +
              (d / "out").string());
  ExpectRefused(r, "column 'marker': 150 distinct ids; rcal fits at most 100 markers", d / "out");
}

std::string LoopUrdf() {
  std::string x = "<?xml version=\"1.0\"?>\n<robot name=\"loop\">\n";
  for (const char* l : {"base", "a", "b", "c"}) x += std::string("<link name=\"") + l + "\"/>\n";
  const char* joints[][3] = {
      {"j1", "base", "a"}, {"j2", "a", "b"}, {"j3", "b", "c"}, {"j4", "c", "a"}};
  for (const auto& j : joints)
    x += std::string("<joint name=\"") + j[0] + "\" type=\"revolute\"><parent link=\"" + j[1] +
         "\"/><child link=\"" + j[2] +
         "\"/><origin xyz=\"0 0 0.1\"/><axis xyz=\"0 0 1\"/>"
         "<limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>\n";
  return x + "</robot>\n";
}

TEST(BadFiles, AUrdfLoopIsRefusedNamingTheJoint) {
  // Was: SIGSEGV (identifiability, calibrate), and with --tip memory growing ~130 MB/s.
  const fs::path d = TempDir("loop");
  Write(d / "loop.urdf", LoopUrdf());
  Write(d / "poses.csv", "q1,q2,q3,x,y,z\n0,0,0,0.1,0.2,0.3\n0.1,0.1,0.1,0.1,0.2,0.3\n");
  const std::string expected = "joint 'j4' closes a loop: its child link 'a' is an ancestor";
  ExpectRefused(RunRcal("identifiability --robot " + (d / "loop.urdf").string()), expected,
                d / "out");
  ExpectRefused(RunRcal("calibrate " + (d / "poses.csv").string() + " --robot " +
                        (d / "loop.urdf").string() + " --out " + (d / "out").string()),
                expected, d / "out");
  ExpectRefused(RunRcal("calibrate " + (d / "poses.csv").string() + " --robot " +
                        (d / "loop.urdf").string() + " --tip c --out " + (d / "out").string()),
                expected, d / "out");
}

TEST(BadFiles, AnAbsurdRobotYamlIsRefusedNamingTheKey) {
  const fs::path d = TempDir("yaml");
  std::string yaml = Read(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  yaml.replace(yaml.find("d: 0.645"), 8, "d: 1e6");
  Write(d / "robot.yaml", yaml);
  ExpectRefused(RunRcal("identifiability --robot " + (d / "robot.yaml").string()),
                "links[3].d: '1e6' is beyond 100 m", d / "out");
}

// Issue 13, item 4: a robot file in degrees or millimetres, brought to every command that takes
// one (calibrate DATA, calibrate --log, analyze), is refused with the field and the likely unit
// on stderr. Was: limits of ±90 taken as ±90 rad and an alpha of -90 as -90 rad, the arm
// "calibrated", exit 0; a URDF in mm refused without naming the unit; every refusal on stdout.
TEST(BadFiles, ARobotFileInDegreesOrMillimetresIsRefusedNamingTheUnitOnStderr) {
  const fs::path d = TempDir("robot_units");
  const std::string grb = Read(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  ASSERT_EQ(RunRcal("simulate --robot config/robots/grb3016.yaml --poses 30 --out " +
                    (d / "poses.csv").string())
                .exit_code,
            0);
  std::ofstream(d / "empty.lcmlog").close();
  const auto refused = [&](const std::string& robot, const std::string& message) {
    // calibrate --log takes its robot from a cell file: the demo's cell naming this robot.
    std::string cell = Read(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml");
    cell.replace(cell.find("../robots/grb3016.yaml"), 22, robot);
    Write(d / "cell.yaml", cell);
    for (const std::string& command : {"calibrate " + (d / "poses.csv").string() + " --out " +
                                           (d / "out").string() + " --robot " + robot,
                                       "calibrate --log " + (d / "empty.lcmlog").string() +
                                           " --cell " + (d / "cell.yaml").string(),
                                       "analyze " + (d / "poses.csv").string() + " --out " +
                                           (d / "out").string() + " --robot " + robot}) {
      const SplitResult r = RunRcalSplit(command, d);
      EXPECT_EQ(r.exit_code, 1) << command << "\n" << r.out << r.err;
      EXPECT_NE(r.err.find(message), std::string::npos) << command << "\n" << r.err;
      EXPECT_EQ(r.out.find("[error]"), std::string::npos) << command << "\n" << r.out;
      EXPECT_FALSE(fs::exists(d / "out/robot_calibrated.yaml")) << command;
    }
  };
  // Limits of ±90° on joint 5, below the 100 rad any angle is bounded by.
  std::string yaml = grb;
  yaml.replace(yaml.find("lower: -2*pi/3, upper: 2*pi/3"), 29, "lower: -90, upper: 90");
  Write(d / "limits.yaml", yaml);
  refused((d / "limits.yaml").string(),
          "limits.yaml: links[4].joint.lower: '-90' rad is beyond two turns (4π): degrees? rcal "
          "files are in radians: -90° is -pi/2 (line 24)");
  // Every alpha of -pi/2 as -90.
  yaml = grb;
  for (size_t at = 0; (at = yaml.find("alpha: -pi/2", at)) != std::string::npos;)
    yaml.replace(at, 12, "alpha: -90");
  Write(d / "alpha.yaml", yaml);
  refused((d / "alpha.yaml").string(),
          "alpha.yaml: links[0].alpha: '-90' rad is beyond a turn (2π): degrees? rcal files are "
          "in radians: -90° is -pi/2 (line 15)");
  // The UR10's URDF with its origins in millimetres.
  std::string urdf = Read(kUr10);
  const std::string from = "xyz=\"-0.6127 0 0\"";
  ASSERT_NE(urdf.find(from), std::string::npos);
  urdf.replace(urdf.find(from), from.size(), "xyz=\"-612.7 0 0\"");
  Write(d / "ur10_mm.urdf", urdf);
  const SplitResult r =
      RunRcalSplit("calibrate " + kUr10Data + " --robot " + (d / "ur10_mm.urdf").string() +
                       " --out " + (d / "out").string(),
                   d);
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(r.err.find("joint 'elbow_joint': origin xyz beyond 100 m: not an arm's dimension "
                       "(xyz -612.7 0 0): millimetres? URDF lengths are metres"),
            std::string::npos)
      << r.err;
}

// The first 5000 rows of BROAD trial 02 (40 s of rest, then motion), one cell replaced.
fs::path BroadWith(const fs::path& dir, int row, int column, const std::string& value) {
  std::vector<std::string> lines = Lines(Read(RCAL_SHARED_DIR "/data/broad/broad_02_100hz.csv"));
  lines.resize(5001);
  if (row > 0) lines.at(row) = SetCell(lines.at(row), column, value);
  const fs::path p = dir / "trial.csv";
  Write(p, Join(lines));
  return p;
}

TEST(BadFiles, FuseRefusesImuValuesBeyondTheSensorRange) {
  // Gyro 1e300 (finite): was exit 0 and "total RMSE 0.00°" from a filter gone NaN.
  const fs::path d = TempDir("fuse");
  Result r = RunRcal("fuse " + BroadWith(d, 4100, 1, "1e300").string());
  EXPECT_GT(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("row 4100 column 'gyr_x' is 1e300: beyond the gyro range ±35 rad/s"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("0.00 |"), std::string::npos) << r.output;
  // NaN accelerometer, time going back.
  r = RunRcal("fuse " + BroadWith(d, 4200, 6, "nan").string());
  EXPECT_GT(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("row 4200 column 'acc_z' is nan: a finite number is required"),
            std::string::npos)
      << r.output;
  r = RunRcal("fuse " + BroadWith(d, 4300, 0, "1").string());
  EXPECT_GT(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("row 4300 column 't_s' is 1: time must increase"), std::string::npos)
      << r.output;
  // The range is a setting: a wider gyro range accepts the file (and the filter copes).
  r = RunRcal("fuse " + BroadWith(d, 0, 0, "").string() + " --set imu.gyro_range=50");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

TEST(BadFiles, AnalyzeRefusesImuValuesBeyondTheSensorRange) {
  // rcal analyze read IMU streams with its own loader, which took any finite value: a 1e300
  // gyro went into the analysis.
  const fs::path d = TempDir("analyze");
  const Result r = RunRcal("analyze " + BroadWith(d, 4100, 1, "1e300").string() + " --out " +
                           (d / "out").string());
  EXPECT_GT(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("row 4100 column 'gyr_x' is 1e300: beyond the gyro range ±35 rad/s"),
            std::string::npos)
      << r.output;
}

}  // namespace
