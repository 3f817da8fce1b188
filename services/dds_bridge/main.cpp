// dds_bridge: rcal's calibration results on DDS, for ROS 2 and for other machines.
//
// Subscribes on LCM: KINEMATIC_PARAMS, CALIBRATION_STATUS, TOOL_POSITION and ORIENTATION.
// Publishes on DDS (Cyclone DDS, ROS 2 conventions, types from idl/rcal_msgs.idl):
//   rt/rcal/kinematic_params    rcal_msgs::msg::dds_::KinematicParams_    reliable,
//   transient-local, rt/rcal/calibration_status  rcal_msgs::msg::dds_::CalibrationStatus_ keep-last
//   1 rt/rcal/tool_pose           rcal_msgs::msg::dds_::ToolPose_           best-effort
// every message naming the robot (--robot-id). A ToolPose_ is published for every TOOL_POSITION,
// with the latest ORIENTATION received before it. HEALTH at 1 Hz of sensor time (and once at
// start, with utime 0, when the LCM subscriptions are in place).
//
// With --cell, also in the ROS 2 standard types, so stock tools (rviz2, tf2_echo, rqt_runtime_
// monitor, robot_state_publisher's consumers) show rcal's results with no rcal package:
//   rt/tf_static           tf2_msgs/TFMessage      the calibrated set-up frames (setup_frames.hpp),
//                                                  reliable, transient-local, depth 1: re-sent
//                                                  whole with every new KINEMATIC_PARAMS
//   rt/robot_description   std_msgs/String         the calibrated URDF (io::RobotDescriptionUrdf: a
//                                                  URDF robot's own file with its joint origins
//                                                  corrected, a YAML robot's written from its
//                                                  model; set-up frames as fixed joints; the
//                                                  calibration hash in a comment), transient-local
//   rt/diagnostics         diagnostic_msgs/DiagnosticArray   every process's HEALTH (level OK,
//                                                  WARN when it rejected or lost something since
//                                                  its previous HEALTH, ERROR on a filter reset)
//                                                  and the drivers' clock offsets (CLOCK_OFFSET)
//   rt/rcal/tool_pose_with_covariance  geometry_msgs/PoseWithCovarianceStamped  the marker's
//                                                  position and the IMU's orientation in the world
//                                                  (the position sensor's frame), best effort
// The tool pose (rt/rcal/tool_pose and its ROS 2 twin) comes from TOOL_POSITION and ORIENTATION
// (position_kf, orientation_kf), or with --tool-pose-from ins from INS_TOOL_POSITION and
// INS_ORIENTATION (aided_ins, the tracker-aided INS: the same message types, the same frames).
//
// Cyclone binds to loopback only (config/cyclonedds-loopback.xml) unless CYCLONEDDS_URI is set,
// e.g. to config/cyclonedds-network.xml. Bad input (fails to decode, NaN, sizes that disagree,
// KINEMATIC_PARAMS of another robot) is rejected naming the field, counted in HEALTH, and not
// published; a failed DDS write is reported in HEALTH. The bridge keeps no state but the latest
// orientation, so a restart of any LCM publisher needs nothing from it.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstring>
#include <map>
#include <optional>

#include "rcal/clock_offset_t.hpp"
#include "rcal/dds/convert.hpp"
#include "rcal/dds/dds_common.hpp"
#include "rcal/dds/ros2_convert.hpp"
#include "rcal/dds/setup_frames.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/health_t.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/calibration_export.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/services/common.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace {

using namespace rcal;

struct Options {
  std::string robot_id;
  std::optional<io::BuiltCell> cell;  // --cell: the model for the ROS 2 standard outputs
  io::CellChannels channels;  // the LCM channels it subscribes (the cell's, else the table's)
  std::string lcm_url;
  int dds_domain = -1;  // -1: Cyclone's default (DDS_DOMAIN_DEFAULT)
  std::string name = "dds_bridge";
};

