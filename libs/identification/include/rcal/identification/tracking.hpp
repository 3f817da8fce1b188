// The online identification run over recorded poses in time order, as `rcal track` runs it (the
// offline twin of the ekf_identifier process, for users and for tests), and the figures of a
// seeded tracking experiment (a step of one joint offset or link length after convergence).
//
// Poses marked test are never fitted: at each one the tool position predicted with the estimate
// of that moment is compared with the measurement.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "rcal/identification/ekf_identifier.hpp"

namespace rcal::identification {

/// One row of a tracking trace.
struct TrackRow {
  bool test = false;
  double prediction_error_m = 0;  ///< test rows: |p_measured − p_predicted| [m]; NaN otherwise
  TrackingStatus status = TrackingStatus::kConverging;  ///< after this row
  std::vector<std::string> changed;  ///< the change named at this row (parameters or "joint q")
  std::vector<double> steps;         ///< its size per name [m | rad]
  /// Per name, the probability it is the one that stepped when the names are alternatives
  /// (DetectedChange::probability); empty: one step along all of them.
  std::vector<double> probability;
  /// The last change as its second look renamed it at this row (EkfSettings::
  /// change_second_look; empty: no rename here), its steps [m | rad] and probabilities.
  std::vector<std::string> renamed;
  std::vector<double> renamed_steps, renamed_probability;
  double nis = 0;         ///< fitted rows: normalised innovation squared; NaN otherwise
  bool accepted = false;  ///< fitted rows: taken by the filter
  std::string rejected;   ///< why a fitted row was refused (gate, invalid input)
};

/// Names a detected change's directions: the parameter's name, or "offset of joint NAME".
std::vector<std::string> ChangeNames(const kinematics::KinematicModel& model,
                                     const DetectedChange& change);

/// Fills the row's change and rename from an update's result (nothing when it has neither).
void RecordChanges(const kinematics::KinematicModel& model, const EkfUpdateResult& result,
                   TrackRow& row);

/// Runs `ekf` over `poses` in order; is_test[k] marks poses never fitted (empty: none).
/// Throws std::invalid_argument when is_test has the wrong size.
std::vector<TrackRow> Track(EkfIdentifier& ekf,
                            const std::vector<kinematics::PoseMeasurement>& poses,
                            const std::vector<bool>& is_test = {});

/// The tool position error [m] of the model at x for a measurement (its marker).
double PositionError(const kinematics::KinematicModel& model, const kinematics::PoseMeasurement& z,
                     const Eigen::VectorXd& x);

}  // namespace rcal::identification
