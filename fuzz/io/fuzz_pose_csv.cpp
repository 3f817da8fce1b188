// Pose dataset CSV (io/pose_dataset.hpp), both layouts, then the plausibility check against a
// 6-joint arm and the text round trip.
#include <cstdint>

#include "fuzz_common.hpp"
#include "rcal/io/pose_dataset.hpp"
#include "rcal/io/robot_yaml.hpp"

namespace {

const rcal::kinematics::KinematicModel& Arm() {
  // The GRB3016 of config/robots/grb3016.yaml (limits and lengths matter, not exact values).
  static const rcal::kinematics::KinematicModel model =
      rcal::io::BuildModel(rcal::io::ParseRobotYaml(
          R"(schema: rcal.robot/1
name: arm
convention: dh
base: {xyz: [0, 0, 0], rpy: [0, 0, 0]}
links:
  - {a: 0.150, alpha: -pi/2, d: 0.250, theta: 0, joint: {name: j1, type: revolute, lower: -17*pi/18, upper: 17*pi/18}}
  - {a: 0.570, alpha: -pi, d: 0, theta: -pi/2, joint: {name: j2, type: revolute, lower: -pi/2, upper: 5*pi/6}}
  - {a: 0.150, alpha: pi/2, d: 0, theta: 0, joint: {name: j3, type: revolute, lower: -17*pi/18, upper: 4*pi/9}}
  - {a: 0, alpha: -pi/2, d: 0.645, theta: 0, joint: {name: j4, type: revolute, lower: -pi, upper: pi}}
  - {a: 0, alpha: pi/2, d: 0, theta: 0, joint: {name: j5, type: revolute, lower: -2*pi/3, upper: 2*pi/3}}
  - {a: 0, alpha: 0, d: 0.095, theta: 0, joint: {name: j6, type: prismatic, lower: -0.1, upper: 0.1}}
marker: {xyz: [0, 0, 0.1]}
)",
          "arm.yaml"));
  return model;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text = rcal::fuzz::Text(data, size);
  rcal::fuzz::Refusing([&] {
    const rcal::io::PoseDataset d = rcal::io::ParsePoseDataset(text, "fuzz.csv");
    if (d.num_joints == 6) rcal::io::CheckPosesPlausible(d, Arm(), "fuzz.csv");
    if (!d.samples.empty()) (void)rcal::io::ParsePoseDataset(rcal::io::PoseDatasetText(d), "again");
  });
  rcal::fuzz::Refusing([&] { (void)rcal::io::ParsePoseDataset(text, "fuzz.csv", 6); });
  return 0;
}
