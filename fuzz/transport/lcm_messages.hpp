// Shared by the transport fuzz targets: bytes decoded as one of rcal's message types the way every
// rcal process and command decodes them (transport::DecodeLcm: the schema's bounds check, then
// the generated decoder), then through the message → domain adapters of transport/adapters.hpp.
// A crash, a sanitizer report, an allocation beyond libFuzzer's -malloc_limit_mb, or bytes the
// check passes but the generated decoder refuses (the schema and the code disagree) is a finding.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <type_traits>

#include "rcal/arm_conditions_t.hpp"
#include "rcal/calibration_status_t.hpp"
#include "rcal/clock_offset_t.hpp"
#include "rcal/health_t.hpp"
#include "rcal/ik_command_t.hpp"
#include "rcal/ik_request_t.hpp"
#include "rcal/imu_sample_t.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/joint_state_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/model_discrepancy_t.hpp"
#include "rcal/next_poses_t.hpp"
#include "rcal/orientation_estimate_t.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/position_sample_t.hpp"
#include "rcal/supervisor_state_t.hpp"
#include "rcal/tool_position_estimate_t.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_schema.hpp"

namespace rcal::fuzz {

inline const kinematics::KinematicModel& Grb3016() {
  static const kinematics::KinematicModel model =
      io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml").model;
  return model;
}

// The adapters a process runs on a decoded message (none for the types only displayed).
inline void Adapt(const pose_measurement_t& m) {
  std::string error;
  if (auto z = transport::FromMessage(m, &error)) (void)kinematics::Validate(Grb3016(), *z);
  // marker_id mapped to the model's marker slot, as ekf_identifier and calibrate-log do.
  if (auto z = transport::FromMessage(m, &error, &Grb3016()))
    (void)kinematics::Validate(Grb3016(), *z);
  // The pose's context, as ekf_identifier and calibrate-log read it.
  (void)transport::ContextFromMessage(m, &error);
}
// An extended model (ekf_identifier --effects, ik_corrector --effects) to check effects against.
inline const kinematics::ExtendedModel& Grb3016Bending() {
  static const kinematics::ExtendedModel model(Grb3016(),
                                               {{kinematics::EffectCause::kJointCompliance, 1},
                                                {kinematics::EffectCause::kJointPeriodic, 2, 2}});
  return model;
}
inline void Adapt(const ik_request_t& m) {
  std::string error;
  (void)transport::FromMessage(m, 6, &error);
  (void)transport::FromMessage(m, -1, &error);
}
inline void Adapt(const kinematic_params_t& m) {
  std::string error;
  (void)transport::ParamsFromMessage(m, Grb3016(), &error);
  (void)transport::EffectsFromMessage(m, Grb3016Bending(), &error);
}
// sensor_acquisition --follow-next-poses: the advice checked against the model, then followed.
inline void Adapt(const next_poses_t& m) {
  std::string error;
  if (auto n = transport::NextPosesFromMessage(m, Grb3016(), &error))
    (void)cell::NextStopToFollow(n->q, {Eigen::VectorXd::Zero(Grb3016().num_joints())});
}
// still_window: the controller's report checked before it stands for a window's context.
inline void Adapt(const arm_conditions_t& m) {
  std::string error;
  (void)transport::ArmConditionsFromMessage(m, &error);
}
inline void Adapt(const model_discrepancy_t& m) {
  std::string error;
  (void)transport::ModelDiscrepancyFromMessage(m, &error);
}
template <typename Msg>
void Adapt(const Msg&) {}

template <typename Msg>
void Decode(const std::uint8_t* data, std::size_t size) {
  const std::string refused =
      transport::CheckLcmMessage(Msg::getTypeName(), Msg::getHash(), data, size);
  Msg msg;
  const std::string why = transport::DecodeLcm(data, size, &msg);
  if (refused.empty() != why.empty()) {
    // The check passed bytes the generated decoder refuses (or the reverse): the schema walk and
    // lcm-gen's code disagree on the format.
    std::fprintf(stderr, "%s: check '%s', decode '%s'\n", Msg::getTypeName(), refused.c_str(),
                 why.c_str());
    std::abort();
  }
  if (why.empty()) Adapt(msg);
  if constexpr (std::is_same_v<Msg, pose_measurement_t>) {
    // The log readers' decoder, which also reads the layouts before the context and marker_id.
    Msg upgraded;
    if (transport::DecodePoseMeasurement(data, size, &upgraded).empty()) Adapt(upgraded);
  }
  if constexpr (std::is_same_v<Msg, kinematic_params_t>) {
    // rcal export's decoder, which also reads the layout before the effects.
    Msg upgraded;
    if (transport::DecodeKinematicParams(data, size, &upgraded).empty()) Adapt(upgraded);
  }
}

/// Decodes as the type with this index (mod 16).
inline void DecodeAs(unsigned index, const std::uint8_t* data, std::size_t size) {
  switch (index % 16) {
    case 0:
      return Decode<calibration_status_t>(data, size);
    case 1:
      return Decode<health_t>(data, size);
    case 2:
      return Decode<ik_command_t>(data, size);
    case 3:
      return Decode<ik_request_t>(data, size);
    case 4:
      return Decode<imu_sample_t>(data, size);
    case 5:
      return Decode<joint_state_t>(data, size);
    case 6:
      return Decode<kinematic_params_t>(data, size);
    case 7:
      return Decode<orientation_estimate_t>(data, size);
    case 8:
      return Decode<pose_measurement_t>(data, size);
    case 9:
      return Decode<position_sample_t>(data, size);
    case 10:
      return Decode<supervisor_state_t>(data, size);
    case 12:
      return Decode<clock_offset_t>(data, size);
    case 13:
      return Decode<next_poses_t>(data, size);
    case 14:
      return Decode<model_discrepancy_t>(data, size);
    case 15:
      return Decode<arm_conditions_t>(data, size);
    default:
      return Decode<tool_position_estimate_t>(data, size);
  }
}

/// Decodes as the type the pipeline publishes on `channel` (pose_measurement_t if none).
inline void DecodeChannel(std::string_view channel, const std::uint8_t* data, std::size_t size) {
  namespace ch = transport::channels;
  const std::string_view names[16] = {ch::kCalibrationStatus,
                                      ch::kHealth,
                                      ch::kIkCommand,
                                      ch::kIkRequest,
                                      ch::kImu,
                                      ch::kJoints,
                                      ch::kKinematicParams,
                                      ch::kOrientation,
                                      "",
                                      ch::kPosition,
                                      ch::kSupervisorState,
                                      ch::kToolPosition,
                                      ch::kClockOffset,
                                      ch::kNextPoses,
                                      ch::kModelDiscrepancy,
                                      ch::kArmConditions};
  for (unsigned i = 0; i < 16; ++i)
    if (!names[i].empty() && names[i] == channel) return DecodeAs(i, data, size);
  DecodeAs(8, data, size);
}

}  // namespace rcal::fuzz
