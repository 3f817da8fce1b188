// What the dds_bridge, its tests and bench_dds share: topic names (ROS 2 convention), the QoS of
// each topic, and the choice of the Cyclone DDS configuration (loopback only unless told).
#pragma once

#include <dds/dds.h>

#include <string>

namespace rcal::dds {

/// DDS topic names: ROS 2 maps topic /rcal/x to DDS topic rt/rcal/x.
inline constexpr const char* kKinematicParamsTopic = "rt/rcal/kinematic_params";
inline constexpr const char* kCalibrationStatusTopic = "rt/rcal/calibration_status";
inline constexpr const char* kToolPoseTopic = "rt/rcal/tool_pose";

/// QoS of the parameter and status topics, for writers and readers alike: reliable,
/// transient-local, keep-last 1, so a subscriber that joins late gets the latest value of every
/// robot at once (ROS 2: reliability reliable, durability transient_local, depth 1).
/// The caller owns the result (dds_delete_qos).
dds_qos_t* LatchedQos();

/// QoS of the tool pose stream: best-effort, volatile, keep-last 1 (a late or slow reader gets
/// the newest pose, never a backlog). The caller owns the result (dds_delete_qos).
dds_qos_t* StreamQos();

/// The ROS 2 sensor-data QoS (rclcpp::SensorDataQoS: best effort, volatile, keep last `depth`),
/// what ROS 2 sensor drivers publish with and ros2_input reads with (a deep history there, so a
/// burst between two takes is not overwritten). StreamQos() is this with depth 1. The caller owns
/// the result (dds_delete_qos).
dds_qos_t* SensorDataQos(int depth);

/// The ROS 2 topic name /x as its DDS topic name rt/x.
inline std::string DdsTopicName(const std::string& ros_topic) {
  return "rt" + ros_topic;
}

/// A topic and a writer (`writer` true) or reader on it, `qos` for both. Throws
/// std::runtime_error naming the topic and Cyclone's return code.
dds_entity_t CreateEndpoint(dds_entity_t participant, const dds_topic_descriptor_t* desc,
                            const std::string& topic_name, const dds_qos_t* qos, bool writer);

/// The repository's loopback-only configuration: config/cyclonedds-loopback.xml as a file://
/// URI (found next to the working directory or in the source tree the binary was built from).
/// Throws std::runtime_error naming the path when the file does not exist.
std::string LoopbackConfigUri();

/// Makes Cyclone DDS bind to loopback only unless the environment chose otherwise: when
/// CYCLONEDDS_URI is unset or empty, sets it to LoopbackConfigUri(). Call before the first DDS
/// entity is created. Returns the CYCLONEDDS_URI in effect. Throws as LoopbackConfigUri().
std::string EnsureCycloneConfig();

/// Deletes a DDS entity (and its children) at scope exit.
class EntityGuard {
 public:
  explicit EntityGuard(dds_entity_t e = 0) : e_(e) {}
  ~EntityGuard() {
    if (e_ > 0) dds_delete(e_);
  }
  EntityGuard(const EntityGuard&) = delete;
  EntityGuard& operator=(const EntityGuard&) = delete;
  dds_entity_t get() const { return e_; }

 private:
  dds_entity_t e_;
};

}  // namespace rcal::dds
