// A kinematic chain compiled for fast, allocation-free forward kinematics and joint Jacobians.
//
// KinematicModel evaluates the chain ET by ET (one AngleAxis per rotation ET). For a fixed
// parameter vector x most of those ETs are constants, so CompiledChain folds them once:
//
//   T_WT(q) = F₀ · J₁(q₁ + c₁) · F₁ · J₂(q₂ + c₂) · … · J_N(q_N + c_N) · F_N
//
// where each Fₖ is a fixed rigid transform (every ET between two joint ETs, with x applied), and
// each Jₖ is a pure rotation about (revolute) or translation along (prismatic) the joint's unit
// axis. A joint ET's constant part cₖ (nominal + x, e.g. θᵢ + Δθᵢ of a D–H link) shares the joint
// axis, R_u(c + q) = R_u(c) · R_u(q), so it is folded once as a fixed offset of the joint
// variable; no extra transform is applied for it.
//
// Each Fₖ is stored in the cheapest exact form: a short list of primitive operations (merged
// translations, rotations about x, y or z with precomputed sin/cos), or, when that would take
// more than two rotations (e.g. a URDF origin with its 6-parameter error), one general 3 × 3
// rotation and one translation. A D–H link, Rz(θ+q) Tz(d) Tx(a) Rx(α), becomes one sincos, two
// column updates for Rz, one translation (a, 0, d) and two column updates for Rx.
// Joint axes equal to ±x, ±y, ±z take the same fast path (one sincos, two column updates); any
// other axis uses Rodrigues' formula R_u(q) = I + sin q [u]× + (1 − cos q) [u]×². sin and cos
// come from a Cody–Waite-reduced polynomial accurate to 1 ulp (std::sin/cos beyond |q| > 1e5).
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
  /// One primitive operation on the running pose (R, p): p += R·t, R ← R·R_axis(angle), or
  /// R ← R·M.
  struct Op {
    enum class Kind : unsigned char { kTranslate, kRotX, kRotY, kRotZ, kRotate };
    Kind kind = Kind::kTranslate;
    double angle = 0.0;                               ///< [rad] axis rotations (while compiling)
    double s = 0.0, c = 1.0;                          ///< sin, cos of the angle
    Eigen::Vector3d t = Eigen::Vector3d::Zero();      ///< [m] translation, current frame
    Eigen::Matrix3d M = Eigen::Matrix3d::Identity();  ///< general rotation
  };
  struct JointStep {
    int index = 0;                                 ///< column of q / of the Jacobian
    bool revolute = true;                          ///< rotation ET (else translation ET)
    int axis = 2;                                  ///< 0/1/2: ±x/±y/±z fast path; 3: general u
    double sign = 1.0;                             ///< +1 / −1 for ±x, ±y, ±z
    double offset = 0.0;                           ///< c: nominal + x of the joint ET [rad | m]
    Eigen::Vector3d u = Eigen::Vector3d::UnitZ();  ///< unit axis in the joint frame
    int ops_end = 0;                               ///< ops_[previous end, ops_end) = F after it
  };

  static void CloseSegment(std::vector<Op>& ops, size_t begin);

  std::vector<Op> ops_;   ///< F₀ then F₁ … F_N, flattened
  int base_ops_end_ = 0;  ///< ops_[0, base_ops_end_) = F₀
  std::vector<JointStep> joints_;
};

}  // namespace rcal::kinematics
