#include "rcal/io/robot_urdf.hpp"

#include <gtest/gtest.h>
#include <tinyxml.h>

#include <filesystem>
#include <map>
#include <numbers>
#include <random>
#include <sstream>
#include <tuple>
#include <vector>

#include "../kinematics/test_robots.hpp"
#include "io_test_util.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/pose_dataset.hpp"

namespace rcal::io {
namespace {

using kinematics::KinematicModel;
using testing::ErrorOf;
using testing::ScratchDir;
constexpr double kPi = std::numbers::pi;

std::filesystem::path Ur10Urdf() {
  return testing::SourceDir() / "config/robots/ur10.urdf";
}

const std::vector<std::string> kUrJoints{"shoulder_pan_joint", "shoulder_lift_joint",
                                         "elbow_joint",        "wrist_1_joint",
                                         "wrist_2_joint",      "wrist_3_joint"};

// An independent reading of a URDF: joints by child link, straight from the XML with tinyxml.
struct XmlJoint {
  std::string name, type, parent;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero(), rpy = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();
};

Eigen::Vector3d Triple(const char* text) {
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  if (text == nullptr) return v;
  std::istringstream in(text);
  in >> v(0) >> v(1) >> v(2);
  return v;
}

std::map<std::string, XmlJoint> JointsByChild(const std::string& xml) {
  TiXmlDocument doc;
  doc.Parse(xml.c_str());
  EXPECT_FALSE(doc.Error());
  std::map<std::string, XmlJoint> out;
  for (const TiXmlElement* j = doc.RootElement()->FirstChildElement("joint"); j != nullptr;
       j = j->NextSiblingElement("joint")) {
    XmlJoint x;
    x.name = j->Attribute("name");
    x.type = j->Attribute("type");
    x.parent = j->FirstChildElement("parent")->Attribute("link");
    if (const TiXmlElement* o = j->FirstChildElement("origin")) {
      x.xyz = Triple(o->Attribute("xyz"));
      x.rpy = Triple(o->Attribute("rpy"));
    }
    if (const TiXmlElement* a = j->FirstChildElement("axis")) x.axis = Triple(a->Attribute("xyz"));
    out[j->FirstChildElement("child")->Attribute("link")] = x;
  }
  return out;
}

/// Hand-chained product of the URDF origins and joint motions, base link → tip link, with the
/// joint values given by joint name.
Eigen::Isometry3d ChainByHand(const std::string& xml, const std::string& base,
                              const std::string& tip, const std::map<std::string, double>& q) {
  const auto joints = JointsByChild(xml);
  std::vector<XmlJoint> chain;
  for (std::string link = tip; link != base;) {
    const XmlJoint& j = joints.at(link);
    chain.insert(chain.begin(), j);
    link = j.parent;
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (const XmlJoint& j : chain) {
    Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();
    origin.translation() = j.xyz;
    origin.linear() = (Eigen::AngleAxisd(j.rpy(2), Eigen::Vector3d::UnitZ()) *
                       Eigen::AngleAxisd(j.rpy(1), Eigen::Vector3d::UnitY()) *
                       Eigen::AngleAxisd(j.rpy(0), Eigen::Vector3d::UnitX()))
                          .toRotationMatrix();
    T = T * origin;
    if (j.type == "revolute" || j.type == "continuous") {
      T = T * Eigen::AngleAxisd(q.at(j.name), j.axis.normalized());
    } else if (j.type == "prismatic") {
      T = T * Eigen::Translation3d(q.at(j.name) * j.axis.normalized());
    }
  }
  return T;
}

std::map<std::string, double> ByName(const KinematicModel& m, const Eigen::VectorXd& q) {
  std::map<std::string, double> out;
  for (int j = 0; j < m.num_joints(); ++j) out[m.joints()[j].name] = q(j);
  return out;
}

double FrameDifference(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.matrix() - b.matrix()).norm();
}

TEST(RobotUrdf, Ur10LoadsTheChainFromRootToTheLastMovingJoint) {
  const KinematicModel m = LoadRobotUrdf(Ur10Urdf());
  ASSERT_EQ(m.num_joints(), 6);
  for (int j = 0; j < 6; ++j) EXPECT_EQ(m.joints()[j].name, kUrJoints[j]);
  EXPECT_EQ(m.num_params(), 36);  // 6 placement errors per joint
  EXPECT_GE(m.FindParameter("elbow_joint_drx"), 0);
  EXPECT_DOUBLE_EQ(m.joints()[2].lower, -kPi);
  EXPECT_DOUBLE_EQ(m.joints()[0].upper, 2 * kPi);
  const RobotSpec spec = LoadUrdfRobotSpec(Ur10Urdf());
  EXPECT_EQ(spec.convention, Convention::kUrdf);
  // The chain ends at wrist_3_link (camera and tool frames hang below it, fixed).
  ASSERT_TRUE(spec.links.back().joint.has_value());
  EXPECT_EQ(spec.links.back().joint->name, "wrist_3_joint");
  EXPECT_EQ(spec.links.size(), 9u);  // support, robot, base_link_inertia fixed + 6 joints
}

TEST(RobotUrdf, Ur10ForwardKinematicsEqualsHandChainedOrigins) {
  const std::string xml = ReadFile(Ur10Urdf());
  const KinematicModel m = LoadRobotUrdf(Ur10Urdf());
  UrdfOptions o;
  o.tip_link = "camera_color_optical_frame";
  const KinematicModel to_camera = LoadRobotUrdf(Ur10Urdf(), o);
  std::mt19937 rng(11);
  std::vector<Eigen::VectorXd> qs{Eigen::VectorXd::Zero(6)};
  for (int k = 0; k < 20; ++k) qs.push_back(kinematics::testing::RandomJoints(m, rng));
  for (const auto& q : qs) {
    const Eigen::Isometry3d expected = ChainByHand(xml, "world", "wrist_3_link", ByName(m, q));
    EXPECT_LT(FrameDifference(m.ToolFrame(q, m.Nominal()), expected), 1e-12);
    EXPECT_LT((m.Forward(q, m.Nominal()).p_WM_W - expected.translation()).norm(), 1e-12);
    // Down to the camera: the fixed joints after the arm, with their odd rotations.
    const Eigen::Isometry3d camera =
        ChainByHand(xml, "world", "camera_color_optical_frame", ByName(m, q));
    EXPECT_LT(FrameDifference(to_camera.ToolFrame(q, to_camera.Nominal()), camera), 1e-12);
  }
}

TEST(RobotUrdf, BaseAndTipLinksChooseTheChain) {
  const std::string xml = ReadFile(Ur10Urdf());
  UrdfOptions o;
  o.base_link = "base_link";
  o.tip_link = "wrist_3_link";
  const KinematicModel m = LoadRobotUrdf(Ur10Urdf(), o);
  ASSERT_EQ(m.num_joints(), 6);
  std::mt19937 rng(12);
  for (int k = 0; k < 10; ++k) {
    const Eigen::VectorXd q = kinematics::testing::RandomJoints(m, rng);
    EXPECT_LT(FrameDifference(m.ToolFrame(q, m.Nominal()),
                              ChainByHand(xml, "base_link", "wrist_3_link", ByName(m, q))),
              1e-12);
  }
  o.tip_link = "no_such_link";
  EXPECT_NE(ErrorOf([&] { LoadRobotUrdf(Ur10Urdf(), o); }).find("tip link 'no_such_link'"),
            std::string::npos);
  o.tip_link = "wall_link";  // not below base_link
  EXPECT_NE(ErrorOf([&] { LoadRobotUrdf(Ur10Urdf(), o); }).find("is not below base link"),
            std::string::npos);
}

TEST(RobotUrdf, BaseFrameAndMarkerOptions) {
  UrdfOptions o;
  o.add_base_frame = true;
  o.base_xyz = {0.1, -0.2, 0.3};
  o.base_rpy = {0.01, 0.02, 0.03};
  o.add_marker = true;
  o.marker_xyz = {0.0, 0.0, 0.05};
  const KinematicModel m = LoadRobotUrdf(Ur10Urdf(), o);
  EXPECT_EQ(m.num_params(), 36 + 6 + 3);
  EXPECT_EQ(m.FindParameter("base_x"), 0);
  EXPECT_GE(m.FindParameter("marker_z"), 0);
  const KinematicModel plain = LoadRobotUrdf(Ur10Urdf());
  const Eigen::VectorXd q = Eigen::VectorXd::LinSpaced(6, -1.0, 1.0);
  Eigen::Isometry3d T_WB = Eigen::Isometry3d::Identity();
  T_WB.translation() = o.base_xyz;
  T_WB.linear() = geometry::FromRpy(o.base_rpy);
  const Eigen::Vector3d expected = T_WB * (plain.ToolFrame(q, plain.Nominal()) * o.marker_xyz);
  EXPECT_LT((m.Forward(q, m.Nominal()).p_WM_W - expected).norm(), 1e-12);
  o.identify_joints = false;
  o.identify_base = false;
  EXPECT_EQ(LoadRobotUrdf(Ur10Urdf(), o).num_params(), 3);
}

TEST(RobotUrdf, CalibratedUrdfRoundTrips) {
  ScratchDir dir;
  const LoadedRobot robot = LoadRobot(Ur10Urdf());
  const KinematicModel& m = robot.model;
  std::mt19937 rng(13);
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::VectorXd x = kinematics::testing::RandomErrors(m, rng, 0.005, 0.02);
    const auto out = dir / "calibrated.urdf";
    SaveCalibratedUrdf(Ur10Urdf(), out, robot.spec, m, x);
    const KinematicModel cal = LoadRobotUrdf(out);
    ASSERT_EQ(cal.num_params(), m.num_params());
    for (int k = 0; k < 20; ++k) {
      const Eigen::VectorXd q = kinematics::testing::RandomJoints(m, rng);
      EXPECT_LT(FrameDifference(cal.ToolFrame(q, cal.Nominal()), m.ToolFrame(q, x)), 1e-12);
    }
    // The rest of the file is kept: visuals, the fixed joints, the comment saying what changed.
    const std::string text = ReadFile(out);
    EXPECT_NE(
        text.find("Calibrated by rcal: chain world -> wrist_3_link; 6 joint origins corrected"),
        std::string::npos);
    EXPECT_NE(text.find("wall_joint"), std::string::npos);
    EXPECT_NE(text.find("<mesh"), std::string::npos);
  }
  // Zero errors leave the origins as they were.
  const std::string same =
      CalibratedUrdfText(ReadFile(Ur10Urdf()), Ur10Urdf().string(), robot.spec, m, m.Nominal());
  EXPECT_NE(same.find("rpy=\"1.570796326589793 3.141592653589793 3.141592653589793\""),
            std::string::npos);
}

// Issue 12: the calibrated URDF carries the set-up frames as fixed joints, so a user's tools see
// the calibrated cell from the URDF alone: the chain rcal_world → rcal_marker_<id> of the file,
// loaded with no errors, gives the calibrated marker positions (world frame), for every marker,
// and rcal_world → rcal_imu the calibrated flange → IMU rotation. The chain here starts at
// base_link, below the URDF's root (world → support_link → base_link on fixed joints).
TEST(RobotUrdf, CalibratedUrdfCarriesTheSetupFramesAsFixedJoints) {
  ScratchDir dir;
  UrdfOptions o;
  o.base_link = "base_link";
  o.add_base_frame = true;
  o.add_marker = true;
  LoadedRobot robot = LoadRobot(Ur10Urdf(), o);
  robot.spec.markers.push_back({3, {0.02, -0.05, 0.04}, true});
  robot.spec.imu = FrameSpec{};
  const KinematicModel m = BuildModel(robot.spec);
  ASSERT_EQ(m.markers().size(), 2u);
  std::mt19937 rng(21);
  Eigen::VectorXd x = kinematics::testing::RandomErrors(m, rng, 0.005, 0.02);
  x(m.FindParameter("base_x")) = 1.2;  // a far, turned base and 10 cm markers
  x(m.FindParameter("base_rz")) = 2.5;
  x(m.FindParameter("marker_z")) = 0.1;
  x(m.FindParameter("imu_rx")) = 0.7;
  const auto out = dir / "calibrated.urdf";
  SaveCalibratedUrdf(Ur10Urdf(), out, robot.spec, m, x);
  const std::string text = ReadFile(out);
  EXPECT_NE(text.find("rcal_world (the position sensor's frame) -> world"), std::string::npos)
      << text.substr(0, 600);
  for (int slot = 0; slot < 2; ++slot) {
    UrdfOptions reload;
    reload.base_link = "rcal_world";
    reload.tip_link = slot == 0 ? "rcal_marker" : "rcal_marker_3";
    reload.identify_joints = false;
    const KinematicModel cal = LoadRobotUrdf(out, reload);
    ASSERT_EQ(cal.num_params(), 0);
    for (int k = 0; k < 50; ++k) {
      const Eigen::VectorXd q = kinematics::testing::RandomJoints(m, rng);
      EXPECT_LT(
          (cal.ToolFrame(q, cal.Nominal()).translation() - m.ForMarker(slot).Forward(q, x).p_WM_W)
              .norm(),
          1e-9)
          << reload.tip_link;
    }
  }
  UrdfOptions imu;
  imu.base_link = "rcal_world";
  imu.tip_link = "rcal_imu";
  imu.identify_joints = false;
  const KinematicModel cal = LoadRobotUrdf(out, imu);
  const Eigen::VectorXd q = kinematics::testing::RandomJoints(m, rng);
  EXPECT_LT((cal.ToolFrame(q, cal.Nominal()).linear() - m.Forward(q, x).R_EI).norm(), 1e-9);
}

TEST(RobotUrdf, CalibratedUrdfRejectsAForeignModel) {
  const KinematicModel other = kinematics::testing::UrLikeUrdf();
  const RobotSpec spec = LoadRobot(Ur10Urdf()).spec;
  const std::string msg = ErrorOf([&] {
    CalibratedUrdfText(ReadFile(Ur10Urdf()), "robot.urdf", spec, other, other.Nominal());
  });
  EXPECT_NE(msg.find("joint 'shoulder_pan' of model 'ur_like' is not in the URDF"),
            std::string::npos)
      << msg;
}

TEST(RobotUrdf, ComposeUrdfOriginMatchesTheEtLayout) {
  std::mt19937 rng(14);
  std::normal_distribution<double> n(0.0, 1.0);
  for (double pitch : {0.3, kPi / 2, -kPi / 2, kPi / 2 - 1e-9, kPi}) {
    const Eigen::Vector3d xyz(0.1, -0.2, 0.3), rpy(0.4, pitch, -0.7);
    Eigen::Matrix<double, 6, 1> e;
    for (int i = 0; i < 6; ++i) e(i) = n(rng) * (i < 3 ? 0.01 : 0.05);
    Eigen::Vector3d xyz2, rpy2;
    ComposeUrdfOrigin(xyz, rpy, e, &xyz2, &rpy2);
    Eigen::Isometry3d expected = Eigen::Isometry3d::Identity();
    expected.translation() = xyz;
    expected.linear() = geometry::FromRpy(rpy);
    expected = expected * Eigen::Translation3d(e.head<3>()) *
               Eigen::AngleAxisd(e(3), Eigen::Vector3d::UnitZ()) *
               Eigen::AngleAxisd(e(4), Eigen::Vector3d::UnitY()) *
               Eigen::AngleAxisd(e(5), Eigen::Vector3d::UnitX());
    Eigen::Isometry3d got = Eigen::Isometry3d::Identity();
    got.translation() = xyz2;
    got.linear() = geometry::FromRpy(rpy2);
    EXPECT_LT(FrameDifference(got, expected), 1e-14) << "pitch " << pitch;
    // Exactly at gimbal lock too.
    const Eigen::Matrix3d R = geometry::FromRpy(0.4, pitch, -0.7);
    EXPECT_LT((geometry::FromRpy(RobustRpy(R)) - R).norm(), 1e-15) << "pitch " << pitch;
  }
}

std::string TinyUrdf(const std::string& extra) {
  return R"(<?xml version="1.0"?>
<robot name="tiny">
  <link name="a"/><link name="b"/><link name="c"/>
  <joint name="ab" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="bc" type="fixed"><parent link="b"/><child link="c"/>
    <origin xyz="0.2 0 0" rpy="0 0 0"/></joint>
)" + extra +
         "</robot>\n";
}

