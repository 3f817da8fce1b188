// Non-geometric effects as an extension of the kinematic model: an ExtendedModel is a
// KinematicModel plus a list of effects, each with its own parameters e [SI], that change the
// joint values the chain sees and/or the lengths of the arm's links:
//
//   q̃ⱼ = qⱼ + Σ_effects on j δⱼ(q, context, e)        effective joint value [rad | m]
//   ℓₖ = (1 + s(context, e)) · ℓₖ,nominal              every translation ET of the arm (thermal)
//   pose = KinematicModel pose at (q̃, x) with the scaled arm ETs
//
// Causes (the issue-6 vocabulary) and their parameters:
//
//   joint_compliance  δⱼ = cⱼ · τⱼ(q, payload)            cⱼ [rad/(N·m)] (prismatic: [m/N])
//                     τⱼ is the gravity torque about joint j of a point-mass model of the arm
//                     (GravityModel: mass per metre of link at the mid-points between joint
//                     origins, the tool mass and the payload at the end of the chain), computed
//                     at the nominal geometry (x = 0) and the joints as read. Positive c: the
//                     joint gives way in the direction gravity pulls.
//   joint_periodic    δⱼ = aₕ sin(h qⱼ) + bₕ cos(h qⱼ)     aₕ, bₕ [rad], harmonic order h = 1 or 2
//                     (gear or encoder eccentricity); one effect per harmonic.
//   joint_scale       δⱼ = sⱼ · qⱼ                          sⱼ [1] (gear-ratio error)
//   backlash          δⱼ = bⱼ · sign(dqⱼ)                   bⱼ [rad | m], half the dead band;
//                     sign(dqⱼ) is the direction of the last motion before the stop (0: unknown)
//   thermal           s = κ (T − T_ref)   (temperature)      κ [1/K], T [°C]
//                     s = ρ (t − t_ref)   (time drift)       ρ [1/s], t [s]
//                     scales the arm's translation ETs: those of the chain that are not part of
//                     the set-up frames (parameter groups base, marker, imu, earth).
//   time_offset       streamed data only (a residual ∝ joint velocity): not a pose-level effect,
//                     not modelled here.
//
// Pose and Jacobians follow kinematics::IdentificationJacobian's convention: rows 0–2 ∂p_WM_W
// [m per unit], rows 3–5 ∂δθ_E [rad per unit] with R_EI(e + de) = Exp(δθ_E)·R_EI(e).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "rcal/kinematics/model.hpp"

namespace rcal::kinematics {

enum class EffectCause { kJointCompliance, kJointPeriodic, kJointScale, kThermal, kBacklash };

/// The vocabulary name: "joint_compliance", "joint_periodic", "joint_scale", "thermal",
/// "backlash".
const char* ToString(EffectCause cause);
/// The cause named `name` (vocabulary above), or nullopt.
std::optional<EffectCause> ParseEffectCause(const std::string& name);

/// What a pose depends on besides the joints as read.
struct EffectContext {
  static constexpr double kAbsent = std::numeric_limits<double>::quiet_NaN();
  double temperature_c = kAbsent;  ///< [°C]; NaN: unknown (thermal by temperature contributes 0)
  double payload_kg = 0.0;         ///< [kg] at the end of the chain; NaN counts as 0
  double time_s = kAbsent;         ///< [s]; NaN: unknown (thermal by time contributes 0)
  Eigen::VectorXi dq_sign;         ///< per joint −1, 0, +1 (last motion); empty: all 0
};

/// The point-mass model behind joint_compliance's gravity torque.
struct GravityModel {
  double link_density_kg_per_m = 10.0;   ///< [kg/m] of chain between consecutive joint origins
  double tool_mass_kg = 0.0;             ///< [kg] always at the end of the chain
  Eigen::Vector3d g_B{0.0, 0.0, -9.81};  ///< gravity [m/s²] in the robot base frame
};

/// One effect: a cause on a joint (or on the whole arm for thermal) and its settings.
struct Effect {
  enum class ThermalSource { kTemperature, kTime };
  EffectCause cause = EffectCause::kJointScale;
  int joint = -1;    ///< joint index (0-based) for joint effects; −1 for thermal
  int harmonic = 1;  ///< joint_periodic: harmonic order h (1 or 2)
  ThermalSource thermal_source = ThermalSource::kTemperature;
  double reference = 20.0;  ///< thermal: T_ref [°C] or t_ref [s]

