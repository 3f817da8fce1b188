#include "robot_setup.hpp"

#include <spdlog/spdlog.h>

#include <stdexcept>

#include "command.hpp"
#include "pose_log.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "rcal/transport/channels.hpp"

namespace rcal::tool {

io::LoadedRobot LoadRobotForCell(const std::string& robot_path, const std::string& tip_link,
                                 const std::string& base_link, const std::string& frames) {
  const bool add = frames == "auto";
  if (!add && frames != "none") throw std::runtime_error("--frames: auto or none");
  io::UrdfOptions uo;
  uo.tip_link = tip_link;
  uo.base_link = base_link;
  uo.add_base_frame = add;
  uo.add_marker = add;
  io::LoadedRobot robot = io::LoadRobot(ResolvePath(robot_path), uo);
  if (add) {
    if (!robot.from_urdf) {
      if (!robot.spec.base) robot.spec.base = io::FrameSpec{};
      if (!robot.spec.marker && !robot.spec.tool) robot.spec.marker = io::FrameSpec{};
    }
    robot.model = io::BuildModel(robot.spec);
  }
  return robot;
}

void AddOrientationFrame(io::LoadedRobot& robot, bool earth_frame) {
  const bool add_imu = !robot.spec.imu, add_earth = earth_frame && !robot.spec.earth;
  if (!add_imu && !add_earth) return;
  if (add_imu) robot.spec.imu = io::FrameSpec{};
  if (add_earth) robot.spec.earth = io::FrameSpec{};
  robot.model = io::BuildModel(robot.spec);
}

io::PoseDataset LoadPoseDataFor(const io::LoadedRobot& robot, const std::string& data_path,
                                const std::string& command, bool allow_gaps) {
  std::vector<std::string> joint_names;
  for (const auto& j : robot.model.joints()) joint_names.push_back(j.name);
  const std::string path = ResolvePath(data_path);
  io::PoseDataset data;
  if (IsLcmLog(path)) {
    // A log of the pipeline: its POSE_MEASUREMENT events, checked as ekf_identifier checks them.
    const PoseLog log = ReadPoseLog(path, robot.model, transport::channels::kPoseMeasurement);
    CheckLogGaps(data_path, log.log, allow_gaps);
    if (log.skipped > 0)
      spdlog::warn("{}: {} of {} {} events skipped (first: {})", data_path, log.skipped, log.events,
                   transport::channels::kPoseMeasurement, log.first_skip_reason);
    data = ToPoseDataset(log, robot.model.num_joints());
  } else {
    data = io::LoadPoseDataset(path, robot.model.num_joints(), joint_names);
  }
  if (data.samples.empty()) throw std::runtime_error(data_path + ": no poses");
  // Poses this robot cannot have produced (joints far beyond their limits, a marker beyond the
  // arm's reach) would be fitted as if true: refused, naming the row and the column.
  io::CheckPosesPlausible(data, robot.model, data_path);
  for (const auto& s : data.samples)
    if (s.marker != 0)
      throw std::runtime_error(data_path +
                               ": column 'marker': several markers per tool are not supported by " +
                               command + " yet (found id " + std::to_string(s.marker) + ")");
  return data;
}

std::vector<kinematics::PoseMeasurement> ToMeasurements(const io::PoseDataset& data) {
  std::vector<kinematics::PoseMeasurement> ms;
  for (const auto& s : data.samples) {
    kinematics::PoseMeasurement m;
    m.q = s.q;
    m.p_WM_W = s.p_WM_W;
    m.has_orientation = data.has_orientation;
    if (m.has_orientation) m.R_EI = geometry::QuatToMatrix(s.q_EI_wxyz);
    ms.push_back(m);
  }
  return ms;
}

}  // namespace rcal::tool
