#include "rcal/kinematics/joint_effects.hpp"

#include <cmath>
#include <stdexcept>

namespace rcal::kinematics {
namespace {

double OrZero(double v) {
  return std::isfinite(v) ? v : 0.0;
}

}  // namespace

const char* ToString(EffectCause cause) {
  switch (cause) {
    case EffectCause::kJointCompliance:
      return "joint_compliance";
    case EffectCause::kJointPeriodic:
      return "joint_periodic";
    case EffectCause::kJointScale:
      return "joint_scale";
    case EffectCause::kThermal:
      return "thermal";
    case EffectCause::kBacklash:
      return "backlash";
  }
  return "?";
}

std::optional<EffectCause> ParseEffectCause(const std::string& name) {
  for (EffectCause c : {EffectCause::kJointCompliance, EffectCause::kJointPeriodic,
                        EffectCause::kJointScale, EffectCause::kThermal, EffectCause::kBacklash})
    if (name == ToString(c)) return c;
  return std::nullopt;
}

bool Effect::SameAs(const Effect& o) const {
  if (cause != o.cause) return false;
  if (cause == EffectCause::kThermal) return thermal_source == o.thermal_source;
  if (joint != o.joint) return false;
  return cause != EffectCause::kJointPeriodic || harmonic == o.harmonic;
}

double ThermalRegressor(const Effect& effect, const EffectContext& ctx) {
  return effect.thermal_source == Effect::ThermalSource::kTemperature ? ctx.temperature_c
                                                                      : ctx.time_s;
}

ExtendedModel::ExtendedModel(KinematicModel base, std::vector<Effect> effects, GravityModel gravity)
    : base_(std::move(base)), effects_(std::move(effects)), gravity_(std::move(gravity)) {
  for (size_t k = 0; k < effects_.size(); ++k) {
    const Effect& f = effects_[k];
    if (f.cause != EffectCause::kThermal && (f.joint < 0 || f.joint >= base_.num_joints()))
      throw std::invalid_argument(std::string("effect ") + ToString(f.cause) + ": joint index " +
                                  std::to_string(f.joint) + " not in model '" + base_.name() + "'");
    if (f.cause == EffectCause::kJointPeriodic && f.harmonic != 1 && f.harmonic != 2)
      throw std::invalid_argument("effect joint_periodic: harmonic must be 1 or 2");
    for (size_t l = 0; l < k; ++l)
      if (effects_[l].SameAs(f))
        throw std::invalid_argument(std::string("effect ") + ToString(f.cause) + " given twice");
    offsets_.push_back(num_effect_params_);
    num_effect_params_ += f.num_params();
  }
  // The arm's translation ETs: chain ETs after the base frame that are not set-up parameters.
  const auto& chain = base_.ets(Segment::kChain);
  base_end_ = 0;
  for (size_t k = 0; k < chain.size(); ++k)
    if (chain[k].param >= 0 && base_.parameters()[chain[k].param].group == "base")
      base_end_ = static_cast<int>(k) + 1;
  arm_translation_.assign(chain.size(), false);
  for (size_t k = base_end_; k < chain.size(); ++k) {
    const auto& et = chain[k];
    if (et.kind != ElementaryTransform::Kind::kTranslation) continue;
    arm_translation_[k] = et.param < 0 || !IsSetupGroup(base_.parameters()[et.param].group);
  }
  if (base_.marker_slot() == 0 && base_.markers().size() > 1) {
    auto views = std::make_shared<std::vector<ExtendedModel>>();
    for (size_t k = 1; k < base_.markers().size(); ++k)
      views->emplace_back(base_.ForMarker(static_cast<int>(k)), effects_, gravity_);
    marker_views_ = std::move(views);
  }
}

const ExtendedModel& ExtendedModel::ForMarker(int slot) const {
  if (slot == base_.marker_slot()) return *this;
  if (!marker_views_ || slot < 1 || slot > static_cast<int>(marker_views_->size()))
    throw std::out_of_range("marker slot " + std::to_string(slot) + " not in extended model of '" +
                            base_.name() + "'");
  return (*marker_views_)[slot - 1];
}

std::vector<EffectParameter> ExtendedModel::EffectParameters() const {
  std::vector<EffectParameter> out;
  for (const Effect& f : effects_) {
    const std::string cause = ToString(f.cause);
    if (f.cause == EffectCause::kThermal) {
      if (f.thermal_source == Effect::ThermalSource::kTemperature)
        out.push_back({cause + ".temperature.kappa", "1/K"});
      else
        out.push_back({cause + ".time.rate", "1/s"});
      continue;
    }
    const Joint& j = base_.joints()[f.joint];
    const bool rev = j.type == JointType::kRevolute;
    const std::string p = cause + "." + j.name + ".";
    switch (f.cause) {
      case EffectCause::kJointCompliance:
        out.push_back({p + "c", rev ? "rad/(N*m)" : "m/N"});
        break;
      case EffectCause::kJointPeriodic:
        out.push_back({p + "sin" + std::to_string(f.harmonic), rev ? "rad" : "m"});
        out.push_back({p + "cos" + std::to_string(f.harmonic), rev ? "rad" : "m"});
        break;
      case EffectCause::kJointScale:
        out.push_back({p + "s", "1"});
        break;
      case EffectCause::kBacklash:
        out.push_back({p + "b", rev ? "rad" : "m"});
        break;
      case EffectCause::kThermal:
        break;
    }
  }
  return out;
}

void ExtendedModel::CheckSizes(const Eigen::VectorXd& q, const Eigen::VectorXd& x,
                               const Eigen::VectorXd& e) const {
  if (q.size() != base_.num_joints())
    throw std::invalid_argument("q has " + std::to_string(q.size()) + " joints, model '" +
                                base_.name() + "' has " + std::to_string(base_.num_joints()));
  if (x.size() != base_.num_params())
    throw std::invalid_argument("x has " + std::to_string(x.size()) + " parameters, model '" +
                                base_.name() + "' has " + std::to_string(base_.num_params()));
  if (e.size() != num_effect_params_)
    throw std::invalid_argument("e has " + std::to_string(e.size()) +
                                " effect parameters, the extended model has " +
                                std::to_string(num_effect_params_));
}

Eigen::VectorXd ExtendedModel::GravityTorque(const Eigen::VectorXd& q, double payload_kg) const {
  const int n = base_.num_joints();
  if (q.size() != n) throw std::invalid_argument("GravityTorque: wrong joint count");
  const auto& chain = base_.ets(Segment::kChain);
  // Walk the nominal chain: joint origins o_j and axes w_j (world), the end of the chain.
  std::vector<Eigen::Vector3d> o(n, Eigen::Vector3d::Zero()), w(n, Eigen::Vector3d::UnitZ());
  std::vector<int> order;  // joints in chain order
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  Eigen::Matrix3d R_WB = Eigen::Matrix3d::Identity();
  for (size_t k = 0; k < chain.size(); ++k) {
    if (static_cast<int>(k) == base_end_) R_WB = T.linear();
    const auto& et = chain[k];
    double v = et.nominal;
    if (et.joint >= 0) {
      v += q(et.joint);
      o[et.joint] = T.translation();
      w[et.joint] = T.linear() * et.axis;
      order.push_back(et.joint);
    }
    T = T * EtTransform(et, v);
  }
  if (static_cast<int>(chain.size()) == base_end_) R_WB = T.linear();
  const Eigen::Vector3d g_W = R_WB * gravity_.g_B;
  const Eigen::Vector3d p_end = T.translation();
  // Point masses, each carried by the joints before it in the chain.
  struct Mass {
    Eigen::Vector3d p;
    double m;
    size_t after;  // index in `order` of the last joint before it
  };
  std::vector<Mass> masses;
  for (size_t i = 0; i < order.size(); ++i) {
    const Eigen::Vector3d a = o[order[i]];
    const Eigen::Vector3d b = i + 1 < order.size() ? o[order[i + 1]] : p_end;
    masses.push_back({0.5 * (a + b), gravity_.link_density_kg_per_m * (b - a).norm(), i});
  }
  if (!order.empty())
    masses.push_back({p_end, gravity_.tool_mass_kg + OrZero(payload_kg), order.size() - 1});
  Eigen::VectorXd tau = Eigen::VectorXd::Zero(n);
  for (size_t i = 0; i < order.size(); ++i) {
    const int j = order[i];
    const bool rev = base_.joints()[j].type == JointType::kRevolute;
    for (const Mass& m : masses) {
      if (m.after < i) continue;
      const Eigen::Vector3d F = m.m * g_W;
      tau(j) += rev ? w[j].dot((m.p - o[j]).cross(F)) : w[j].dot(F);
    }
  }
  return tau;
}

void ExtendedModel::EffectDerivatives(const Eigen::VectorXd& q, const EffectContext& ctx,
                                      Eigen::MatrixXd& dq_de, Eigen::RowVectorXd& ds_de) const {
  dq_de = Eigen::MatrixXd::Zero(base_.num_joints(), num_effect_params_);
  ds_de = Eigen::RowVectorXd::Zero(num_effect_params_);
  Eigen::VectorXd tau;
  for (size_t k = 0; k < effects_.size(); ++k) {
    const Effect& f = effects_[k];
    const int o = offsets_[k], j = f.joint;
    switch (f.cause) {
      case EffectCause::kJointCompliance:
        if (tau.size() == 0) tau = GravityTorque(q, ctx.payload_kg);
        dq_de(j, o) = tau(j);
        break;
      case EffectCause::kJointPeriodic:
        dq_de(j, o) = std::sin(f.harmonic * q(j));
        dq_de(j, o + 1) = std::cos(f.harmonic * q(j));
        break;
      case EffectCause::kJointScale:
        dq_de(j, o) = q(j);
        break;
      case EffectCause::kBacklash:
        dq_de(j, o) = j < ctx.dq_sign.size() ? static_cast<double>(ctx.dq_sign(j)) : 0.0;
        break;
      case EffectCause::kThermal:
        ds_de(o) = OrZero(ThermalRegressor(f, ctx) - f.reference);
        break;
    }
  }
}

Eigen::VectorXd ExtendedModel::EffectiveJoints(const Eigen::VectorXd& q, const EffectContext& ctx,
                                               const Eigen::VectorXd& e) const {
  CheckSizes(q, base_.Nominal(), e);
  Eigen::MatrixXd dq_de;
  Eigen::RowVectorXd ds_de;
  EffectDerivatives(q, ctx, dq_de, ds_de);
  return q + dq_de * e;  // every effect is linear in its parameters
}

double ExtendedModel::LengthScale(const EffectContext& ctx, const Eigen::VectorXd& e) const {
  double s = 0;
  for (size_t k = 0; k < effects_.size(); ++k)
    if (effects_[k].cause == EffectCause::kThermal)
      s += e(offsets_[k]) * OrZero(ThermalRegressor(effects_[k], ctx) - effects_[k].reference);
  return s;
}

Eigen::VectorXd ExtendedModel::ReadJointsFor(const Eigen::VectorXd& q_eff, const EffectContext& ctx,
                                             const Eigen::VectorXd& e, int iterations) const {
  Eigen::VectorXd q = q_eff;
  for (int it = 0; it < iterations; ++it) q = q_eff - (EffectiveJoints(q, ctx, e) - q);
  return q;
}

ToolPose ExtendedModel::Forward(const Eigen::VectorXd& q, const EffectContext& ctx,
                                const Eigen::VectorXd& x, const Eigen::VectorXd& e) const {
  ToolPose pose;
  Jacobians(q, ctx, x, e, nullptr, nullptr, &pose);
  return pose;
}

Eigen::Isometry3d ExtendedModel::ToolFrame(const Eigen::VectorXd& q, const EffectContext& ctx,
                                           const Eigen::VectorXd& x,
                                           const Eigen::VectorXd& e) const {
  CheckSizes(q, x, e);
  const Eigen::VectorXd qe = EffectiveJoints(q, ctx, e);
  const double s = LengthScale(ctx, e);
  const auto& chain = base_.ets(Segment::kChain);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (size_t k = 0; k < chain.size(); ++k) {
    const auto& et = chain[k];
    double v = et.nominal * (arm_translation_[k] ? 1.0 + s : 1.0);
    if (et.param >= 0) v += x(et.param);
    if (et.joint >= 0) v += qe(et.joint);
    T = T * EtTransform(et, v);
  }
  return T;
}

void ExtendedModel::Jacobians(const Eigen::VectorXd& q, const EffectContext& ctx,
                              const Eigen::VectorXd& x, const Eigen::VectorXd& e,
                              Eigen::MatrixXd* J_x, Eigen::MatrixXd* J_e, ToolPose* pose) const {
  CheckSizes(q, x, e);
  Eigen::MatrixXd dq_de;
  Eigen::RowVectorXd ds_de;
  EffectDerivatives(q, ctx, dq_de, ds_de);
  const Eigen::VectorXd qe = q + dq_de * e;
  const double s = ds_de.dot(e);
  const auto value = [&](const ElementaryTransform& et, bool arm) {
    double v = et.nominal * (arm ? 1.0 + s : 1.0);
    if (et.param >= 0) v += x(et.param);
    if (et.joint >= 0) v += qe(et.joint);
    return v;
  };
  const auto& chain = base_.ets(Segment::kChain);
  const auto& earth = base_.ets(Segment::kEarth);
  const auto& imu = base_.ets(Segment::kImu);
  std::vector<Eigen::Isometry3d> T(chain.size() + 1, Eigen::Isometry3d::Identity());
  for (size_t k = 0; k < chain.size(); ++k)
    T[k + 1] = T[k] * EtTransform(chain[k], value(chain[k], arm_translation_[k]));
  std::vector<Eigen::Matrix3d> R_E(earth.size() + 1, Eigen::Matrix3d::Identity());
  for (size_t k = 0; k < earth.size(); ++k)
    R_E[k + 1] = R_E[k] * EtTransform(earth[k], value(earth[k], false)).linear();
  std::vector<Eigen::Matrix3d> R_I(imu.size() + 1, Eigen::Matrix3d::Identity());
  for (size_t k = 0; k < imu.size(); ++k)
    R_I[k + 1] = R_I[k] * EtTransform(imu[k], value(imu[k], false)).linear();
  const Eigen::Vector3d p_end = T.back().translation();
  const Eigen::Matrix3d R_EW = R_E.back();
  const Eigen::Matrix3d R_EF = R_EW * T.back().linear();
  if (pose) {
    pose->p_WM_W = p_end;
    pose->R_EI = R_EF * R_I.back();
  }
  if (!J_x && !J_e) return;

  const int n = base_.num_joints();
  Eigen::MatrixXd Jx = Eigen::MatrixXd::Zero(6, base_.num_params());
  Eigen::MatrixXd Jq = Eigen::MatrixXd::Zero(6, n);
  Eigen::Matrix<double, 6, 1> Js = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 1> col;
  for (size_t k = 0; k < chain.size(); ++k) {
    const auto& et = chain[k];
    const Eigen::Vector3d a_W = T[k].linear() * et.axis;
    if (et.kind == ElementaryTransform::Kind::kTranslation) {
      col << a_W, Eigen::Vector3d::Zero();
    } else {
      col << a_W.cross(p_end - T[k].translation()), R_EW * a_W;
    }
    if (et.param >= 0) Jx.col(et.param) += col;
    if (et.joint >= 0) Jq.col(et.joint) += col;
    if (arm_translation_[k]) Js += et.nominal * col;
  }
  for (size_t k = 0; k < earth.size(); ++k) {
    if (earth[k].param < 0 || earth[k].kind != ElementaryTransform::Kind::kRotation) continue;
    col << Eigen::Vector3d::Zero(), R_E[k] * earth[k].axis;
    Jx.col(earth[k].param) += col;
  }
  for (size_t k = 0; k < imu.size(); ++k) {
    if (imu[k].param < 0 || imu[k].kind != ElementaryTransform::Kind::kRotation) continue;
    col << Eigen::Vector3d::Zero(), R_EF * R_I[k] * imu[k].axis;
    Jx.col(imu[k].param) += col;
  }
  if (J_x) *J_x = Jx;
  if (J_e) *J_e = Jq * dq_de + Js * ds_de;
}

}  // namespace rcal::kinematics
