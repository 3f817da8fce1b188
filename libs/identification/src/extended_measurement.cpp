#include "rcal/identification/extended_measurement.hpp"

#include <Eigen/Geometry>
#include <cmath>

namespace rcal::identification {

void ExtendedResidualAndJacobian(const kinematics::ExtendedModel& model,
                                 const kinematics::PoseMeasurement& z,
                                 const kinematics::EffectContext& context, const Eigen::VectorXd& x,
                                 const Eigen::VectorXd& e, const std::vector<int>& identified,
                                 Eigen::VectorXd& r, Eigen::MatrixXd* H) {
  const int d = z.dimension();
  const int ng = static_cast<int>(identified.size()), ne = model.num_effect_params();
  Eigen::MatrixXd J_x, J_e;
  kinematics::ToolPose pose;
  model.ForMarker(z.marker).Jacobians(z.q, context, x, e, H ? &J_x : nullptr, H ? &J_e : nullptr,
                                      &pose);
  r.resize(d);
  r.head<3>() = z.p_WM_W - pose.p_WM_W;
  if (d == 6) {
    const Eigen::AngleAxisd aa(z.R_EI * pose.R_EI.transpose());
    r.tail<3>() = aa.angle() * aa.axis();
  }
  if (H) {
    H->resize(d, ng + ne);
    for (int c = 0; c < ng; ++c) H->col(c) = J_x.col(identified[c]).head(d);
    if (ne > 0) H->rightCols(ne) = J_e.topRows(d);
  }
}

std::string ValidateContext(const kinematics::ExtendedModel& model,
                            const kinematics::EffectContext& c) {
  const int n = model.base().num_joints();
  if (c.dq_sign.size() != 0 && c.dq_sign.size() != n)
    return "dq_sign: " + std::to_string(c.dq_sign.size()) + " values, expected " +
           std::to_string(n) + " (or none)";
  for (int j = 0; j < c.dq_sign.size(); ++j)
    if (std::abs(c.dq_sign(j)) > 1)
      return "dq_sign: value " + std::to_string(c.dq_sign(j)) + " of joint " +
             std::to_string(j + 1) + " is not -1, 0 or +1";
  if (std::isinf(c.temperature_c)) return "temperature_c: infinite";
  if (std::isinf(c.time_s)) return "time_s: infinite";
  if (std::isinf(c.payload_kg) || c.payload_kg < 0) return "payload_kg: negative or infinite";
  return "";
}

}  // namespace rcal::identification
