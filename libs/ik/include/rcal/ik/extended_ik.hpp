// Inverse kinematics on an extended model (kinematics/joint_effects.hpp): the joints as read q
// that place the tool frame at the target when the arm has non-geometric effects e under the
// pose's context c (temperature, payload, time, approach direction):
//
//   T_WT(q) = chain at the effective joints q̃ = EffectiveJoints(q, c, e), geometric errors x and
//             arm translations scaled by (1 + s), s = LengthScale(c, e) (ExtendedModel::ToolFrame)
//
// Solved directly for q by the Levenberg–Marquardt IK of levenberg_marquardt_ik.hpp (same
// residual, damping, joint limits on q, tolerances), with
//   pose      T_WT(q) exactly as above (the residual and every step's acceptance use it), and
//   Jacobian  ∂T_WT/∂q ≈ J_chain(q̃; x), the geometric chain's joint Jacobian at the effective
//             joints, i.e. ∂q̃/∂q ≈ I and ∂(growth)/∂q ≈ 0.
// The neglected terms are of the effects' relative size (c·∂τ/∂q, s, h·a ~ 1e-4), so the steps
// are Gauss–Newton steps with a Jacobian that is off by that much: the solution is the exact
// one (|p* − p(q)| ≤ position_tolerance on the extended pose) and each iteration near it shrinks
// the error by a factor ~1e-4. Seeded from the current joints as read, it stays on their branch.
// Units: metres, radians; e in the SI units of joint_effects.hpp.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "rcal/ik/levenberg_marquardt_ik.hpp"
#include "rcal/kinematics/joint_effects.hpp"

namespace rcal::ik {

/// The solver. One instance per thread (it holds the context of the solve under way).
class ExtendedIk : private LevenbergMarquardtIk {
 public:
  /// `model` with geometric errors x [m | rad] (size model.base().num_params()) and effect
  /// parameters e (size model.num_effect_params()). Throws std::invalid_argument naming x or e on
  /// a wrong size or non-finite values.
  ExtendedIk(kinematics::ExtendedModel model, const Eigen::VectorXd& x, const Eigen::VectorXd& e,
             IkSettings settings = {});

  /// A new calibration: geometric errors and effect parameters (checked as in the constructor).
  void SetParameters(const Eigen::VectorXd& x, const Eigen::VectorXd& e);

  const kinematics::ExtendedModel& model() const { return model_; }
  const Eigen::VectorXd& x() const { return x_; }
  const Eigen::VectorXd& e() const { return e_; }
  using LevenbergMarquardtIk::num_joints;
  using LevenbergMarquardtIk::settings;

  /// Joints as read q placing the tool frame at T_WT_target under `context`, from the current
  /// joints q_seed (IkResult as LevenbergMarquardtIk::Solve, errors of the extended pose). A
  /// context whose dq_sign has neither 0 nor num_joints values, or an infinite temperature, time
  /// or payload, is kInvalidInput naming the field.
  IkResult Solve(const Eigen::Isometry3d& T_WT_target, const Eigen::VectorXd& q_seed,
                 const kinematics::EffectContext& context);
  /// Position-only mode (orientation free, reported as 0).
  IkResult SolvePosition(const Eigen::Vector3d& p_WT_W, const Eigen::VectorXd& q_seed,
                         const kinematics::EffectContext& context);

 private:
  void Evaluate(const Eigen::VectorXd& q, Eigen::Isometry3d& T_WT,
                kinematics::CompiledChain::Jacobian* J) const override;
  /// Empty when the context fits the model, else the reason naming the field.
  std::string CheckContext(const kinematics::EffectContext& context) const;
  /// Takes the context for the solve to come, or fills `refused` (kInvalidInput) and returns
  /// false.
  bool Prepare(const kinematics::EffectContext& context, const Eigen::VectorXd& q_seed,
               IkResult& refused);
  void Check(const Eigen::VectorXd& x, const Eigen::VectorXd& e) const;

  kinematics::ExtendedModel model_;
  Eigen::VectorXd x_, e_;
  kinematics::EffectContext context_;  // of the solve under way
};

}  // namespace rcal::ik
