// Robots and pose data as the data-driven commands (calibrate, analyze, simulate) load them.
#pragma once

#include <Eigen/Core>
#include <map>
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
/// layout) and its joint count checked. Refuses an empty file. An LCM log's read summary is
/// printed; a log that lost data (broken frames, undecodable events) is refused unless
/// `allow_gaps` (CheckLogGaps).
io::PoseDataset LoadPoseDataFor(const io::LoadedRobot& robot, const std::string& data_path,
                                bool allow_gaps = false);

/// Gives the robot a flange → marker offset for every marker id `data` measures (its `marker`
/// column; several reflectors on the tool). With `add` (--frames auto) an id the robot lacks gets
/// an unknown offset, identified from 0; without, such an id is an error naming it. `known` fixes
/// ids at given offsets p_FM [m, tip-link frame] (not identified), replacing the file's. Throws
/// std::runtime_error naming the marker id.
void SetUpMarkers(io::LoadedRobot& robot, const io::PoseDataset& data,
                  const std::map<int, Eigen::Vector3d>& known, bool add);

/// The measurements of a dataset (covariances left empty: set them with
/// identification::SetNoise); each sample's marker id becomes the model's slot for it. Throws
/// std::runtime_error naming the row when `model` has no marker of that id.
std::vector<kinematics::PoseMeasurement> ToMeasurements(const io::PoseDataset& data,
                                                        const kinematics::KinematicModel& model);

/// Parses ID=x,y,z (a known marker offset [m]) and ID=N (a data row) option values. Throws
/// std::runtime_error naming `option` and the value.
std::map<int, Eigen::Vector3d> ParseMarkerOffsets(const std::vector<std::string>& values,
                                                  const std::string& option);
std::map<int, int> ParseMarkerRows(const std::vector<std::string>& values,
                                   const std::string& option);

/// "base_link → tip_link (N joints: j1, j2, …)": the chain a robot's model runs along.
std::string ChainText(const io::LoadedRobot& robot);

/// The frame a parameter's value is expressed in, in words: "world ← base_link (T_WB)",
/// "tip_link → marker 2 (p_FM, tip_link frame)", "joint origin of elbow (parent link frame)".
/// `index` is the parameter's index in robot.model.
std::string ParameterFrame(const io::LoadedRobot& robot, int index);

}  // namespace rcal::tool
