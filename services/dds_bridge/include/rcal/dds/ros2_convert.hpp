// ROS 2 standard messages (idl/ros2_msgs.idl) <-> rcal's domain types: pure functions, no DDS
// entities, no state. The input side reads what a cell's ROS 2 drivers publish (the arm's
// sensor_msgs/JointState and sensor_msgs/Temperature, the IMU's sensor_msgs/Imu and
// MagneticField, a motion-capture geometry_msgs/PoseStamped or a laser tracker's PointStamped); the
// output side writes rcal's results in the types stock ROS 2 tools show (tf2_msgs/TFMessage,
// diagnostic_msgs/DiagnosticArray, geometry_msgs/PoseWithCovarianceStamped, std_msgs/String for
// robot_description).
//
// Conventions at this border: ROS quaternions are (x, y, z, w) fields, rcal's are w, x, y, z
// (Eigen::Quaterniond). Stamps: builtin_interfaces/Time → utime [µs] on the publisher's clock (the
// clock offset between drivers is estimated elsewhere); nanosec ≥ 10⁹ and negative seconds are
// refused. Units are SI as ROS REP 103 has them (rad, m, rad/s, m/s², T) and are checked against
// the ranges a real sensor can report (transport::SensorRanges): a magnetometer driver that
// publishes µT or a gyro in °/s fails naming the field and the likely unit.
//
// Every From* checks its input and returns std::nullopt with `*error` naming the field, e.g.
// "joint_states.position[2] (joint3): NaN" or "joint_states.name: 'elbow_joint' missing".
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "rcal/dds/convert.hpp"
#include "rcal/health_t.hpp"
#include "rcal/joint_state_t.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "ros2_msgs.h"

namespace rcal::dds {

using JointState = sensor_msgs_msg_dds__JointState_;
using Imu = sensor_msgs_msg_dds__Imu_;
using MagneticField = sensor_msgs_msg_dds__MagneticField_;
using Temperature = sensor_msgs_msg_dds__Temperature_;
using InertiaStamped = geometry_msgs_msg_dds__InertiaStamped_;
using PoseStamped = geometry_msgs_msg_dds__PoseStamped_;
using PointStamped = geometry_msgs_msg_dds__PointStamped_;
using PoseWithCovarianceStamped = geometry_msgs_msg_dds__PoseWithCovarianceStamped_;
using TFMessage = tf2_msgs_msg_dds__TFMessage_;
using DiagnosticArray = diagnostic_msgs_msg_dds__DiagnosticArray_;
using RosString = std_msgs_msg_dds__String_;

#define RCAL_DDS_DESCRIPTOR(T, desc)                     \
  template <>                                            \
  inline const dds_topic_descriptor_t* Descriptor<T>() { \
    return &desc;                                        \
  }
RCAL_DDS_DESCRIPTOR(JointState, sensor_msgs_msg_dds__JointState__desc)
RCAL_DDS_DESCRIPTOR(Imu, sensor_msgs_msg_dds__Imu__desc)
RCAL_DDS_DESCRIPTOR(MagneticField, sensor_msgs_msg_dds__MagneticField__desc)
RCAL_DDS_DESCRIPTOR(Temperature, sensor_msgs_msg_dds__Temperature__desc)
RCAL_DDS_DESCRIPTOR(InertiaStamped, geometry_msgs_msg_dds__InertiaStamped__desc)
RCAL_DDS_DESCRIPTOR(PoseStamped, geometry_msgs_msg_dds__PoseStamped__desc)
RCAL_DDS_DESCRIPTOR(PointStamped, geometry_msgs_msg_dds__PointStamped__desc)
RCAL_DDS_DESCRIPTOR(PoseWithCovarianceStamped,
                    geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc)
RCAL_DDS_DESCRIPTOR(TFMessage, tf2_msgs_msg_dds__TFMessage__desc)
RCAL_DDS_DESCRIPTOR(DiagnosticArray, diagnostic_msgs_msg_dds__DiagnosticArray__desc)
RCAL_DDS_DESCRIPTOR(RosString, std_msgs_msg_dds__String__desc)
#undef RCAL_DDS_DESCRIPTOR

// ---- input: the drivers' messages -------------------------------------------------------------

/// header.frame_id as a string ("" when unset).
inline std::string FrameId(const std_msgs_msg_dds__Header_& h) {
  return h.frame_id ? std::string(h.frame_id) : std::string();
}

/// The arm's joints by name: JointState rows are mapped by name, never by order (drivers publish
/// in their own order, and some add joints of grippers or other axes, which are ignored).
class JointNameMap {
 public:
  /// `names`: the model's joints in chain order (kinematics::KinematicModel::joints()). Throws
  /// std::invalid_argument on an empty or repeated name.
  explicit JointNameMap(std::vector<std::string> names);
  const std::vector<std::string>& names() const { return names_; }
  /// Chain index of `name`, or −1.
  int Index(const std::string& name) const;

