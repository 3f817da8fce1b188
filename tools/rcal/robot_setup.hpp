// Robots and pose data as the data-driven commands (calibrate, analyze, simulate) load them.
#pragma once

#include <string>
#include <vector>

#include "rcal/io/pose_dataset.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/kinematics/measurement.hpp"

namespace rcal::tool {

/// A robot for a measured cell. `frames` is "auto" (a URDF chain gets a world ← base frame and a
/// marker offset; a YAML robot gets whichever of the two it lacks) or "none" (the file as it is).
/// Throws std::runtime_error naming the option or the file at fault.
io::LoadedRobot LoadRobotForCell(const std::string& robot_path, const std::string& tip_link,
                                 const std::string& base_link, const std::string& frames);

/// Adds the flange → IMU (measured marker) rotation when the robot lacks one: data with
/// orientation measure it. With `earth_frame` also the earth ← world rotation: orientation from
/// an IMU (the pipeline's POSE_MEASUREMENT) is in the IMU's own earth frame (gravity and magnetic
/// north), not in the position sensor's frame.
void AddOrientationFrame(io::LoadedRobot& robot, bool earth_frame = false);

/// The pose dataset at `data_path` with the joint columns named after `robot`'s joints (FIGAROH
/// layout) and its joint count checked. Refuses an empty file, and several markers per tool,
/// which `command` does not support yet. An LCM log's read summary is printed; a log that lost
/// data (broken frames, undecodable events) is refused unless `allow_gaps` (CheckLogGaps).
io::PoseDataset LoadPoseDataFor(const io::LoadedRobot& robot, const std::string& data_path,
                                const std::string& command, bool allow_gaps = false);

/// The measurements of a dataset (covariances left empty: set them with
/// identification::SetNoise).
std::vector<kinematics::PoseMeasurement> ToMeasurements(const io::PoseDataset& data);

}  // namespace rcal::tool