  /// Number of parameters: 2 for joint_periodic, 1 otherwise.
  int num_params() const { return cause == EffectCause::kJointPeriodic ? 2 : 1; }
  /// Same cause, joint, harmonic and thermal source (parameters aside).
  bool SameAs(const Effect& o) const;
};

/// One effect parameter, for reports.
struct EffectParameter {
  std::string name;  ///< e.g. "joint_compliance.shoulder_lift.c", "joint_periodic.j3.sin2"
  std::string unit;  ///< SI: "rad/(N*m)", "m/N", "rad", "m", "1", "1/K", "1/s"
};

/// A KinematicModel extended with effects. Immutable once built; queries take the joints as read
/// q, the context, the geometric errors x [m | rad] and the effect parameters e [SI, see above].
class ExtendedModel {
 public:
  ExtendedModel() = default;
  /// Throws std::invalid_argument for an effect on a joint the model does not have, a harmonic
  /// other than 1 or 2, or the same effect twice.
  ExtendedModel(KinematicModel base, std::vector<Effect> effects, GravityModel gravity = {});

  const KinematicModel& base() const { return base_; }
  /// The extended model measuring marker `slot` of the base (KinematicModel::ForMarker): the same
  /// effects and parameters. Slot 0 is this model. Throws std::out_of_range for another slot.
  const ExtendedModel& ForMarker(int slot) const;
  const std::vector<Effect>& effects() const { return effects_; }
  const GravityModel& gravity() const { return gravity_; }
  int num_effect_params() const { return num_effect_params_; }
  /// Index in e of the first parameter of effect k.
  int effect_offset(int k) const { return offsets_[k]; }
  /// Names and units of e, in order.
  std::vector<EffectParameter> EffectParameters() const;
  /// A zero effect vector.
  Eigen::VectorXd NoEffects() const { return Eigen::VectorXd::Zero(num_effect_params_); }

  /// Gravity torque τ about each joint [N·m] (prismatic: force along the axis [N]) of the
  /// point-mass model at the nominal geometry, joints as read q, payload [kg] at the tool.
  Eigen::VectorXd GravityTorque(const Eigen::VectorXd& q, double payload_kg) const;

  /// Effective joint values q̃ [rad | m] (file comment).
  Eigen::VectorXd EffectiveJoints(const Eigen::VectorXd& q, const EffectContext& ctx,
                                  const Eigen::VectorXd& e) const;
  /// The thermal length scale s [1] (0 without a thermal effect).
  double LengthScale(const EffectContext& ctx, const Eigen::VectorXd& e) const;

  /// Joints as read that give the effective joints q_eff (fixed-point inversion of
  /// EffectiveJoints; the effects are small). For the IK corrector: solve IK for q̃ on the
  /// geometric model, then command ReadJointsFor(q̃). Thermal scaling is not inverted here.
  Eigen::VectorXd ReadJointsFor(const Eigen::VectorXd& q_eff, const EffectContext& ctx,
                                const Eigen::VectorXd& e, int iterations = 20) const;

  /// Marker position and IMU orientation.
  ToolPose Forward(const Eigen::VectorXd& q, const EffectContext& ctx, const Eigen::VectorXd& x,
                   const Eigen::VectorXd& e) const;
  /// End of the chain in the world frame, T_WT (the frame the IK corrector places).
  Eigen::Isometry3d ToolFrame(const Eigen::VectorXd& q, const EffectContext& ctx,
                              const Eigen::VectorXd& x, const Eigen::VectorXd& e) const;

  /// Analytic Jacobians of the pose (convention in the file comment): J_x 6 × num_params w.r.t.
  /// the geometric errors, J_e 6 × num_effect_params w.r.t. the effect parameters. Either may be
  /// null. `pose`, when not null, receives the pose.
  void Jacobians(const Eigen::VectorXd& q, const EffectContext& ctx, const Eigen::VectorXd& x,
                 const Eigen::VectorXd& e, Eigen::MatrixXd* J_x, Eigen::MatrixXd* J_e,
                 ToolPose* pose = nullptr) const;

 private:
  // ∂q̃/∂e (num_joints × num_effect_params) and ∂s/∂e (row).
  void EffectDerivatives(const Eigen::VectorXd& q, const EffectContext& ctx, Eigen::MatrixXd& dq_de,
                         Eigen::RowVectorXd& ds_de) const;
  void CheckSizes(const Eigen::VectorXd& q, const Eigen::VectorXd& x,
                  const Eigen::VectorXd& e) const;

  KinematicModel base_;
  std::vector<Effect> effects_;
  GravityModel gravity_;
  std::vector<int> offsets_;
  int num_effect_params_ = 0;
  std::vector<bool> arm_translation_;  // per chain ET: scaled by thermal
  std::shared_ptr<const std::vector<ExtendedModel>> marker_views_;  // slots 1 … (primary only)
  int base_end_ = 0;  // first chain ET after the set-up base frame
};

/// Context as a regressor value, for analysis: temperature [°C] or time [s] (NaN when absent).
double ThermalRegressor(const Effect& effect, const EffectContext& ctx);

}  // namespace rcal::kinematics
