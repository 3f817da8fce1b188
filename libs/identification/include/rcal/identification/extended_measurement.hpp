// The pose measurement of an extended model (kinematics/joint_effects.hpp): the measurement
// function shared by the batch fit (extended_lm.hpp) and the EKF identifier (ekf_identifier.hpp).
//
//   h(q, c; x, e) = ExtendedModel pose at joints as read q, context c, geometric errors x [m | rad]
//                   and effect parameters e [SI, joint_effects.hpp]
//   r = z − h        [ p_WM_W,meas − p_WM_W ;  Log(R_EI,meas · R_EI ᵀ) ]   [m ; rad, earth frame]
//   H = ∂h/∂[x_identified ; e] = [ J_x(:, identified)  J_e ]   (d × (|identified| + |e|))
//
// with d = 3 (position only) or 6 and the Jacobian convention of measurement.hpp, so that
// r(x + dx, e + de) ≈ r(x, e) − H·[dx_identified; de]. With no effects this is
// kinematics::ResidualAndJacobian.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/measurement.hpp"

namespace rcal::identification {

/// r = z − h and, when H is not null, H (file comment). x full length, e of size
/// model.num_effect_params().
void ExtendedResidualAndJacobian(const kinematics::ExtendedModel& model,
                                 const kinematics::PoseMeasurement& z,
                                 const kinematics::EffectContext& context, const Eigen::VectorXd& x,
                                 const Eigen::VectorXd& e, const std::vector<int>& identified,
                                 Eigen::VectorXd& r, Eigen::MatrixXd* H);

/// Checks a context against a model: dq_sign empty or one value in {−1, 0, +1} per joint,
/// temperature_c / time_s finite or NaN (unknown), payload_kg finite ≥ 0 or NaN (0). Returns an
/// empty string when valid, else a reason naming the field ("dq_sign: 5 values, expected 6").
std::string ValidateContext(const kinematics::ExtendedModel& model,
                            const kinematics::EffectContext& context);

}  // namespace rcal::identification