TEST(RobotUrdf, BadInputIsNamed) {
  // The default tip is the link after the last moving joint, not a fixed leaf.
  EXPECT_EQ(ParseUrdfRobotSpec(TinyUrdf(""), "tiny.urdf").links.size(), 1u);
  // Two moving branches of the same depth: the tip must be named.
  const std::string two_arms = TinyUrdf(R"(<link name="d"/>
  <joint name="ad" type="revolute"><parent link="a"/><child link="d"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
)");
  EXPECT_NE(ErrorOf([&] { ParseUrdfRobotSpec(two_arms, "tiny.urdf"); })
                .find("tiny.urdf: the tip link is ambiguous (links after the deepest moving "
                      "joints below 'a': b, d)"),
            std::string::npos);
  UrdfOptions o;
  o.tip_link = "c";
  EXPECT_EQ(ParseUrdfRobotSpec(two_arms, "tiny.urdf", o).links.size(), 2u);
  // Malformed XML and invalid URDF.
  EXPECT_NE(ErrorOf([&] {
              ParseUrdfRobotSpec("<robot name='x'><link", "bad.urdf");
            }).find("bad.urdf: malformed XML"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] {
              ParseUrdfRobotSpec("<robot name='x'></robot>", "bad.urdf");
            }).find("bad.urdf: not a valid URDF"),
            std::string::npos);
  // Unsupported joint types.
  std::string floating = TinyUrdf("");
  floating.replace(floating.find("type=\"revolute\""), 15, "type=\"floating\"");
  EXPECT_NE(ErrorOf([&] {
              ParseUrdfRobotSpec(floating, "f.urdf");
            }).find("f.urdf: joint 'ab': only revolute"),
            std::string::npos);
  // Only fixed joints.
  std::string fixed_only = TinyUrdf("");
  fixed_only.replace(fixed_only.find("type=\"revolute\""), 15, "type=\"fixed\"");
  EXPECT_NE(ErrorOf([&] {
              ParseUrdfRobotSpec(fixed_only, "x.urdf");
            }).find("x.urdf: no moving joint below base link 'a'"),
            std::string::npos);
}

