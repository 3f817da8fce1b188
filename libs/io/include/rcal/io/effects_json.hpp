// The effect list of an `rcal analyze` analysis.json (cmd_analyze.cpp writes it), read back so
// that `rcal calibrate --effects` fits the model the analysis selected and ik_corrector commands
// the arm with it, and the calibrated effects written as the same JSON entries. Keys of one entry
// of "effects" (SI units):
//   cause      "joint_compliance" | "joint_periodic" | "joint_scale" | "backlash" | "thermal"
//   joints     [joint name]          one name for the joint causes, [] for thermal
//   harmonic   1 | 2                 joint_periodic only
//   source     "temperature" | "time", reference [°C | s]     thermal only
//   values     [{name, unit, value, sigma}]   one per effect parameter (periodic: sin, cos)
// Top-level "selected_on" (analysis.json, optional): what the selection was run on —
//   data, rows, rows_fitted, split, row_fingerprints [PoseFingerprint of each row it fitted] —
// read back so that `rcal calibrate --effects` can say whether its held-out rows were seen by
// the selection. Other keys (selection_z, ...) are ignored. Causes of streamed or IMU data
// (time_offset, gyro_bias, magnetic_disturbance, accel_motion) are refused: they are not pose-level
// effects.
#pragma once

#include <Eigen/Core>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "rcal/io/pose_dataset.hpp"
#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/measurement.hpp"

namespace rcal::io {

struct AnalysisEffects {
  std::vector<kinematics::Effect> effects;
  Eigen::VectorXd values;  ///< the analysis' fitted values, in ExtendedModel order [SI]
  /// The gravity model joint_compliance was fitted with (top-level `link_density_kg_per_m`)
  /// [kg/m]; NaN when the file does not say.
  double link_density_kg_per_m = std::numeric_limits<double>::quiet_NaN();
  /// "selected_on" given: the fingerprints of the rows the selection fitted.
  bool has_selection_rows = false;
  std::set<std::string> selection_rows;
  /// The analysis' own held-out gain ("gain": relative_gain, scheme); NaN / "" when absent.
  double analysis_relative_gain = std::numeric_limits<double>::quiet_NaN();
  std::string analysis_gain_scheme;
};

/// A fingerprint of one measured pose (FNV-1a 64 over the bytes of its joints, position and,
/// when measured, orientation; 16 hex digits): the same row read from the same file gives the
/// same fingerprint, so two commands can tell which rows they share.
std::string PoseFingerprint(const kinematics::PoseMeasurement& m);

/// Parses the "effects" list of an analysis.json document against `model` (joint names).
/// Throws std::runtime_error naming the key ("effects[1].joints: no joint 'elbow2' in robot ...").
AnalysisEffects ParseAnalysisEffects(const nlohmann::json& analysis,
                                     const kinematics::KinematicModel& model);
/// Reads the file and parses it; errors name the file too.
AnalysisEffects ReadAnalysisEffects(const std::string& path,
                                    const kinematics::KinematicModel& model);

/// The effects of `model` with values e and 1σ sigma as analysis.json entries (the keys above).
nlohmann::json EffectsJson(const kinematics::ExtendedModel& model, const Eigen::VectorXd& e,
                           const Eigen::VectorXd& sigma);

/// The context of each sample of a pose dataset (temperature, payload (absent: 0), time, dq).
std::vector<kinematics::EffectContext> ToContexts(const PoseDataset& data);

}  // namespace rcal::io
