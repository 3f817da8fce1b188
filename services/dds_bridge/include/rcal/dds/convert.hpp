// The LCM <-> DDS conversion of the dds_bridge: pure functions, no DDS entities, no state.
//
// LCM messages (lcmtypes/) become the C structs idlc generates from idl/rcal_msgs.idl
// (rcal_msgs::msg::dds_::KinematicParams_, CalibrationStatus_, ToolPose_) and back. Values are
// copied bit for bit: LCM → DDS → LCM gives the same message. Time: LCM `utime` [µs] becomes the
// ROS 2 header stamp (sec = floor(utime / 10⁶), nanosec = the rest in ns); the way back drops any
// sub-microsecond part of a stamp another DDS writer set.
//
// Every conversion checks its input first and returns std::nullopt with `*error` naming the
// field (e.g. "kinematic_params.values[3] (d2): NaN") when it does not fit: array sizes that
// disagree, NaN or infinite values, an empty robot id, a time outside the stamp's range.
// `condition_number` may be +inf (a rank-deficient Jacobian); nothing else may be infinite.
#pragma once

#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <utility>

#include "rcal/calibration_status_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/orientation_estimate_t.hpp"
#include "rcal/tool_position_estimate_t.hpp"
#include "rcal_msgs.h"

namespace rcal::dds {

using KinematicParams = rcal_msgs_msg_dds__KinematicParams_;
using CalibrationStatus = rcal_msgs_msg_dds__CalibrationStatus_;
using ToolPose = rcal_msgs_msg_dds__ToolPose_;
using Time = builtin_interfaces_msg_dds__Time_;

/// header.frame_id of each message: the parameters belong to the chain from `base`; the tool
/// position is in the position sensor frame `meas`; the status has no frame.
inline constexpr const char* kKinematicParamsFrame = "base";
inline constexpr const char* kCalibrationStatusFrame = "";
inline constexpr const char* kToolPoseFrame = "meas";

/// The topic descriptor idlc generated for T (what dds_create_topic and dds_sample_free take).
template <typename T>
const dds_topic_descriptor_t* Descriptor();
template <>
inline const dds_topic_descriptor_t* Descriptor<KinematicParams>() {
  return &rcal_msgs_msg_dds__KinematicParams__desc;
}
template <>
inline const dds_topic_descriptor_t* Descriptor<CalibrationStatus>() {
  return &rcal_msgs_msg_dds__CalibrationStatus__desc;
}
template <>
inline const dds_topic_descriptor_t* Descriptor<ToolPose>() {
  return &rcal_msgs_msg_dds__ToolPose__desc;
}

/// Owns one generated C sample: strings and sequences are allocated with dds_alloc and freed
/// with dds_sample_free on destruction. Movable, not copyable. get() is what dds_write takes.
template <typename T>
class Sample {
 public:
  Sample() { std::memset(&v_, 0, sizeof v_); }
  ~Sample() { dds_sample_free(&v_, Descriptor<T>(), DDS_FREE_CONTENTS); }
  Sample(Sample&& o) noexcept {
    std::memcpy(&v_, &o.v_, sizeof v_);
    std::memset(&o.v_, 0, sizeof o.v_);
  }
  Sample& operator=(Sample&& o) noexcept {
    if (this != &o) {
      dds_sample_free(&v_, Descriptor<T>(), DDS_FREE_CONTENTS);
      std::memcpy(&v_, &o.v_, sizeof v_);
      std::memset(&o.v_, 0, sizeof o.v_);
    }
    return *this;
  }
  Sample(const Sample&) = delete;
  Sample& operator=(const Sample&) = delete;

  T& get() { return v_; }
  const T& get() const { return v_; }

 private:
  T v_;
};

// ---- time -------------------------------------------------------------------------------------

/// utime [µs] → stamp. Fails (naming `field`) when the seconds do not fit the stamp's int32.
std::optional<Time> StampFromUtime(int64_t utime, const std::string& field, std::string* error);
/// stamp → utime [µs] (sub-microsecond part dropped). Fails when nanosec ≥ 10⁹.
std::optional<int64_t> UtimeFromStamp(const Time& stamp, const std::string& field,
                                      std::string* error);

/// Fills a header: stamp from utime, frame_id a copy of `frame` (dds_string_dup). Fails as
/// StampFromUtime.
bool FillHeader(std_msgs_msg_dds__Header_& h, int64_t utime, const char* frame,
                const std::string& field, std::string* error);

// ---- kinematic parameters ---------------------------------------------------------------------

/// KINEMATIC_PARAMS → KinematicParams_. robot_id comes from the message (must not be empty);
/// names, values, sigmas and identified must all have num_params entries; values and sigmas
/// finite.
std::optional<Sample<KinematicParams>> ToDds(const kinematic_params_t& msg, std::string* error);
/// KinematicParams_ → KINEMATIC_PARAMS. Same checks; the four sequences must have equal lengths.
std::optional<kinematic_params_t> FromDds(const KinematicParams& msg, std::string* error);

// ---- calibration status -----------------------------------------------------------------------

/// CALIBRATION_STATUS + the robot it belongs to (the LCM message does not name it) →
/// CalibrationStatus_. Residuals and NIS finite; condition_number not NaN (may be +inf).
std::optional<Sample<CalibrationStatus>> ToDds(const calibration_status_t& msg,
                                               const std::string& robot_id, std::string* error);
/// CalibrationStatus_ → CALIBRATION_STATUS (the robot id stays in the DDS message).
std::optional<calibration_status_t> FromDds(const CalibrationStatus& msg, std::string* error);

// ---- tool pose --------------------------------------------------------------------------------

/// TOOL_POSITION + the latest ORIENTATION (nullptr: none yet, has_orientation false) + the robot
/// → ToolPose_. All values finite.
std::optional<Sample<ToolPose>> ToDds(const tool_position_estimate_t& position,
                                      const orientation_estimate_t* orientation,
                                      const std::string& robot_id, std::string* error);

/// What a ToolPose_ carries, as LCM messages. The orientation's gyro_bias is not carried (zero).
struct ToolPoseMessages {
  tool_position_estimate_t position;
  std::optional<orientation_estimate_t> orientation;  ///< when has_orientation
};
std::optional<ToolPoseMessages> FromDds(const ToolPose& msg, std::string* error);

}  // namespace rcal::dds
