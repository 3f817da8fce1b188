// A kinematic chain compiled for fast, allocation-free forward kinematics and joint Jacobians.
//
// KinematicModel evaluates the chain ET by ET (one AngleAxis per rotation ET). For a fixed
// parameter vector x most of those ETs are constants, so CompiledChain folds them once:
//
//   T_WT(q) = F₀ · J₁(q₁) · F₁ · J₂(q₂) · … · J_N(q_N) · F_N
//
// where each Fₖ is a fixed rigid transform (every ET between two joint ETs, with x applied), and
// each Jₖ is a pure rotation about (revolute) or translation along (prismatic) the joint's unit
// axis by the joint variable alone. A joint ET's constant part (nominal + x, e.g. θᵢ + Δθᵢ of a
// D–H link) shares the joint axis, R_u(c + q) = R_u(c) · R_u(q), so it folds into the F in front.
// Axes equal to ±x, ±y, ±z take a fast path (one sincos, two column updates); any other axis
// uses Rodrigues' formula R_u(q) = I + sin q [u]× + (1 − cos q) [u]×².
//
// Joint Jacobian convention (same as KinematicModel::JointJacobian): 6 × N in the world frame,
// rows 0–2 the velocity of the tool-frame origin [m/s per joint unit/s], rows 3–5 the angular
// velocity [rad/s per joint unit/s]. For revolute joint k with world axis u_k through the world
// point o_k:  J_k = [u_k × (p_WT − o_k); u_k];  for a prismatic joint:  J_k = [u_k; 0].
//
// The chain is the "chain" segment of the model (world ← base … tool/marker), i.e. the frame
// KinematicModel::ToolFrame returns. The earth and IMU segments are not part of it.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

#include "rcal/kinematics/model.hpp"

namespace rcal::kinematics {

class CompiledChain {
 public:
  /// 6 × N Jacobian storage (N = num_joints()).
  using Jacobian = Eigen::Matrix<double, 6, Eigen::Dynamic>;

  CompiledChain() = default;
  /// Compiles the chain of `model` at parameter errors `x` [m | rad] (size model.num_params()).
  /// Throws std::invalid_argument on a wrong size of x, or when a joint drives more than one ET.
  CompiledChain(const KinematicModel& model, const Eigen::VectorXd& x);

  int num_joints() const { return static_cast<int>(joints_.size()); }

  /// Tool frame in the world frame, T_WT, at joints q [rad | m] (size num_joints(), unchecked in
  /// release builds). Allocation-free.
  Eigen::Isometry3d ToolFrame(const Eigen::Ref<const Eigen::VectorXd>& q) const;

  /// Joint Jacobian (convention in the file comment) written into J, which must be 6 × N
  /// (unchecked in release builds). When T_WT is not null it receives the tool frame, computed on
  /// the way. Allocation-free.
  void JointJacobian(const Eigen::Ref<const Eigen::VectorXd>& q, Eigen::Ref<Jacobian> J,
                     Eigen::Isometry3d* T_WT = nullptr) const;

  /// Convenience overload that allocates the 6 × N result.
  Jacobian JointJacobian(const Eigen::Ref<const Eigen::VectorXd>& q) const;

 private:
  enum class Axis : unsigned char { kX, kY, kZ, kGeneral };
  struct Fixed {
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  ///< rotation of the fixed transform
    Eigen::Vector3d p = Eigen::Vector3d::Zero();      ///< translation of the fixed transform [m]
    bool identity = true;                             ///< skip when the transform is identity
  };
  struct JointStep {
    int index = 0;                                 ///< column of q / of the Jacobian
    bool revolute = true;                          ///< rotation ET (else translation ET)
    Axis axis = Axis::kZ;                          ///< fast-path axis
    double sign = 1.0;                             ///< +1 / −1 for ±x, ±y, ±z
    Eigen::Vector3d u = Eigen::Vector3d::UnitZ();  ///< unit axis in the joint frame
    Fixed after;                                   ///< F_k: fixed transform after this joint
  };

  Fixed base_;  ///< F₀
  std::vector<JointStep> joints_;
};

}  // namespace rcal::kinematics
