#include "rcal/identification/tracking.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

#include "rcal/kinematics/measurement.hpp"

namespace rcal::identification {

std::vector<std::string> ChangeNames(const kinematics::KinematicModel& model,
                                     const DetectedChange& change) {
  std::vector<std::string> names;
  for (size_t i = 0; i < change.parameters.size(); ++i) {
    if (change.parameters[i] >= 0)
      names.push_back(model.parameters()[change.parameters[i]].name);
    else
      names.push_back("offset of joint " + model.joints()[change.joints[i]].name);
  }
  return names;
}

double PositionError(const kinematics::KinematicModel& model, const kinematics::PoseMeasurement& z,
                     const Eigen::VectorXd& x) {
  return kinematics::Residual(model, z, x).head<3>().norm();
}

void RecordChanges(const kinematics::KinematicModel& model, const EkfUpdateResult& result,
                   TrackRow& row) {
  if (result.change) {
    row.changed = ChangeNames(model, *result.change);
    row.steps.assign(result.change->step.data(),
                     result.change->step.data() + result.change->step.size());
    row.probability = result.change->probability;
  }
  if (result.reattributed) {
    row.renamed = ChangeNames(model, *result.reattributed);
    const Eigen::VectorXd& st = result.reattributed->step;
    row.renamed_steps.assign(st.data(), st.data() + st.size());
    row.renamed_probability = result.reattributed->probability;
  }
}

std::vector<TrackRow> Track(EkfIdentifier& ekf,
                            const std::vector<kinematics::PoseMeasurement>& poses,
                            const std::vector<bool>& is_test) {
  if (!is_test.empty() && is_test.size() != poses.size())
    throw std::invalid_argument("is_test: " + std::to_string(is_test.size()) + " flags for " +
                                std::to_string(poses.size()) + " poses");
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<TrackRow> rows;
  rows.reserve(poses.size());
  for (size_t k = 0; k < poses.size(); ++k) {
    TrackRow row;
    row.test = !is_test.empty() && is_test[k];
    if (row.test) {
      const std::string why = kinematics::Validate(ekf.model(), poses[k]);
      row.prediction_error_m = why.empty() ? PositionError(ekf.model(), poses[k], ekf.x()) : nan;
      row.rejected = why;
      row.nis = nan;
      row.status = ekf.status();
    } else {
      const EkfUpdateResult r = ekf.Update(poses[k]);
      row.prediction_error_m = nan;
      row.nis = r.nis;
      row.accepted = r.accepted;
      row.rejected = r.reason;
      row.status = r.status;
      RecordChanges(ekf.model(), r, row);
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

}  // namespace rcal::identification