// A URDF of the links and joints given; each joint "name:parent:child" is revolute about z with
// limits ±1 and an origin 0.1 m up.
std::string GraphUrdf(const std::vector<std::string>& links,
                      const std::vector<std::string>& joints) {
  std::string xml = "<?xml version=\"1.0\"?>\n<robot name=\"graph\">\n";
  for (const auto& l : links) xml += "  <link name=\"" + l + "\"/>\n";
  for (const auto& j : joints) {
    const size_t a = j.find(':'), b = j.find(':', a + 1);
    xml += "  <joint name=\"" + j.substr(0, a) + "\" type=\"revolute\"><parent link=\"" +
           j.substr(a + 1, b - a - 1) + "\"/><child link=\"" + j.substr(b + 1) +
           "\"/><origin xyz=\"0 0 0.1\"/><axis xyz=\"0 0 1\"/>"
           "<limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>\n";
  }
  return xml + "</robot>\n";
}

TEST(RobotUrdf, ALoopIsRefusedNamingTheJointThatClosesIt) {
  // j4's child a is an ancestor of its parent c. liburdfdom accepts this (base is still the one
  // root); walking to the tip recursed without end (SIGSEGV), and with a tip link the walk up
  // never reached the base.
  const std::string xml =
      GraphUrdf({"base", "a", "b", "c"}, {"j1:base:a", "j2:a:b", "j3:b:c", "j4:c:a"});
  const std::string expected =
      "loop.urdf: joint 'j4' closes a loop: its child link 'a' is an ancestor of its parent "
      "link 'c'";
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(xml, "loop.urdf"); }), expected);
  UrdfOptions o;
  o.tip_link = "c";
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(xml, "loop.urdf", o); }), expected);
  // A loop without the root (every link has a parent), and a joint onto its own link.
  EXPECT_NE(ErrorOf([&] {
              ParseUrdfRobotSpec(GraphUrdf({"a", "b"}, {"j1:a:b", "j2:b:a"}), "l.urdf");
            }).find("l.urdf: joint 'j2' closes a loop"),
            std::string::npos);
  EXPECT_EQ(ErrorOf([&] {
              ParseUrdfRobotSpec(GraphUrdf({"a", "b"}, {"j1:a:b", "j2:b:b"}), "s");
            }),
            "s: joint 'j2': link 'b' is both its parent and its child");
}

