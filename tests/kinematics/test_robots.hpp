// Robots built directly from their published tables, independent of the YAML/URDF loaders.
#pragma once

#include <numbers>
#include <random>

#include "rcal/kinematics/model.hpp"

namespace rcal::kinematics::testing {

constexpr double kPi = std::numbers::pi;

inline Joint Rev(const std::string& name, double lim = kPi) {
  return {name, JointType::kRevolute, -lim, lim};
}

/// GRB3016, Table 1 of the paper as read in NOTES.md (mm → m), standard D–H, plus the paper's
/// 4-parameter D–H tool transform.
inline KinematicModel Grb3016(double tool_a = 0.010, double tool_alpha = 0.1, double tool_d = 0.050,
                              double tool_theta = 0.2) {
  ModelBuilder b("grb3016");
  b.DhLink(0.150, -kPi / 2, 0.250, 0.0, Rev("j1"))
      .DhLink(0.570, -kPi, 0.0, -kPi / 2, Rev("j2"))
      .DhLink(0.150, kPi / 2, 0.0, 0.0, Rev("j3"))
      .DhLink(0.0, -kPi / 2, 0.645, 0.0, Rev("j4"))
      .DhLink(0.0, kPi / 2, 0.0, -kPi / 2, Rev("j5"))
      .DhLink(0.0, 0.0, -0.200, 0.0, Rev("j6"))
      .ToolDh(tool_a, tool_alpha, tool_d, tool_theta);
  return b.Build();
}

/// A 7-joint arm (Panda-like, modified D–H) with base, marker, IMU and earth frames.
/// The 7 links of a Panda-like arm (modified D–H), appended to `b`.
inline ModelBuilder& SevenJointLinks(ModelBuilder& b) {
  return b.ModifiedDhLink(0.0, 0.0, 0.333, 0.0, Rev("j1", 2.8))
      .ModifiedDhLink(0.0, -kPi / 2, 0.0, 0.0, Rev("j2", 1.7))
      .ModifiedDhLink(0.0, kPi / 2, 0.316, 0.0, Rev("j3", 2.8))
      .ModifiedDhLink(0.0825, kPi / 2, 0.0, 0.0, Rev("j4", 3.0))
      .ModifiedDhLink(-0.0825, -kPi / 2, 0.384, 0.0, Rev("j5", 2.8))
      .ModifiedDhLink(0.0, kPi / 2, 0.0, 0.0, Rev("j6", 3.7))
      .ModifiedDhLink(0.088, kPi / 2, 0.107, 0.0, Rev("j7", 2.8));
}

inline KinematicModel SevenJointSetup() {
  ModelBuilder b("seven");
  b.BaseFrame({0.5, -0.2, 0.1}, {0.01, -0.02, 0.3});
  SevenJointLinks(b)
      .MarkerOffset({0.02, -0.01, 0.10})
      .ImuMounting({0.1, -0.05, 0.7})
      .EarthFrame({0.02, 0.03, 1.2});
  return b.Build();
}

/// A UR-like arm's base frame and six joints in URDF form (joint origins + axes, 6-parameter
/// joint errors), appended to `b`: the chain ends at the flange.
inline ModelBuilder& UrLikeChain(ModelBuilder& b) {
  return b.BaseFrame({0.1, 0.2, 0.0}, {0.0, 0.0, 0.5})
      .UrdfJoint({0, 0, 0.1273}, {0, 0, 0}, {0, 0, 1}, Rev("shoulder_pan"))
      .UrdfJoint({0, 0.220941, 0}, {0, kPi / 2, 0}, {0, 1, 0}, Rev("shoulder_lift"))
      .UrdfJoint({0, -0.1719, 0.612}, {0, 0, 0}, {0, 1, 0}, Rev("elbow"))
      .UrdfJoint({0, 0, 0.5723}, {0, kPi / 2, 0}, {0, 1, 0}, Rev("wrist_1"))
      .UrdfJoint({0, 0.1149, 0}, {0, 0, 0}, {0, 0, 1}, Rev("wrist_2"))
      .UrdfJoint({0, 0, 0.1157}, {0, 0, 0}, {0, 1, 0}, Rev("wrist_3"));
}

/// A UR-like arm in URDF form with a marker.
inline KinematicModel UrLikeUrdf() {
  ModelBuilder b("ur_like");
  UrLikeChain(b).MarkerOffset({0.0, 0.15, 0.05});
  return b.Build();
}

/// UrLikeUrdf with three reflectors on the tool (marker ids 0, 2 and 5, as a laser tracker
/// measures them) and an IMU.
inline KinematicModel UrLikeThreeMarkers() {
  ModelBuilder b("ur_like_3");
  UrLikeChain(b)
      .MarkerOffset({0.0, 0.15, 0.05})
      .MarkerOffset({0.08, -0.02, 0.10}, true, 2)
      .MarkerOffset({-0.06, 0.04, 0.12}, true, 5)
      .ImuMounting({0.2, -0.1, 0.4});
  return b.Build();
}

inline Eigen::VectorXd RandomJoints(const KinematicModel& m, std::mt19937& rng) {
  Eigen::VectorXd q(m.num_joints());
  for (int j = 0; j < m.num_joints(); ++j) {
    std::uniform_real_distribution<double> u(m.joints()[j].lower, m.joints()[j].upper);
    q(j) = u(rng);
  }
  return q;
}

inline Eigen::VectorXd RandomErrors(const KinematicModel& m, std::mt19937& rng,
                                    double sigma_length = 0.003, double sigma_angle = 0.01) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::VectorXd x(m.num_params());
  for (int i = 0; i < m.num_params(); ++i)
    x(i) = n(rng) * (m.parameters()[i].is_angle ? sigma_angle : sigma_length);
  return x;
}

}  // namespace rcal::kinematics::testing