 private:
  std::vector<std::string> names_;
  std::unordered_map<std::string, int> index_;
};

/// JointState → JOINTS (chain order, names as the model's). Every model joint must be named once
/// with a finite position; velocity is used when the driver gives one per name (else 0); effort
/// is ignored. `topic` prefixes the field names in errors.
std::optional<joint_state_t> FromRos(const JointState& m, const JointNameMap& map,
                                     const std::string& topic, std::string* error);

/// Imu → IMU sample without magnetic field (has_mag false): gyro [rad/s] and specific force
/// [m/s²] in the message's frame (the sensor's axes). The orientation a driver may add is not
/// used (rcal estimates it). Checked against `ranges`.
std::optional<transport::ImuSample> FromRos(const Imu& m, const transport::SensorRanges& ranges,
                                            const std::string& topic, std::string* error);

/// A magnetometer reading: its stamp [µs, the IMU driver's clock] and field [T], sensor axes.
struct MagReading {
  int64_t utime = 0;
  Eigen::Vector3d m_S = Eigen::Vector3d::Zero();
};
std::optional<MagReading> FromRos(const MagneticField& m, const transport::SensorRanges& ranges,
                                  const std::string& topic, std::string* error);

/// Temperature → the arm's conditions (ARM_CONDITIONS) at the message's stamp [µs, the
/// publisher's clock]: temperature [°C, as sensor_msgs/Temperature has it] finite and in
/// [−60, 200] °C (kelvin is named: transport::TemperatureProblem); variance finite and ≥ 0 (0:
/// unknown; not used further). Payload NaN: another topic carries it (InertiaStamped).
std::optional<transport::ArmConditions> FromRos(const Temperature& m, const std::string& topic,
                                                std::string* error);
/// InertiaStamped (the payload the arm carries) → the arm's conditions at the message's stamp:
/// payload = inertia.m [kg], finite and in [0, 1000] kg (grams are named:
/// transport::PayloadProblem); the centre of mass and the tensor must be finite (not used
/// further). Temperature NaN: another topic carries it (Temperature).
std::optional<transport::ArmConditions> FromRos(const InertiaStamped& m, const std::string& topic,
                                                std::string* error);

/// PoseStamped (motion capture) → POSITION of `marker_id`: the pose's position [m] in the
/// tracker's frame, covariance `covariance` (the cell's σ²). The orientation is not used (the
/// IMU gives it) but must be a unit quaternion (±1e-3), else the sample is refused.
std::optional<transport::PositionSample> FromRos(const PoseStamped& m, int32_t marker_id,
                                                 const Eigen::Matrix3d& covariance,
                                                 const transport::SensorRanges& ranges,
                                                 const std::string& topic, std::string* error);
/// PointStamped (laser tracker) → POSITION of `marker_id`, as PoseStamped.
std::optional<transport::PositionSample> FromRos(const PointStamped& m, int32_t marker_id,
                                                 const Eigen::Matrix3d& covariance,
                                                 const transport::SensorRanges& ranges,
                                                 const std::string& topic, std::string* error);

/// The other way, for the drivers of a simulated cell and for tests: what a ROS 2 driver would
/// publish, stamped with the sample's utime. `order`: the chain indices in the order the driver
/// lists its joints (a permutation; empty: chain order).
std::optional<Sample<JointState>> ToRos(const joint_state_t& js, const std::vector<int>& order,
                                        const char* frame_id, std::string* error);
std::optional<Sample<Imu>> ToRos(const transport::ImuSample& s, const char* frame_id,
                                 std::string* error);
std::optional<Sample<MagneticField>> ToRos(const MagReading& s, const char* frame_id,
                                           std::string* error);
/// The arm's temperature as a driver publishes it (variance [°C²], 0: unknown). Refused: a
/// temperature that is not finite.
std::optional<Sample<Temperature>> ToRos(const transport::ArmConditions& c, double variance,
                                         const char* frame_id, std::string* error);
/// The payload as a controller would publish it: m = payload_kg, centre of mass and tensor zero
/// (a point mass at the flange). Refused: a payload that is not finite.
std::optional<Sample<InertiaStamped>> ToRosPayload(const transport::ArmConditions& c,
                                                   const char* frame_id, std::string* error);
std::optional<Sample<PoseStamped>> ToRosPose(const transport::PositionSample& s,
                                             const char* frame_id, std::string* error);
std::optional<Sample<PointStamped>> ToRosPoint(const transport::PositionSample& s,
                                               const char* frame_id, std::string* error);

// ---- output: rcal's results in ROS 2 terms ----------------------------------------------------

/// One tf2 transform: the pose of `child` in `parent` (p_PC_P, R_PC), as tf2 has parent → child.
struct NamedTransform {
  std::string parent, child;
  Eigen::Vector3d p_PC_P = Eigen::Vector3d::Zero();  ///< [m]
  Eigen::Quaterniond q_PC = Eigen::Quaterniond::Identity();
};
/// Transforms → TFMessage, every header stamped `utime`. Finite values, unit quaternions, named
/// frames.
std::optional<Sample<TFMessage>> ToRos(const std::vector<NamedTransform>& transforms, int64_t utime,
                                       std::string* error);
/// TFMessage → transforms (tests, and any reader of rt/tf_static).
std::optional<std::vector<NamedTransform>> FromRos(const TFMessage& m, std::string* error);

/// diagnostic_msgs/DiagnosticStatus levels.
enum class DiagnosticLevel : uint8_t { kOk = 0, kWarn = 1, kError = 2, kStale = 3 };
/// One process's HEALTH as a DiagnosticStatus: name "rcal/<process>", hardware_id the robot id,
/// level OK, WARN (something rejected or lost since the previous HEALTH of that process: the
/// counters grew), ERROR (a filter reset since the previous), STALE (`stale`: no HEALTH for a
/// while); message the last error; values every counter. `extra` key-values are appended (e.g.
/// the clock offsets).
struct DiagnosticEntry {
  health_t health;
  DiagnosticLevel level = DiagnosticLevel::kOk;
  std::vector<std::pair<std::string, std::string>> extra;
};
/// The level of `now` given the previous HEALTH of the same process (nullptr: first).
DiagnosticLevel LevelOf(const health_t& now, const health_t* previous);
std::optional<Sample<DiagnosticArray>> ToRos(const std::vector<DiagnosticEntry>& entries,
                                             const std::string& hardware_id, int64_t utime,
                                             std::string* error);
/// A DiagnosticStatus as read back: name, level, message, key-values.
struct DiagnosticReading {
  std::string name, message, hardware_id;
  DiagnosticLevel level = DiagnosticLevel::kOk;
  std::vector<std::pair<std::string, std::string>> values;
};
std::optional<std::vector<DiagnosticReading>> FromRos(const DiagnosticArray& m, std::string* error);

/// The tool pose as PoseWithCovarianceStamped in the world frame `frame_id` (the position
/// sensor's): the marker position p_WM_W and its covariance from the position KF (TOOL_POSITION);
/// the IMU's orientation in the world, R_WI = R_WE · R_EI, from the orientation KF (ORIENTATION,
/// R_EI) and the calibrated earth frame (R_WE = R_EWᵀ), its covariance rotated to the world.
/// Without an orientation or without R_WE yet: identity and −1 on the diagonal of the rotation
/// block (REP 145's "unknown"). Position–rotation cross terms are 0 (two filters).
std::optional<Sample<PoseWithCovarianceStamped>> ToRos(const tool_position_estimate_t& position,
                                                       const orientation_estimate_t* orientation,
                                                       const Eigen::Matrix3d* R_WE,
                                                       const char* frame_id, std::string* error);

/// A string message (robot_description: the URDF text).
Sample<RosString> ToRos(const std::string& text);

}  // namespace rcal::dds
