// Levenberg–Marquardt inverse kinematics on any chain model (KinematicModel at parameters x,
// evaluated through a CompiledChain).
//
// Target: the tool frame in the world frame, T_WT* = (R*, p*)  (the frame
// KinematicModel::ToolFrame returns). Residual at joints q, with T_WT(q) = (R, p):
//
//   r(q) = [ p* − p(q) ;  w · Log(R* · R(q)ᵀ) ]        (6 rows; position-only mode: first 3)
//
// w the orientation weight [m/rad]; Log the SO(3) logarithm, so the rotation part is the left
// rotation error in the world frame [rad]. With the geometric joint Jacobian J = [J_v; J_ω]
// (world frame, tool origin) and R(q + δ) = Exp(J_ω δ) R(q), the residual Jacobian is
//
//   ∂r/∂q = −G,   G = [ J_v ;  w · Jr⁻¹(e_R) · J_ω ],  e_R = Log(R* R(q)ᵀ)
//
// (Jr⁻¹ the inverse right Jacobian of SO(3)). Each iteration solves the damped normal equations
//
//   (GᵀG + λ I) δ = Gᵀ r,      q ← Π(q + δ)
//
// with Π the projection onto the joint limits (clamping); a joint resting on a limit that δ would
// push further out is held there and δ is solved again for the other joints. It accepts the step
// when ½|r|² falls and adapts λ (Nielsen's rule: shrink on success by max(1/3, 1 − (2ρ − 1)³), grow
// ×ν on failure). Converged when |p* − p| ≤ position_tolerance and |e_R| ≤ orientation_tolerance.
// Seeding from the current joints keeps the solution on the seed's branch (elbow, wrist, shoulder
// configuration); the solver never jumps to another branch on purpose.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>

#include "rcal/kinematics/compiled_chain.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::ik {

struct IkSettings {
  double position_tolerance = 1e-10;     ///< [m] on |p* − p|
  double orientation_tolerance = 1e-10;  ///< [rad] on the rotation angle between R* and R
  int max_iterations = 100;              ///< LM iterations (each one FK + Jacobian evaluation)
  double initial_damping = 1e-3;         ///< τ: λ₀ = τ · max diag(GᵀG) [dimensionless]
  double orientation_weight = 1.0;       ///< w [m/rad]: 1 rad of orientation error counts as w m
  bool respect_joint_limits = true;      ///< project every step onto the model's joint limits
};

enum class IkStatus {
  kConverged,      ///< both tolerances met
  kMaxIterations,  ///< still improving when max_iterations ran out
  kStalled,        ///< no step lowers the error: a local minimum (unreachable, or a joint limit)
  kInvalidInput,   ///< wrong seed size, NaN/inf in the target or the seed
};

struct IkResult {
  Eigen::VectorXd q;       ///< joints [rad | m]: the solution, or the best found
  bool converged = false;  ///< status == kConverged
  IkStatus status = IkStatus::kInvalidInput;
  int iterations = 0;              ///< LM iterations used
  double position_error = 0.0;     ///< |p* − p(q)| [m] at the returned q
  double orientation_error = 0.0;  ///< angle between R* and R(q) [rad] at the returned q
  std::string reason;              ///< why it failed, in words; empty on success
};

/// The solver. Holds its compiled chain and a preallocated workspace: one instance per thread.
class LevenbergMarquardtIk {
 public:
  /// Compiles `model` at parameter errors x [m | rad] (size model.num_params()).
  LevenbergMarquardtIk(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                       IkSettings settings = {});

  virtual ~LevenbergMarquardtIk() = default;
  LevenbergMarquardtIk(const LevenbergMarquardtIk&) = default;
  LevenbergMarquardtIk(LevenbergMarquardtIk&&) = default;
  LevenbergMarquardtIk& operator=(const LevenbergMarquardtIk&) = default;
  LevenbergMarquardtIk& operator=(LevenbergMarquardtIk&&) = default;

  /// Recompiles the chain at new parameter errors (a new calibration), keeping the settings.
  void SetParameters(const Eigen::VectorXd& x);

  const IkSettings& settings() const { return settings_; }
  IkSettings& settings() { return settings_; }
  int num_joints() const { return chain_.num_joints(); }
  const kinematics::CompiledChain& chain() const { return chain_; }

  /// Joints q placing the tool frame at T_WT_target (tool frame in the world frame), starting
  /// from q_seed [rad | m] (the current joints). A seed outside the limits is clamped first.
  IkResult Solve(const Eigen::Isometry3d& T_WT_target, const Eigen::VectorXd& q_seed);

  /// Position-only mode: joints placing the tool-frame origin at p_WT_W [m, world frame];
  /// orientation is free (IkResult::orientation_error is reported as 0).
  IkResult SolvePosition(const Eigen::Vector3d& p_WT_W, const Eigen::VectorXd& q_seed);

 protected:
  /// The pose the solver drives to the target: the tool frame T_WT at joints q and, when J is
  /// not null, the joint Jacobian J = [J_v; J_ω] of the file comment. Here the compiled chain; a
  /// solver on another forward model (extended_ik.hpp) overrides it.
  virtual void Evaluate(const Eigen::VectorXd& q, Eigen::Isometry3d& T_WT,
                        kinematics::CompiledChain::Jacobian* J) const;

 private:
  IkResult Run(const Eigen::Isometry3d& T_WT_target, bool position_only,
               const Eigen::VectorXd& q_seed);
  /// Residual r (rows 0..m−1) at the pose T_WT; returns ½|r|². Fills the position and
  /// orientation errors and e_R.
  double Residual(const Eigen::Isometry3d& T_WT_target, const Eigen::Isometry3d& T_WT,
                  bool position_only, Eigen::Matrix<double, 6, 1>& r, double& position_error,
                  double& orientation_error, Eigen::Vector3d& e_R) const;
  void Project(Eigen::VectorXd& q) const;

  kinematics::KinematicModel model_;
  kinematics::CompiledChain chain_;
  IkSettings settings_;
  Eigen::VectorXd lower_, upper_;  // joint limits [rad | m]
  // Workspace, sized at construction.
  kinematics::CompiledChain::Jacobian J_, G_;
  Eigen::MatrixXd H_, Hd_;
  Eigen::VectorXd g_, rhs_, dq_, q_, q_trial_;
  Eigen::VectorXi at_limit_;
  Eigen::LLT<Eigen::MatrixXd> llt_;
};

/// Short name of a status ("converged", "max iterations", "stalled", "invalid input").
const char* ToString(IkStatus status);

}  // namespace rcal::ik