TEST(RobotUrdf, TheRobotCheckedIsTheRobotLiburdfdomReads) {
  // Found by fuzz_robot_urdf (a 1216-byte leak in liburdfdom): an unclosed <?xml declaration
  // swallows the first <robot> tag, so the document's first element is a <link>; the check
  // looked at that root and passed, while liburdfdom took the first top-level <robot> (a loop)
  // and leaked its links.
  std::string loop = GraphUrdf({"a", "b"}, {"j1:a:b", "j2:b:a"});
  loop.erase(0, loop.find("<robot"));
  const std::string xml =
      "<?xml version=\"1.0\"\n<robot name=\"first\"><link name=\"base\"/></robot>\n" + loop;
  EXPECT_NE(
      ErrorOf([&] { ParseUrdfRobotSpec(xml, "u.urdf"); }).find("u.urdf: joint 'j2' closes a loop"),
      std::string::npos);
  // Two top-level robots: which one is meant is not guessed; none is an error too.
  const std::string one = GraphUrdf({"base", "a"}, {"j1:base:a"});
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(one + one.substr(one.find("<robot")), "t.urdf"); }),
            "t.urdf: more than one top-level <robot> element");
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec("<model name=\"x\"/>", "n.urdf"); }),
            "n.urdf: no top-level <robot> element");
}

