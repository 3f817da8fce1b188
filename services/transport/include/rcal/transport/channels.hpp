// Channel names of the pipeline (one message type per channel, see lcmtypes/).
#pragma once

namespace rcal::transport::channels {

inline constexpr const char* kImu = "IMU";                     ///< imu_sample_t
inline constexpr const char* kPosition = "POSITION";           ///< position_sample_t
inline constexpr const char* kJoints = "JOINTS";               ///< joint_state_t
inline constexpr const char* kOrientation = "ORIENTATION";     ///< orientation_estimate_t
inline constexpr const char* kToolPosition = "TOOL_POSITION";  ///< tool_position_estimate_t
/// The tracker-aided INS (aided_ins): its attitude and the marker it tracks.
inline constexpr const char* kInsOrientation = "INS_ORIENTATION";     ///< orientation_estimate_t
inline constexpr const char* kInsToolPosition = "INS_TOOL_POSITION";  ///< tool_position_estimate_t
inline constexpr const char* kPoseMeasurement = "POSE_MEASUREMENT";   ///< pose_measurement_t
inline constexpr const char* kKinematicParams = "KINEMATIC_PARAMS";   ///< kinematic_params_t
inline constexpr const char* kCalibrationStatus = "CALIBRATION_STATUS";  ///< calibration_status_t
inline constexpr const char* kIkRequest = "IK_REQUEST";                  ///< ik_request_t
inline constexpr const char* kIkCommand = "IK_COMMAND";                  ///< ik_command_t
inline constexpr const char* kHealth = "HEALTH";                         ///< health_t
inline constexpr const char* kSupervisorState = "SUPERVISOR_STATE";      ///< supervisor_state_t
inline constexpr const char* kClockOffset = "CLOCK_OFFSET";              ///< clock_offset_t
inline constexpr const char* kNextPoses = "NEXT_POSES";                  ///< next_poses_t
inline constexpr const char* kModelDiscrepancy = "MODEL_DISCREPANCY";    ///< model_discrepancy_t
inline constexpr const char* kArmConditions = "ARM_CONDITIONS";          ///< arm_conditions_t

}  // namespace rcal::transport::channels