class Bridge {
 public:
  /// The final HEALTH (on a clean stop): the counts up to the end.
  void Finish() { health_.Final(t_); }
  Bridge(const Options& o, transport::Transport& t, dds_entity_t participant)
      : o_(o), t_(t), health_(o.name) {
    dds_qos_t* latched = dds::LatchedQos();
    dds_qos_t* stream = dds::StreamQos();
    params_w_ = Writer(participant, dds::Descriptor<dds::KinematicParams>(),
                       dds::kKinematicParamsTopic, latched);
    status_w_ = Writer(participant, dds::Descriptor<dds::CalibrationStatus>(),
                       dds::kCalibrationStatusTopic, latched);
    pose_w_ = Writer(participant, dds::Descriptor<dds::ToolPose>(), dds::kToolPoseTopic, stream);
    if (o_.cell) {
      tf_w_ = Writer(participant, dds::Descriptor<dds::TFMessage>(), "rt/tf_static", latched);
      description_w_ =
          Writer(participant, dds::Descriptor<dds::RosString>(), "rt/robot_description", latched);
      dds_qos_t* reliable = dds_create_qos();  // ROS 2's default: reliable, volatile
      dds_qset_reliability(reliable, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
      dds_qset_history(reliable, DDS_HISTORY_KEEP_LAST, 10);
      diagnostics_w_ =
          Writer(participant, dds::Descriptor<dds::DiagnosticArray>(), "rt/diagnostics", reliable);
      dds_delete_qos(reliable);
      pose_cov_w_ = Writer(participant, dds::Descriptor<dds::PoseWithCovarianceStamped>(),
                           "rt/rcal/tool_pose_with_covariance", stream);
      prefix_ = o_.cell->spec.ros2 ? o_.cell->spec.ros2->frame_prefix : "rcal_";
    }
    dds_delete_qos(latched);
    dds_delete_qos(stream);

    auto undecodable = [this](const std::string& e) {
      health_.Received();
      Reject(e);
    };
    t_.Subscribe<kinematic_params_t>(
        o_.channels.kinematic_params, [this](const kinematic_params_t& m) { OnParams(m); },
        undecodable);
    t_.Subscribe<calibration_status_t>(
        o_.channels.calibration_status, [this](const calibration_status_t& m) { OnStatus(m); },
        undecodable);
    t_.Subscribe<orientation_estimate_t>(
        o_.channels.orientation, [this](const orientation_estimate_t& m) { OnOrientation(m); },
        undecodable);
    t_.Subscribe<tool_position_estimate_t>(
        o_.channels.tool_position, [this](const tool_position_estimate_t& m) { OnToolPosition(m); },
        undecodable);
    if (o_.cell) {
      t_.Subscribe<health_t>(
          o_.channels.health, [this](const health_t& m) { OnHealth(m); }, undecodable);
      t_.Subscribe<clock_offset_t>(
          o_.channels.clock_offset, [this](const clock_offset_t& m) { OnClock(m); }, undecodable);
    }
    health_.Tick(0, t_);  // "up": the subscriptions are in place
  }

 private:
  static dds_entity_t Writer(dds_entity_t participant, const dds_topic_descriptor_t* desc,
                             const char* name, const dds_qos_t* qos) {
    return dds::CreateEndpoint(participant, desc, name, qos, true);
  }

  void Reject(const std::string& reason) {
    health_.Rejected(reason);
    spdlog::warn("rejected: {}", reason);
  }

  template <typename T>
  void Write(dds_entity_t writer, const std::optional<dds::Sample<T>>& s, const std::string& error,
             const char* what) {
    if (!s) return Reject(error);
    const dds_return_t rc = dds_write(writer, &s->get());
    if (rc < 0) {
      health_.Error(std::string("dds_write ") + what + ": " + dds_strretcode(rc));
      spdlog::error("dds_write {}: {}", what, dds_strretcode(rc));
      return;
    }
    health_.Published();
  }

  void OnParams(const kinematic_params_t& m) {
    health_.Received();
    std::string error;
    if (m.robot_id != o_.robot_id) {
      Reject("kinematic_params.robot_id: '" + m.robot_id + "' is not this bridge's robot '" +
             o_.robot_id + "'");
    } else {
      Write(params_w_, dds::ToDds(m, &error), error, "kinematic_params");
      spdlog::info("kinematic_params utime {} ({} parameters, {} poses)", m.utime, m.num_params,
                   m.poses_used);
      if (o_.cell) PublishCalibratedRobot(m);
    }
    health_.Tick(m.utime, t_);
  }

  // TF of the set-up frames and the calibrated URDF, from the identified parameters.
  void PublishCalibratedRobot(const kinematic_params_t& m) {
    std::string error;
    const auto x = transport::ParamsFromMessage(m, o_.cell->model, &error);
    if (!x) return Reject(error);
    const io::RobotSpec cal = io::CalibratedSpec(o_.cell->robot_spec, o_.cell->model, *x);
    if (cal.earth) R_WE_ = geometry::FromRpy(cal.earth->rpy).transpose();
    Write(tf_w_, dds::ToRos(dds::SetupTransforms(cal, prefix_), m.utime, &error), error,
          "tf_static");
    try {
      // The robot file's own URDF (joint origins corrected), or one written from a YAML robot.
      if (o_.cell->robot.from_urdf && urdf_source_.empty())
        urdf_source_ = io::ReadFile(o_.cell->robot.source);
      const std::string urdf = io::RobotDescriptionUrdf(
          o_.cell->robot_spec, o_.cell->model, *x, urdf_source_, o_.cell->robot.source.string(),
          {"rcal calibration " + io::CalibrationHash(o_.cell->model, *x) + " of cell '" +
           o_.cell->spec.name + "', " + std::to_string(m.poses_used) + " poses, sensor time " +
           std::to_string(m.utime) + " us"});
      Write(description_w_, std::optional{dds::ToRos(urdf)}, "", "robot_description");
    } catch (const std::exception& e) {
      health_.Error(std::string("robot_description: ") + e.what());
      spdlog::error("robot_description: {}", e.what());
    }
  }

  void OnHealth(const health_t& m) {
    if (m.process == o_.name) return;  // its own: counted already
    const auto prev = last_health_.find(m.process);
    dds::DiagnosticEntry e{
        m, dds::LevelOf(m, prev == last_health_.end() ? nullptr : &prev->second), {}};
    last_health_[m.process] = m;
    std::string error;
    Write(diagnostics_w_, dds::ToRos({e}, o_.robot_id, m.utime, &error), error, "diagnostics");
  }

  void OnClock(const clock_offset_t& m) {
    health_.Received();
    std::string error;
    const auto clocks = transport::ClockOffsetsFromMessage(m, &error);
    if (!clocks) return Reject(error);
    health_t h{};
    h.utime = m.utime;
    h.process = "clock_offsets";
    dds::DiagnosticEntry e{h, dds::DiagnosticLevel::kOk, {}};
    for (const transport::SourceClock& c : *clocks) {
      if (!c.fixed && c.offset.state != estimation::ClockState::kLocked)
        e.level = dds::DiagnosticLevel::kWarn;
      e.extra.emplace_back(c.source + ".state",
                           c.fixed ? "fixed" : estimation::ClockStateName(c.offset.state));
      e.extra.emplace_back(c.source + ".offset_s", std::to_string(c.offset.offset_s));
      e.extra.emplace_back(c.source + ".sigma_s", std::to_string(c.offset.sigma_s));
    }
    e.health.last_error =
        e.level == dds::DiagnosticLevel::kOk ? "" : "a clock offset is not locked";
    Write(diagnostics_w_, dds::ToRos({e}, o_.robot_id, m.utime, &error), error, "diagnostics");
  }

  void OnStatus(const calibration_status_t& m) {
    health_.Received();
    std::string error;
    Write(status_w_, dds::ToDds(m, o_.robot_id, &error), error, "calibration_status");
    health_.Tick(m.utime, t_);
  }

  void OnOrientation(const orientation_estimate_t& m) {
    health_.Received();
    // Checked here so that a bad orientation is rejected once, not with every pose after it.
    std::string error;
    tool_position_estimate_t probe{};
    probe.utime = m.utime;
    if (dds::ToDds(probe, &m, o_.robot_id, &error))
      orientation_ = m;
    else
      Reject(error);
    health_.Tick(m.utime, t_);
  }

  void OnToolPosition(const tool_position_estimate_t& m) {
    health_.Received();
    std::string error;
    Write(pose_w_, dds::ToDds(m, orientation_ ? &*orientation_ : nullptr, o_.robot_id, &error),
          error, "tool_pose");
    if (o_.cell)
      Write(pose_cov_w_,
            dds::ToRos(m, orientation_ ? &*orientation_ : nullptr, R_WE_ ? &*R_WE_ : nullptr,
                       (prefix_ + "world").c_str(), &error),
            error, "tool_pose_with_covariance");
    health_.Tick(m.utime, t_);
  }

  Options o_;
  transport::Transport& t_;
  transport::Health health_;
  dds_entity_t params_w_ = 0, status_w_ = 0, pose_w_ = 0;
  dds_entity_t tf_w_ = 0, description_w_ = 0, diagnostics_w_ = 0, pose_cov_w_ = 0;
  std::optional<orientation_estimate_t> orientation_;
  std::string prefix_;
  std::string urdf_source_;              // the robot file's URDF text (URDF robots), read once
  std::optional<Eigen::Matrix3d> R_WE_;  // world ← earth, from the latest parameters
  std::map<std::string, health_t> last_health_;  // per process, for the diagnostic level
};

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "dds_bridge: KINEMATIC_PARAMS, CALIBRATION_STATUS and the tool pose from LCM to DDS\n"
      "(topics rt/rcal/kinematic_params, rt/rcal/calibration_status, rt/rcal/tool_pose; ROS 2\n"
      "types rcal_msgs/msg/*). Cyclone DDS: $CYCLONEDDS_URI, else config/cyclonedds-loopback.xml.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  std::string cell_path;
  auto* cell_opt = app.add_option("--cell", cell_path,
                                  "cell file (schema rcal.cell/1): the robot id (the identifier's, "
                                  "its robot file's name) and the LCM channels");
  app.add_option("--robot-id", o.robot_id,
                 "robot id on every DDS message (default: the cell's); KINEMATIC_PARAMS of other "
                 "robots are rejected");
  app.add_option("--lcm-url", o.lcm_url, "LCM URL");
  app.add_option("--dds-domain", o.dds_domain, "DDS domain id (-1: Cyclone's default, 0)")
      ->capture_default_str();
  app.add_option("--name", o.name, "process name in HEALTH")->capture_default_str();
  std::string tool_pose_from = "filters";
  app.add_option("--tool-pose-from", tool_pose_from,
                 "the tool pose's source: filters (TOOL_POSITION and ORIENTATION: position_kf "
                 "and orientation_kf) or ins (INS_TOOL_POSITION and INS_ORIENTATION: aided_ins)")
      ->check(CLI::IsMember({"filters", "ins"}))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  if (cell_opt->count() > 0) {
    try {
      o.cell = io::LoadCell(rcal::services::RepoPath(cell_path));
      if (o.robot_id.empty()) o.robot_id = o.cell->model.name();
      o.channels = o.cell->spec.channels;
    } catch (const std::exception& e) {
      spdlog::error("--cell: {}", e.what());
      return 2;
    }
  }
  if (o.robot_id.empty()) {
    spdlog::error("--robot-id: empty (give --cell or --robot-id)");
    return 2;
  }
  if (tool_pose_from == "ins") {
    o.channels.orientation = o.channels.ins_orientation;
    o.channels.tool_position = o.channels.ins_tool_position;
  }