TEST(RobotUrdf, ALinkWithSeveralParentsIsRefused) {
  // A diamond: no loop as parent links go, but c is the child of two joints (liburdfdom keeps
  // the last one and lists c under both parents).
  const std::string xml =
      GraphUrdf({"base", "a", "b", "c"}, {"j1:base:a", "j2:base:b", "j3:a:c", "j4:b:c"});
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(xml, "d.urdf"); }),
            "d.urdf: joint 'j4': link 'c' already has a parent (joint 'j3'); a link has one "
            "parent in a URDF tree");
}

TEST(RobotUrdf, AMissingLinkIsNamedWithItsJoint) {
  EXPECT_EQ(ErrorOf([&] {
              ParseUrdfRobotSpec(GraphUrdf({"base", "a"}, {"j1:base:a", "j2:a:ghost"}), "m.urdf");
            }),
            "m.urdf: joint 'j2': child link 'ghost' is not a <link> of the file");
  EXPECT_EQ(ErrorOf([&] {
              ParseUrdfRobotSpec(GraphUrdf({"base", "a"}, {"j1:nowhere:a"}), "m.urdf");
            }),
            "m.urdf: joint 'j1': parent link 'nowhere' is not a <link> of the file");
  std::string no_parent = GraphUrdf({"base", "a"}, {"j1:base:a"});
  no_parent.replace(no_parent.find("<parent link=\"base\"/>"), 21, "");
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(no_parent, "m.urdf"); }),
            "m.urdf: joint 'j1': no <parent link=\"...\"/>");
}

TEST(RobotUrdf, ALongChainIsWalkedWithoutRecursion) {
  // 100 000 links in a row: a recursive walk to the deepest joint needed ~100 000 stack frames.
  constexpr int kLinks = 100000;
  std::string xml = "<robot name=\"long\">\n";
  for (int i = 0; i < kLinks; ++i) xml += "<link name=\"l" + std::to_string(i) + "\"/>";
  for (int i = 1; i < kLinks; ++i)
    xml += "<joint name=\"j" + std::to_string(i) + "\" type=\"continuous\"><parent link=\"l" +
           std::to_string(i - 1) + "\"/><child link=\"l" + std::to_string(i) +
           "\"/><axis xyz=\"0 0 1\"/></joint>\n";
  xml += "</robot>\n";
  const RobotSpec spec = ParseUrdfRobotSpec(xml, "long.urdf");
  ASSERT_EQ(spec.links.size(), static_cast<size_t>(kLinks - 1));
  EXPECT_EQ(spec.links.back().joint->name, "j" + std::to_string(kLinks - 1));
}

