#include "robot_setup.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <set>
#include <sstream>
#include <stdexcept>

#include "command.hpp"
#include "pose_log.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/io/calibration_export.hpp"
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
      if (robot.spec.markers.empty() && !robot.spec.tool) robot.spec.markers.push_back({});
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
                                bool allow_gaps) {
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
  return data;
}

void SetUpMarkers(io::LoadedRobot& robot, const io::PoseDataset& data,
                  const std::map<int, Eigen::Vector3d>& known, bool add) {
  std::set<int> ids;
  for (const auto& s : data.samples) ids.insert(s.marker);
  for (const auto& [id, p_FM] : known) ids.insert(id);
  // Each marker adds three parameters; a column of row numbers or timestamps is not markers.
  constexpr size_t kMaxMarkers = 100;
  if (ids.size() > kMaxMarkers)
    throw std::runtime_error("column 'marker': " + std::to_string(ids.size()) +
                             " distinct ids; rcal fits at most " + std::to_string(kMaxMarkers) +
                             " markers on one tool");
  if (robot.spec.tool && !(ids.size() == 1 && *ids.begin() == 0))
    throw std::runtime_error(
        "column 'marker': the robot ends in a D–H tool, which is the one "
        "measured point; several markers need a robot without tool:");
  if (robot.spec.tool) return;
  std::vector<io::MarkerSpec>& markers = robot.spec.markers;
  // A chain that ends at the measured point itself (a robot file without marker): one point.
  if (markers.empty() && ids.size() == 1 && *ids.begin() == 0 && known.empty()) return;
  bool changed = false;
  for (int id : ids) {
    auto it = std::find_if(markers.begin(), markers.end(),
                           [&](const io::MarkerSpec& m) { return m.id == id; });
    if (it == markers.end()) {
      // A URDF chain or a YAML robot given frames "auto" has marker 0 with an unknown offset; a
      // dataset without id 0 does not measure it.
      if (!add)
        throw std::runtime_error("column 'marker': id " + std::to_string(id) +
                                 " is not a marker of robot '" + robot.spec.name +
                                 "' (--frames none); add it under markers: in the robot file");
      markers.push_back({id, Eigen::Vector3d::Zero(), true});
      it = markers.end() - 1;
      changed = true;
    }
    if (const auto k = known.find(id); k != known.end()) {
      it->xyz = k->second;
      it->identify = false;
      changed = true;
    }
  }
  // Markers the data never measures would be parameters nothing sees.
  const auto unseen = std::remove_if(markers.begin(), markers.end(),
                                     [&](const io::MarkerSpec& m) { return !ids.count(m.id); });
  changed |= unseen != markers.end();
  markers.erase(unseen, markers.end());
  if (changed) robot.model = io::BuildModel(robot.spec);
}

std::vector<kinematics::PoseMeasurement> ToMeasurements(const io::PoseDataset& data,
                                                        const kinematics::KinematicModel& model) {
  std::vector<kinematics::PoseMeasurement> ms;
  for (size_t i = 0; i < data.samples.size(); ++i) {
    const io::PoseSample& s = data.samples[i];
    kinematics::PoseMeasurement m;
    m.q = s.q;
    m.p_WM_W = s.p_WM_W;
    if (!model.markers().empty() || s.marker != 0) {
      m.marker = model.MarkerSlot(s.marker);
      if (m.marker < 0)
        throw std::runtime_error("row " + std::to_string(s.row > 0 ? s.row : int(i) + 1) +
                                 ": marker " + std::to_string(s.marker) + " is not a marker of '" +
                                 model.name() + "'");
    }
    m.has_orientation = data.has_orientation;
    if (m.has_orientation) m.R_EI = geometry::QuatToMatrix(s.q_EI_wxyz);
    ms.push_back(m);
  }
  return ms;
}

namespace {

double ParseNumber(const std::string& text, const std::string& what) {
  double v = 0;
  const char* first = text.data();
  const char* last = text.data() + text.size();
  if (first != last && *first == '+') ++first;
  const auto [end, ec] = std::from_chars(first, last, v);
  if (text.empty() || ec != std::errc() || end != last || !std::isfinite(v))
    throw std::runtime_error(what + ": '" + text + "' is not a number");
  return v;
}

// "ID=VALUE": the id and the value text.
std::pair<int, std::string> SplitId(const std::string& value, const std::string& option) {
  const size_t eq = value.find('=');
  const std::string id = value.substr(0, eq == std::string::npos ? 0 : eq);
  int v = -1;
  const auto [end, ec] = std::from_chars(id.data(), id.data() + id.size(), v);
  if (eq == std::string::npos || id.empty() || ec != std::errc() || end != id.data() + id.size() ||
      v < 0)
    throw std::runtime_error(option + " '" + value + "': expected MARKER_ID=...");
  return {v, value.substr(eq + 1)};
}

}  // namespace

std::map<int, Eigen::Vector3d> ParseMarkerOffsets(const std::vector<std::string>& values,
                                                  const std::string& option) {
  std::map<int, Eigen::Vector3d> out;
  for (const std::string& value : values) {
    const auto [id, rest] = SplitId(value, option);
    std::vector<double> xyz;
    std::stringstream ss(rest);
    for (std::string part; std::getline(ss, part, ',');)
      xyz.push_back(ParseNumber(part, option + " '" + value + "'"));
    if (xyz.size() != 3)
      throw std::runtime_error(option + " '" + value + "': expected ID=x,y,z [m]");
    for (double c : xyz)
      if (std::abs(c) > 10.0)
        throw std::runtime_error(option + " '" + value +
                                 "': beyond 10 m from the flange (the offset is in metres)");
    if (!out.emplace(id, Eigen::Vector3d(xyz[0], xyz[1], xyz[2])).second)
      throw std::runtime_error(option + ": marker " + std::to_string(id) + " given twice");
  }
  return out;
}

std::map<int, int> ParseMarkerRows(const std::vector<std::string>& values,
                                   const std::string& option) {
  std::map<int, int> out;
  for (const std::string& value : values) {
    const auto [id, rest] = SplitId(value, option);
    const double row = ParseNumber(rest, option + " '" + value + "'");
    if (row < 1 || row != std::floor(row) || row > 1e9)
      throw std::runtime_error(option + " '" + value + "': expected ID=ROW, a data row ≥ 1");
    if (!out.emplace(id, static_cast<int>(row)).second)
      throw std::runtime_error(option + ": marker " + std::to_string(id) + " given twice");
  }
  return out;
}

std::string ChainText(const io::LoadedRobot& robot) {
  std::string joints;
  for (const auto& j : robot.model.joints()) joints += (joints.empty() ? "" : ", ") + j.name;
  return robot.spec.base_link + " → " + robot.spec.tip_link + " (" +
         std::to_string(robot.model.num_joints()) + " joints: " + joints + ")";
}

std::string ParameterFrame(const io::LoadedRobot& robot, int index) {
  return io::ParameterFrameText(robot.spec, robot.model, index);
}

}  // namespace rcal::tool