  try {
    rcal::services::InstallStopHandlers();
    const std::string uri = rcal::dds::EnsureCycloneConfig();
    const dds_domainid_t domain =
        o.dds_domain < 0 ? DDS_DOMAIN_DEFAULT : static_cast<dds_domainid_t>(o.dds_domain);
    rcal::dds::EntityGuard participant(dds_create_participant(domain, nullptr, nullptr));
    if (participant.get() < 0)
      throw std::runtime_error(std::string("dds_create_participant (CYCLONEDDS_URI ") + uri +
                               "): " + dds_strretcode(participant.get()));
    rcal::transport::LcmTransport t(o.lcm_url);
    // Logged before the start-up HEALTH goes out, so whoever sees that heartbeat finds this line.
    spdlog::info(
        "dds_bridge for robot '{}': LCM {} -> DDS domain {} (CYCLONEDDS_URI {}); tool pose from "
        "{} and {}",
        o.robot_id, t.url(), o.dds_domain < 0 ? "default" : std::to_string(o.dds_domain), uri,
        o.channels.tool_position, o.channels.orientation);
    Bridge bridge(o, t, participant.get());
    if (const int rc =
            rcal::services::ServeUntilStopped([&](int ms) { return t.HandleTimeout(ms); });
        rc != 0)
      return rc;
    bridge.Finish();
    spdlog::info("stopped");
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