// Issue 13, item 4: a URDF in millimetres (a 600 mm link as 600 m), refused naming the unit; a
// small arm in millimetres, every origin below 100 m, by the sum of its lengths. Was: the same
// refusal without the unit, and the small arm accepted.
TEST(RobotUrdf, LengthsInMillimetresAreRefusedNamingTheUnit) {
  const std::string ur5e = ReadFile(testing::SourceDir() / "tests/data/arms/ur5e_like.urdf");
  // Every origin xyz × 1000.
  std::string mm = ur5e;
  for (size_t at = 0; (at = mm.find("<origin xyz=\"", at)) != std::string::npos;) {
    at += 13;
    const size_t end = mm.find('"', at);
    std::istringstream in(mm.substr(at, end - at));
    std::ostringstream out;
    for (double v; in >> v;) out << (out.tellp() > 0 ? " " : "") << v * 1000;
    mm.replace(at, end - at, out.str());
  }
  std::string msg = ErrorOf([&] { ParseUrdfRobotSpec(mm, "mm.urdf"); });
  EXPECT_NE(msg.find("mm.urdf: joint 'shoulder_pan_joint': origin xyz beyond 100 m: not an arm's "
                     "dimension (xyz 0 0 162.5): millimetres? URDF lengths are metres"),
            std::string::npos)
      << msg;
  // Origins of 60 m and 50 m: each below 100 m, their sum beyond.
  std::string small = TinyUrdf("");
  small.replace(small.find("xyz=\"0 0 0.1\""), 13, "xyz=\"0 0 60\"");
  small.replace(small.find("xyz=\"0.2 0 0\""), 13, "xyz=\"0 0 50\"");
  UrdfOptions to_c;
  to_c.tip_link = "c";
  msg = ErrorOf([&] { ParseUrdfRobotSpec(small, "small.urdf", to_c); });
  EXPECT_EQ(msg,
            "small.urdf: links: the arm's lengths add up to 110 m, beyond 100 m: no arm is that "
            "long (the largest industrial arms reach about 4 m): millimetres? rcal files are in "
            "metres");
  // A prismatic travel of 500 mm.
  std::string slide = TinyUrdf("");
  slide.replace(slide.find("type=\"revolute\""), 15, "type=\"prismatic\"");
  slide.replace(slide.find("lower=\"-1\" upper=\"1\""), 20, "lower=\"0\" upper=\"500\"");
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(slide, "slide.urdf"); }),
            "slide.urdf: joint 'ab': <limit> beyond 100 m (lower 0, upper 500): millimetres? URDF "
            "prismatic limits are metres");
}

// Issue 13, item 4: a URDF's revolute limits beyond two turns and an origin's roll, pitch or yaw
// beyond a turn: in degrees, refused naming the unit and the value in radians, also below the
// old 100 rad bound (limits of ±90°; liburdfdom keeps only the rotation of rpy="0 0 90", so it was
// taken as 90 rad = 90 - 28π). Was: accepted, the arm calibrated, exit 0.
TEST(RobotUrdf, AnglesInDegreesAreRefusedNamingTheUnit) {
  std::string deg = TinyUrdf("");
  deg.replace(deg.find("lower=\"-1\" upper=\"1\""), 20, "lower=\"-170\" upper=\"170\"");
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(deg, "deg.urdf"); }),
            "deg.urdf: joint 'ab': <limit> (lower -170, upper 170) beyond two turns (4π rad): "
            "degrees? URDF angles are radians: 170° is 2.96706");
  deg = TinyUrdf("");
  deg.replace(deg.find("lower=\"-1\" upper=\"1\""), 20, "lower=\"-90\" upper=\"90\"");
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(deg, "deg.urdf"); }),
            "deg.urdf: joint 'ab': <limit> (lower -90, upper 90) beyond two turns (4π rad): "
            "degrees? URDF angles are radians: 90° is 1.5708");
  deg = TinyUrdf("");
  deg.replace(deg.find("rpy=\"0 0 0\""), 11, "rpy=\"0 0 90\"");
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(deg, "deg.urdf"); }),
            "deg.urdf: joint 'ab': origin rpy \"0 0 90\": 90 rad is beyond a turn (2π): degrees? "
            "URDF angles are radians: 90° is 1.5708");
  // A fixed joint of the chain too; one off the chain (a camera mount) is not rcal's to judge.
  deg = TinyUrdf(R"(<link name="cam"/>
  <joint name="cam_mount" type="fixed"><parent link="a"/><child link="cam"/>
    <origin xyz="0 0 0" rpy="0 0 90"/></joint>
)");
  UrdfOptions to_c;
  to_c.tip_link = "c";
  EXPECT_EQ(ParseUrdfRobotSpec(deg, "deg.urdf", to_c).links.size(), 2u);
  std::string fixed = TinyUrdf("");
  const size_t bc = fixed.find("<joint name=\"bc\"");
  fixed.replace(fixed.find("rpy=\"0 0 0\"", bc), 11, "rpy=\"-180 0 0\"");
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(fixed, "deg.urdf", to_c); }),
            "deg.urdf: joint 'bc': origin rpy \"-180 0 0\": -180 rad is beyond a turn (2π): "
            "degrees? URDF angles are radians: -180° is -3.14159");
  // Within: a 2π rounded to 6.2832, limits of two turns and of ±450°.
  std::string fine = TinyUrdf("");
  fine.replace(fine.find("rpy=\"0 0 0\""), 11, "rpy=\"0 0 6.2832\"");
  fine.replace(fine.find("lower=\"-1\" upper=\"1\""), 20,
               "lower=\"-12.566370614359172\" upper=\"7.853981633974483\"");
  const RobotSpec spec = ParseUrdfRobotSpec(fine, "fine.urdf");
  EXPECT_DOUBLE_EQ(spec.links[0].joint->lower, -4 * kPi);
}

