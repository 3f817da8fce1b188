#include "rcal/io/pose_dataset.hpp"

#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>

#include "io_test_util.hpp"
#include "rcal/io/atomic_file.hpp"

namespace rcal::io {
namespace {

using testing::ErrorOf;
using testing::ScratchDir;

std::filesystem::path FigarohCsv() {
  return testing::SharedDir() / "data/figaroh_ur10/calibration.csv";
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
    p.q = Eigen::Vector3d(n(rng), n(rng), n(rng));
    p.p_WM_W = Eigen::Vector3d(n(rng), n(rng), n(rng)) * 0.5;
    p.has_orientation = i != 3;  // one pose without orientation
    if (p.has_orientation) {
      p.q_EI_wxyz = Eigen::Vector4d(n(rng), n(rng), n(rng), n(rng)).normalized();
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
        BadCsv{"q1,q2,x,y,z,dq1\n0,0,1,2,3,1\n", "missing column 'dq2'"},
        BadCsv{"q1,q2,x,y,z,dq1,dq2\n0,0,1,2,3,1,2\n", "row 1 column 'dq2' must be -1, 0 or 1"},
        BadCsv{"q1,q2,x,y,z\n0,0,1,2\n", "line 2 has 4 cells, the header has 5"},
        BadCsv{"# only a comment\n", "no header row"},
        BadCsv{"x1,y1,z1,phix1,phiy1,j1,j2\n1,2,3,0,0,0,0\n",
               "columns 'phix1,phiy1,phiz1' come together"},
        BadCsv{"x1,y1,phix1,phiy1,phiz1,j1,j2\n1,2,0,0,0,0,0\n", "missing column 'z1'"},
        BadCsv{"x1,y1,z1,j1,j2,j3\n1,2,3,0,0,0\n", "has 3 joint columns, expected 2"},
        BadCsv{"x1,y1,z1,j1,j2\n1,2,3,0,\n", "row 1 column 'j2' is empty"}));

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
