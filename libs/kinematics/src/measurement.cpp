#include "rcal/kinematics/measurement.hpp"

#include <Eigen/Cholesky>
#include <string>

#include "rcal/geometry/so3.hpp"

namespace rcal::kinematics {

Eigen::VectorXd Residual(const KinematicModel& model, const PoseMeasurement& m,
                         const Eigen::VectorXd& x) {
  const ToolPose pose = model.ForMarker(m.marker).Forward(m.q, x);
  Eigen::VectorXd r(m.dimension());
  r.head<3>() = m.p_WM_W - pose.p_WM_W;
  if (m.has_orientation) r.tail<3>() = geometry::Log(m.R_EI * pose.R_EI.transpose());
  return r;
}

void ResidualAndJacobian(const KinematicModel& model, const PoseMeasurement& m,
                         const Eigen::VectorXd& x, const std::vector<int>& identified,
                         Eigen::VectorXd& r, Eigen::MatrixXd& H) {
  thread_local Eigen::MatrixXd J;
  J.resize(6, model.num_params());
  ToolPose pose;
  model.ForMarker(m.marker).IdentificationJacobian(m.q, x, J, &pose);
  const int dim = m.dimension();
  r.resize(dim);
  r.head<3>() = m.p_WM_W - pose.p_WM_W;
  if (m.has_orientation) r.tail<3>() = geometry::Log(m.R_EI * pose.R_EI.transpose());
  H.resize(dim, static_cast<int>(identified.size()));
  for (size_t i = 0; i < identified.size(); ++i) H.col(i) = J.col(identified[i]).head(dim);
}

std::string Validate(const KinematicModel& model, const PoseMeasurement& m) {
  if (m.q.size() != model.num_joints())
    return "q: " + std::to_string(m.q.size()) + " joints, model has " +
           std::to_string(model.num_joints());
  if (!m.q.allFinite()) return "q: not finite";
  if (m.marker != 0 && (m.marker < 0 || m.marker >= static_cast<int>(model.markers().size())))
    return "marker: slot " + std::to_string(m.marker) + ", model has " +
           std::to_string(model.markers().size()) + " marker(s)";
  if (!m.p_WM_W.allFinite()) return "p_WM_W: not finite";
  if (m.has_orientation) {
    if (!m.R_EI.allFinite()) return "R_EI: not finite";
    if ((m.R_EI.transpose() * m.R_EI - Eigen::Matrix3d::Identity()).norm() > 1e-6 ||
        m.R_EI.determinant() < 0)
      return "R_EI: not a rotation";
  }
  const int dim = m.dimension();
  if (m.covariance.rows() != dim || m.covariance.cols() != dim)
    return "covariance: " + std::to_string(m.covariance.rows()) + "x" +
           std::to_string(m.covariance.cols()) + ", expected " + std::to_string(dim) + "x" +
           std::to_string(dim);
  if (!m.covariance.allFinite()) return "covariance: not finite";
  Eigen::LLT<Eigen::MatrixXd> llt(m.covariance);
  if (llt.info() != Eigen::Success) return "covariance: not positive definite";
  return {};
}

}  // namespace rcal::kinematics
