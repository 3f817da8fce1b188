// The calibrated set-up frames of a cell as tf2 transforms (what dds_bridge publishes on
// rt/tf_static), so rviz2 and tf2_echo show where rcal found the tracker, the marker and the IMU.
//
// From io::CalibratedSpec(spec, model, x), parent → child (the child's pose in the parent):
//   <p>world → <base_link>     T_WB, the robot base in the position sensor's frame
//   <p>world → <p>earth        R_WE = R_EWᵀ, the IMU's earth frame (NED/ENU, magnetic north)
//   <tip_link> → <p>marker[_ID] p_FM, each marker (id 0: <p>marker): the corrected tool point,
//                              the frame the IK corrector places
//   <tip_link> → <p>imu        R_FI, the IMU's mounting
// <p> is the cell's ros2.frame_prefix (default rcal_); base_link and tip_link are the chain's own
// link names (a URDF's, so the tree joins robot_state_publisher's; "base" and "flange" for a YAML
// robot; its flange is the frame after the D–H tool, where p_FM starts). Frames the cell does not
// have are left out.
#pragma once

#include <string>
#include <vector>

#include "rcal/dds/ros2_convert.hpp"
#include "rcal/io/robot_yaml.hpp"

namespace rcal::dds {

/// The set-up frames of `calibrated` (io::CalibratedSpec) as named transforms (file comment).
std::vector<NamedTransform> SetupTransforms(const io::RobotSpec& calibrated,
                                            const std::string& prefix);

}  // namespace rcal::dds
