// Pure conversions between LCM messages and the libraries' domain types. No I/O, no state.
//
// Every conversion from a message checks it first (sizes, finite values, unit quaternions,
// covariance shape) and returns std::nullopt with `*error` naming the field when it does not fit,
// so a process rejects and counts it instead of corrupting its state.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "rcal/arm_conditions_t.hpp"
#include "rcal/calibration_status_t.hpp"
#include "rcal/cell/discrepancy_watch.hpp"
#include "rcal/cell/next_poses.hpp"
#include "rcal/clock_offset_t.hpp"
#include "rcal/estimation/clock_offset.hpp"
#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/ik/levenberg_marquardt_ik.hpp"
#include "rcal/ik_command_t.hpp"
#include "rcal/ik_request_t.hpp"
#include "rcal/joint_state_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"
#include "rcal/model_discrepancy_t.hpp"
#include "rcal/next_poses_t.hpp"
#include "rcal/pose_measurement_t.hpp"

namespace rcal::transport {

/// Identifies a parameterisation: "<model name>:<16 hex digits of a hash of the parameter names
/// in order>". Two models with the same id accept each other's KINEMATIC_PARAMS.
std::string ModelId(const kinematics::KinematicModel& model);

// ---- pose measurements ------------------------------------------------------------------------

/// Pose measurement → message. `utime` [µs]: sensor time of the still window's end. `marker_id`:
/// the measured marker's id (the cell's, the dataset's `marker`), not its slot m.marker.
/// `context`: the conditions the pose was taken under (default: temperature and time unknown,
/// no payload, no motion direction).
pose_measurement_t ToMessage(const kinematics::PoseMeasurement& m, int64_t utime,
                             int32_t pose_index, int32_t marker_id = 0,
                             const kinematics::EffectContext& context = {});

/// Decodes a POSE_MEASUREMENT as transport::DecodeLcm does, and also as it was recorded by earlier
/// rcal, so that their logs still calibrate: before it carried the context (fingerprint
/// 0xa1f22502bbcd6577: read with temperature and time unknown, no payload, dq_sign 0) and before
/// it carried marker_id (0x257fdb5ac9ac24a6: also read as marker 0). Returns "" or the refusal.
std::string DecodePoseMeasurement(const void* data, size_t size, pose_measurement_t* msg);

/// The context of a message (kinematics::EffectContext). Checks, naming the field:
/// temperature_c NaN or within [−60, 200] °C, payload_kg within [0, 1000] kg, time_s NaN or
/// finite, dq_sign one value per joint, each −1, 0 or +1. A dq_sign of all 0 reads as no
/// direction (an empty dq_sign).
std::optional<kinematics::EffectContext> ContextFromMessage(const pose_measurement_t& msg,
                                                            std::string* error);

/// The message's marker id for marker slot `slot` of `model` (0 for a model without markers).
int32_t MarkerId(const kinematics::KinematicModel& model, int slot);

/// Message → pose measurement. Checks: num_joints ≥ 1 and == q size, dimension ∈ {3, 6} and
/// consistent with has_orientation, num_covariance == dimension², finite values, quaternion norm
/// within 1e-6 of 1 (renormalised), symmetric covariance, and marker_id: with `model`, one of its
/// markers (0 for a model without markers), turned into its slot (PoseMeasurement::marker);
/// without, 0 (slot 0). Does not check the values against a model (see kinematics::Validate).
std::optional<kinematics::PoseMeasurement> FromMessage(
    const pose_measurement_t& msg, std::string* error,
    const kinematics::KinematicModel* model = nullptr);

// ---- joints -----------------------------------------------------------------------------------

/// Joint vector → message with the model's joint names; dq zero when not given.
joint_state_t ToJointState(const kinematics::KinematicModel& model, const Eigen::VectorXd& q,
                           int64_t utime, const Eigen::VectorXd& dq = {});

// ---- kinematic parameters ---------------------------------------------------------------------

/// Full-length errors x and σ [m | rad] → message. `identified`: indices estimated.
kinematic_params_t ToKinematicParams(const kinematics::KinematicModel& model,
                                     const Eigen::VectorXd& x, const Eigen::VectorXd& sigma,
                                     const std::vector<int>& identified,
                                     const std::string& robot_id, int64_t utime,
                                     int32_t poses_used);

/// The identifier's current estimate → message, with its effect parameters (values and σ, names
/// and units of kinematics::ExtendedModel::EffectParameters) for an extended identifier.
kinematic_params_t ToKinematicParams(const identification::EkfIdentifier& ekf,
                                     const std::string& robot_id, int64_t utime);

/// Decodes a KINEMATIC_PARAMS as transport::DecodeLcm does, and also as earlier rcal recorded it
/// before it carried effect parameters (fingerprint 0xf474f493449420b3: read with none).
std::string DecodeKinematicParams(const void* data, size_t size, kinematic_params_t* msg);

/// The effect parameters of a message, checked against `model` (its EffectParameters: the same
/// count, names in order; finite values, σ ≥ 0 finite). Names the field on a refusal.
std::optional<Eigen::VectorXd> EffectsFromMessage(const kinematic_params_t& msg,
                                                  const kinematics::ExtendedModel& model,
                                                  std::string* error);

/// Message → full-length error vector for `model`. Checks sizes, finiteness, the model id and
/// that every name is the model's parameter at that index.
std::optional<Eigen::VectorXd> ParamsFromMessage(const kinematic_params_t& msg,
                                                 const kinematics::KinematicModel& model,
                                                 std::string* error);

// ---- calibration status -----------------------------------------------------------------------

/// Figures the identifier reports alongside its estimate.
struct StatusFigures {
  double condition_number = 0;
  double rms_position_residual = 0;     ///< [m]
  double rms_orientation_residual = 0;  ///< [rad]
  double last_nis = 0;
  bool converged = false;
};

/// The identifier's counts plus `figures` → message.
calibration_status_t ToCalibrationStatus(const identification::EkfIdentifier& ekf,
                                         const StatusFigures& figures, int64_t utime);

// ---- inverse kinematics -----------------------------------------------------------------------

struct IkQuery {
  int64_t request_id = 0;
  Eigen::Isometry3d T_WT = Eigen::Isometry3d::Identity();  ///< target tool frame, world
  bool position_only = false;
  Eigen::VectorXd q_seed;  ///< [rad | m]
};

/// Message → query. Checks sizes (num_joints == `expected_joints` when ≥ 0), finite values and a
/// unit quaternion (when not position only).
std::optional<IkQuery> FromMessage(const ik_request_t& msg, int expected_joints,
                                   std::string* error);

/// Request → message for tests and clients.
ik_request_t ToMessage(const IkQuery& query, int64_t utime);

/// Solutions on the calibrated and nominal model → message. `nominal_tool_error` [m]: how far
/// the nominal solution lands from the target on the calibrated model.
ik_command_t ToIkCommand(const ik_request_t& request, const ik::IkResult& calibrated,
                         const ik::IkResult& nominal, double nominal_tool_error,
                         int64_t params_utime);

// ---- clock offsets ----------------------------------------------------------------------------

/// One source of CLOCK_OFFSET: its name, whether it shares the joints' clock (`fixed`: no offset
/// estimated), else the estimate as estimation::ClockOffset (state, offset [s], σ [s]).
struct SourceClock {
  std::string source;
  bool fixed = false;
  estimation::ClockOffset offset;
  int32_t resets = 0;
};
/// CLOCK_OFFSET → its sources. Checks: 0 ≤ num_sources ≤ 4096 and every array that long, finite
/// offsets, σ ≥ 0 (+inf: unknown), state 0 to 3 (clock_offset.lcm); the reason names the field.
std::optional<std::vector<SourceClock>> ClockOffsetsFromMessage(const clock_offset_t& msg,
                                                                std::string* error);

// ---- arm conditions (issue 15, item 4: a pose's context from the cell's drivers) ------------

/// One ARM_CONDITIONS report: what the arm's controller says of the conditions it works under.
struct ArmConditions {
  int64_t utime = 0;  ///< [µs] sensor time (the joints' clock)
  double temperature_c = std::numeric_limits<double>::quiet_NaN();  ///< [°C]; NaN: not measured
  double payload_kg = std::numeric_limits<double>::quiet_NaN();     ///< [kg]; NaN: not known
};
arm_conditions_t ToArmConditions(const ArmConditions& c);
/// Why `temperature_c` is no temperature an arm works at: "" when it is one (in [−60, 200] °C, or
/// NaN: not measured); else the reason, e.g. "300.000000 °C is not -60 to 200 (kelvin?)" (the hint
/// for [213, 473]) or "infinite". Shared by every source of ARM_CONDITIONS.
std::string TemperatureProblem(double temperature_c);
/// Why `payload_kg` is no payload an arm carries: "" when it is one (in [0, 1000] kg, or NaN: not
/// known); else the reason, e.g. "5000.000000 kg is not 0 to 1000 (grams?)" or "infinite".
/// Shared by every source of ARM_CONDITIONS.
std::string PayloadProblem(double payload_kg);
/// ARM_CONDITIONS → the report. Checks (the reason names the field): utime ≥ 0; temperature NaN
/// (not measured) or in [−60, 200] °C (a figure beyond it in [213, 473] is reported as kelvin?);
/// payload NaN (not known) or in [0, 1000] kg (beyond: grams?); ±inf refused.
std::optional<ArmConditions> ArmConditionsFromMessage(const arm_conditions_t& msg,
                                                      std::string* error);

// ---- next poses (issue 16) -------------------------------------------------------------------

/// The identifier's advice → NEXT_POSES. `utime` [µs]: the pose after which it was computed;
/// `poses_used`: poses accepted so far.
next_poses_t ToNextPoses(const cell::NextPoseAdvice& advice, int64_t utime, int32_t poses_used,
                         int num_joints);

/// NEXT_POSES as a cell that follows it reads it: suggestions best first.
struct NextPoses {
  int64_t utime = 0;  ///< [µs] sensor time of the pose after which they were computed
  int32_t poses_used = 0;
  std::vector<Eigen::VectorXd> q;  ///< joints [rad | m], the model's order (as read)
  std::vector<double> gain_m2;     ///< predicted decrease of the mean squared error [m²]
  std::vector<double> distance;    ///< joint-space distance from the joints then [rad | m]
  double predicted_rms_m = 0;      ///< predicted RMS task-region position error [m]
};

/// NEXT_POSES → suggestions for `model`. Checks: num_joints == the model's, 0 ≤ count ≤ 1000,
/// num_values == count × num_joints and every array that long, finite values, each joint within
/// the model's limits, gain, distance and predicted_rms_position ≥ 0; the reason names the field
/// (a suggestion outside the limits would drive an arm into its stops).
std::optional<NextPoses> NextPosesFromMessage(const next_poses_t& msg,
                                              const kinematics::KinematicModel& model,
                                              std::string* error);

// ---- model discrepancy (issue 15 item 5) ---------------------------------------------------

/// The discrepancy watch's report → MODEL_DISCREPANCY. `utime` [µs]: the window's last pose;
/// `poses_used`: poses accepted so far; `switched_in`: the new suspects are now identified;
/// `withdrawn`: the changes the switch withdrew (cell::OnlineIdentification::withdrawn).
model_discrepancy_t ToModelDiscrepancy(const cell::DiscrepancyReport& report, int64_t utime,
                                       int32_t poses_used, bool switched_in,
                                       const std::vector<cell::WithdrawnChange>& withdrawn = {});

/// MODEL_DISCREPANCY as a listener reads it.
struct ModelDiscrepancy {
  int64_t utime = 0;  ///< [µs]
  int32_t poses_used = 0, window_poses = 0;
  double chi2 = 0, chi2_dof = 0, chi2_log_p = 0;
  struct Suspect {
    std::string cause, joints, description;
    double z = 0;
    bool in_model = false;
  };
  std::vector<Suspect> suspects;                       ///< strongest first
  std::vector<cell::WatchedCorrelation> correlations;  ///< strongest first
  double heldout_rms_before_m = 0, heldout_rms_after_m = 0, expected_gain = 0;
  std::string scheme;
  bool switched_in = false;
  struct Withdrawn {
    int64_t onset_pose_index = -1;  ///< −1: a pose from before a restart
    std::string changed;            ///< names, comma-separated ("": raised before a restart)
    double evidence = 0;            ///< −2 ln Bayes factor for withdrawing it
  };
  std::vector<Withdrawn> withdrawn;  ///< newest first
};

/// MODEL_DISCREPANCY → its content. Checks: 0 ≤ window_poses, 0 ≤ num_suspects ≤ 64 and every
/// array that long, each cause in the vocabulary, strings ≤ 256 bytes, chi2 and dof finite ≥ 0,
/// chi2_log_p ≤ 0 (−inf allowed), z not NaN, in_model and switched_in 0 or 1, held-out RMS
/// finite ≥ 0, expected_gain finite ≤ 1, 0 ≤ num_correlations ≤ 64 and its arrays that long,
/// |correlation| ≤ 1, correlation_log_p ≤ 0, 0 ≤ num_withdrawn ≤ 64 and its arrays that long,
/// each onset pose_index ≥ −1 (−1: not known) and evidence finite ≥ 0; the reason names the field.
std::optional<ModelDiscrepancy> ModelDiscrepancyFromMessage(const model_discrepancy_t& msg,
                                                            std::string* error);

}  // namespace rcal::transport
