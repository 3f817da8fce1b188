// Pose measurements from a recorded LCM event log (lcm-logger, the logger service): the
// POSE_MEASUREMENT events in log order, decoded and checked exactly as ekf_identifier checks them
// (transport::FromMessage, then kinematics::Validate against the robot), so offline commands see
// the poses the live identifier saw. Events that fail are skipped and counted, with the first
// reason kept for the message to the user. The log is read with io::LcmLogReader (damaged
// frames skipped and counted) and every event checked against its schema before it is decoded
// (transport::DecodeLcm); what was lost is in PoseLog::log, for CheckLogGaps.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "rcal/io/lcm_log.hpp"
#include "rcal/io/pose_dataset.hpp"
#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::tool {

/// True when the file starts with an LCM event-log record (sync word 0xEDA1DA01, big-endian).
bool IsLcmLog(const std::filesystem::path& path);

struct LoggedPose {
  kinematics::PoseMeasurement measurement;  ///< with the logged covariance
  int64_t utime = 0;                        ///< sensor time [µs]
  int32_t pose_index = 0;
  kinematics::EffectContext context;  ///< the conditions logged with it (defaults before they were)
};

struct PoseLog {
  std::vector<LoggedPose> poses;  ///< valid and strictly increasing in utime, in log order
  int64_t events = 0;             ///< events on the channel
  int64_t skipped = 0;            ///< undecodable, invalid for the robot, or not after the last
  std::string first_skip_reason;  ///< empty when none skipped
  /// What reading the log lost: broken frames, unreadable bytes, and the events of `channel`
  /// that did not decode (its events_skipped). Poses with invalid values, invalid for the robot
  /// or out of order are refused as the pipeline refuses them, counted in `skipped` only.
  io::LcmLogStats log;
};

/// Prints "PATH: events read N, skipped S, broken frames B, bytes unreadable U" (and the first
/// reasons) to stdout. When anything was lost and `allow_gaps` is false, throws
/// std::runtime_error saying so (the command exits non-zero); with `allow_gaps`, warns.
void CheckLogGaps(const std::string& path, const io::LcmLogStats& stats, bool allow_gaps);

/// Reads `channel` of the log. Throws std::runtime_error naming the file when it cannot be read.
PoseLog ReadPoseLog(const std::filesystem::path& path, const kinematics::KinematicModel& model,
                    const std::string& channel);

/// The poses as a pose dataset (time = utime [s], row = 1 for the first pose read, as a file's
/// data rows; no temperature, payload or approach sign: the pipeline's messages do not carry
/// them).
io::PoseDataset ToPoseDataset(const PoseLog& log, int num_joints);

}  // namespace rcal::tool
