// services/dds_bridge/setup_frames: the calibrated set-up frames as tf2 transforms. Checked against
// the model itself: chaining the published transforms with the arm's forward kinematics gives the
// model's marker position, at random joints and parameter errors.
#include "rcal/dds/setup_frames.hpp"

#include <gtest/gtest.h>

#include <random>

#include "rcal/geometry/so3.hpp"
#include "rcal/io/cell_yaml.hpp"

namespace rcal::dds {
namespace {

const NamedTransform* Find(const std::vector<NamedTransform>& ts, const std::string& child) {
  for (const auto& t : ts)
    if (t.child == child) return &t;
  return nullptr;
}

Eigen::Isometry3d Iso(const NamedTransform& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = t.q_PC.toRotationMatrix();
  T.translation() = t.p_PC_P;
  return T;
}

TEST(SetupFrames, ChainedWithTheArmTheyGiveTheModelsMarkerAndImu) {
  const io::BuiltCell cell = io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml");
  const auto& model = cell.model;
  std::mt19937_64 rng(11);
  std::normal_distribution<double> g;
  for (int trial = 0; trial < 20; ++trial) {
    Eigen::VectorXd x(model.num_params());
    for (int i = 0; i < x.size(); ++i)
      x(i) = (model.parameters()[i].is_angle ? 0.01 : 0.005) * g(rng);
    const io::RobotSpec cal = io::CalibratedSpec(cell.robot_spec, model, x);
    const auto ts = SetupTransforms(cal, "rcal_");
    ASSERT_EQ(ts.size(), 4u);  // base, earth, marker, imu
    const NamedTransform* base = Find(ts, "base");
    const NamedTransform* earth = Find(ts, "rcal_earth");
    const NamedTransform* marker = Find(ts, "rcal_marker");
    const NamedTransform* imu = Find(ts, "rcal_imu");
    ASSERT_TRUE(base && earth && marker && imu);
    EXPECT_EQ(base->parent, "rcal_world");
    EXPECT_EQ(earth->parent, "rcal_world");
    EXPECT_EQ(marker->parent, "flange");
    EXPECT_EQ(imu->parent, "flange");
    // The arm alone (base at identity, no tool set-up): the calibrated spec without set-up frames.
    io::RobotSpec arm = cal;
    arm.base.reset();
    arm.markers.clear();
    arm.imu.reset();
    arm.earth.reset();
    const kinematics::KinematicModel arm_model = io::BuildModel(arm);
    Eigen::VectorXd q(model.num_joints());
    for (int j = 0; j < q.size(); ++j) q(j) = 0.8 * g(rng);
    const Eigen::Isometry3d T_BF = arm_model.ToolFrame(q, arm_model.Nominal());
    const kinematics::ToolPose truth = model.Forward(q, x);
    const Eigen::Vector3d p_WM_W = Iso(*base) * T_BF * marker->p_PC_P;
    EXPECT_LT((p_WM_W - truth.p_WM_W).norm(), 1e-9) << "trial " << trial;
    // R_EI = R_EW · R_WB · R_BF · R_FI.
    const Eigen::Matrix3d R_EI = earth->q_PC.toRotationMatrix().transpose() *
                                 base->q_PC.toRotationMatrix() * T_BF.linear() *
                                 imu->q_PC.toRotationMatrix();
    EXPECT_LT((R_EI - truth.R_EI).norm(), 1e-9) << "trial " << trial;
  }
}

TEST(SetupFrames, ThePrefixNamesRcalsFramesAndSeveralMarkersAreNumbered) {
  io::RobotSpec spec;
  spec.base_link = "base_link";
  spec.tip_link = "tool0";
  spec.markers = {{0, {0.1, 0, 0}, true}, {3, {0, 0.1, 0}, true}};
  const auto ts = SetupTransforms(spec, "cell7_");
  ASSERT_EQ(ts.size(), 2u);
  EXPECT_EQ(ts[0].child, "cell7_marker");
  EXPECT_EQ(ts[1].child, "cell7_marker_3");
  EXPECT_EQ(ts[1].parent, "tool0");
  EXPECT_EQ(ts[1].p_PC_P, Eigen::Vector3d(0, 0.1, 0));
}

}  // namespace
}  // namespace rcal::dds