// Every real arm rcal ships or is tested on loads: the test arms, the shipped robots and the
// FIGAROH UR10 (their lengths in metres, angles in radians, limits within two turns).
TEST(RobotUrdf, EveryRealArmLoads) {
  namespace fs = std::filesystem;
  std::vector<fs::path> files;
  for (const fs::path& dir :
       {testing::SourceDir() / "tests/data/arms", testing::SourceDir() / "config/robots"})
    for (const auto& e : fs::directory_iterator(dir))
      if (e.path().extension() == ".urdf" || e.path().extension() == ".yaml")
        files.push_back(e.path());
  for (const auto& e : fs::recursive_directory_iterator(testing::SharedDir() / "data"))
    if (e.path().filename() == "robot.urdf") files.push_back(e.path());
  ASSERT_GE(files.size(), 9u);
  for (const fs::path& f : files) {
    SCOPED_TRACE(f.string());
    const LoadedRobot r = LoadRobot(f);
    EXPECT_GE(r.model.num_joints(), 6);
    EXPECT_LT(ArmReach(r.model, false), 4.0);
  }
}

TEST(RobotUrdf, DeeplyNestedXmlIsRefusedBeforeTinyxmlRecursesIntoIt) {
  // tinyxml parses (and frees) one stack frame per nesting level: 300 000 levels overflowed it.
  std::string xml = "<robot name=\"deep\">";
  for (int i = 0; i < 300000; ++i) xml += "<a>";
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(xml, "deep.urdf"); }),
            "deep.urdf: XML elements nest deeper than 100 levels (line 1)");
  // Quoted '>' , comments, CDATA and empty elements do not count as nesting.
  std::string fine = "<robot name=\"x\">";
  for (int i = 0; i < 500; ++i) fine += "<!-- <a> --><b/><c d=\"<e>\"/><![CDATA[<f>]]>";
  fine += "</robot>";
  EXPECT_NE(ErrorOf([&] { ParseUrdfRobotSpec(fine, "fine.urdf"); }).find("not a valid URDF"),
            std::string::npos);
}

TEST(RobotUrdf, AbsurdOriginsAndLimitsAreRefusedNamingTheJoint) {
  std::string far = TinyUrdf("");
  far.replace(far.find("xyz=\"0 0 0.1\""), 13, "xyz=\"0 0 1e6\"");
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(far, "far.urdf"); }),
            "far.urdf: joint 'ab': origin xyz beyond 100 m: not an arm's dimension");
  std::string wide = TinyUrdf("");
  wide.replace(wide.find("upper=\"1\""), 9, "upper=\"1e6\"");
  EXPECT_EQ(ErrorOf([&] { ParseUrdfRobotSpec(wide, "wide.urdf"); }),
            "wide.urdf: joint 'ab': <limit> (lower -1, upper 1e+06) beyond two turns (4π rad)");
}

TEST(RobotUrdf, ContinuousAndPrismaticJoints) {
  std::string xml = TinyUrdf("");
  xml.replace(xml.find("type=\"revolute\""), 15, "type=\"continuous\"");
  RobotSpec spec = ParseUrdfRobotSpec(xml, "c.urdf");
  ASSERT_TRUE(spec.links[0].joint.has_value());
  EXPECT_DOUBLE_EQ(spec.links[0].joint->lower, -kPi);
  EXPECT_DOUBLE_EQ(spec.links[0].joint->upper, kPi);
  xml = TinyUrdf("");
  xml.replace(xml.find("type=\"revolute\""), 15, "type=\"prismatic\"");
  UrdfOptions o;
  o.tip_link = "c";
  const KinematicModel m = BuildModel(ParseUrdfRobotSpec(xml, "p.urdf", o));
  Eigen::VectorXd q(1);
  q << 0.25;
  EXPECT_LT((m.ToolFrame(q, m.Nominal()).translation() - Eigen::Vector3d(0.2, 0, 0.35)).norm(),
            1e-15);
}

TEST(RobotUrdf, LoadRobotDispatchesOnTheExtension) {
  const LoadedRobot urdf = LoadRobot(Ur10Urdf());
  EXPECT_TRUE(urdf.from_urdf);
  EXPECT_EQ(urdf.model.num_joints(), 6);
  const LoadedRobot yaml = LoadRobot(testing::SourceDir() / "config/robots/grb3016.yaml");
  EXPECT_FALSE(yaml.from_urdf);
  EXPECT_EQ(yaml.model.num_params(), 28);
  EXPECT_NE(ErrorOf([&] { LoadRobot("robot.txt"); }).find("unknown robot file type"),
            std::string::npos);
}

// The arm test matrix's GRB3016 (tests/data/arms/grb3016.urdf, hand-written) is the arm of
// config/robots/grb3016.yaml: the same tool frame at random joints and the same joint limits. The
// YAML model chains standard D–H ETs (Rz Tz Tx Rx per link, then the D–H tool), the URDF model
// its joints' origins and rotations: two independent layouts of one arm.
TEST(RobotUrdf, TheMatrixGrb3016IsTheArmOfTheYamlModel) {
  UrdfOptions o;
  o.tip_link = "tool0";
  const LoadedRobot urdf = LoadRobot(testing::SourceDir() / "tests/data/arms/grb3016.urdf", o);
  const LoadedRobot yaml = LoadRobot(testing::SourceDir() / "config/robots/grb3016.yaml");
  ASSERT_EQ(urdf.model.num_joints(), 6);
  ASSERT_EQ(yaml.model.num_joints(), 6);
  for (int j = 0; j < 6; ++j) {
    EXPECT_EQ(urdf.model.joints()[j].name, yaml.model.joints()[j].name);
    EXPECT_NEAR(urdf.model.joints()[j].lower, yaml.model.joints()[j].lower, 1e-15) << j;
    EXPECT_NEAR(urdf.model.joints()[j].upper, yaml.model.joints()[j].upper, 1e-15) << j;
  }
  std::mt19937 rng(12);
  std::vector<Eigen::VectorXd> qs{Eigen::VectorXd::Zero(6)};
  for (int k = 0; k < 200; ++k) qs.push_back(kinematics::testing::RandomJoints(yaml.model, rng));
  for (const auto& q : qs) {
    const Eigen::Isometry3d a = urdf.model.ToolFrame(q, urdf.model.Nominal());
    const Eigen::Isometry3d b = yaml.model.ToolFrame(q, yaml.model.Nominal());
    EXPECT_LT((a.translation() - b.translation()).norm(), 1e-12) << q.transpose();
    EXPECT_LT((a.linear() - b.linear()).norm(), 1e-12) << q.transpose();
  }
}

// Every arm of the test matrix loads with the default tip detection, ends at the link its comment
// names, and its model's tool frame is the URDF's origins chained by hand.
TEST(RobotUrdf, EveryMatrixArmLoadsWithItsDefaultTip) {
  const std::vector<std::tuple<std::string, std::string, std::string, int>> arms = {
      {"grb3016", "base_link", "link_6", 6},
      {"kr6_like", "base_link", "link_6", 6},
      {"ur5e_like", "base_link", "wrist_3_link", 6},
      {"panda_like", "link0", "link7", 7},
      {"irb120_like", "base_link", "link_6", 6}};
  for (const auto& [name, base, tip, joints] : arms) {
    const auto path = testing::SourceDir() / "tests/data/arms" / (name + ".urdf");
    const LoadedRobot r = LoadRobot(path);
    ASSERT_EQ(r.model.num_joints(), joints) << name;
    EXPECT_EQ(r.model.name(), name);
    const std::string xml = ReadFile(path);
    std::mt19937 rng(13);
    for (int k = 0; k < 20; ++k) {
      const Eigen::VectorXd q = kinematics::testing::RandomJoints(r.model, rng);
      EXPECT_LT(FrameDifference(r.model.ToolFrame(q, r.model.Nominal()),
                                ChainByHand(xml, base, tip, ByName(r.model, q))),
                1e-12)
          << name;
    }
  }
}

TEST(RobotUrdf, UrdfRobotSavesAsYamlAndLoadsCalibrated) {
  ScratchDir dir;
  UrdfOptions o;
  o.add_base_frame = true;
  o.add_marker = true;
  const LoadedRobot r = LoadRobot(Ur10Urdf(), o);
  std::mt19937 rng(15);
  const Eigen::VectorXd x = kinematics::testing::RandomErrors(r.model, rng);
  SaveCalibratedRobotYaml(dir / "ur10.yaml", r.spec, r.model, x);
  const KinematicModel cal = LoadRobotYaml(dir / "ur10.yaml");
  for (int k = 0; k < 20; ++k) {
    const Eigen::VectorXd q = kinematics::testing::RandomJoints(r.model, rng);
    EXPECT_LT((cal.Forward(q, cal.Nominal()).p_WM_W - r.model.Forward(q, x).p_WM_W).norm(), 1e-12);
    EXPECT_LT(FrameDifference(cal.ToolFrame(q, cal.Nominal()), r.model.ToolFrame(q, x)), 1e-12);
  }
}

}  // namespace
}  // namespace rcal::io
