#include "rcal/ik/extended_ik.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace rcal::ik {
namespace {

// The geometric solver is built before the checks run: give it a valid x either way.
Eigen::VectorXd UsableX(const kinematics::ExtendedModel& model, const Eigen::VectorXd& x) {
  return x.size() == model.base().num_params() && x.allFinite() ? x : model.base().Nominal();
}

}  // namespace

ExtendedIk::ExtendedIk(kinematics::ExtendedModel model, const Eigen::VectorXd& x,
                       const Eigen::VectorXd& e, IkSettings settings)
    : LevenbergMarquardtIk(model.base(), UsableX(model, x), settings),
      model_(std::move(model)),
      x_(x),
      e_(e) {
  Check(x, e);
}

void ExtendedIk::Check(const Eigen::VectorXd& x, const Eigen::VectorXd& e) const {
  if (x.size() != model_.base().num_params() || !x.allFinite())
    throw std::invalid_argument("x: expected " + std::to_string(model_.base().num_params()) +
                                " finite values, got " + std::to_string(x.size()));
  if (e.size() != model_.num_effect_params() || !e.allFinite())
    throw std::invalid_argument("e: expected " + std::to_string(model_.num_effect_params()) +
                                " finite values, got " + std::to_string(e.size()));
}

void ExtendedIk::SetParameters(const Eigen::VectorXd& x, const Eigen::VectorXd& e) {
  Check(x, e);
  x_ = x;
  e_ = e;
  LevenbergMarquardtIk::SetParameters(x);
}

std::string ExtendedIk::CheckContext(const kinematics::EffectContext& c) const {
  const int n = num_joints();
  if (c.dq_sign.size() != 0 && c.dq_sign.size() != n)
    return "context.dq_sign: " + std::to_string(c.dq_sign.size()) + " values, expected " +
           std::to_string(n) + " or none";
  if (std::isinf(c.temperature_c)) return "context.temperature_c: infinite";
  if (std::isinf(c.time_s)) return "context.time_s: infinite";
  if (std::isinf(c.payload_kg)) return "context.payload_kg: infinite";
  return "";
}

bool ExtendedIk::Prepare(const kinematics::EffectContext& context, const Eigen::VectorXd& q_seed,
                         IkResult& refused) {
  std::string why = CheckContext(context);
  if (why.empty()) {
    context_ = context;
    return true;
  }
  refused.q = q_seed;
  refused.status = IkStatus::kInvalidInput;
  refused.reason = std::move(why);
  return false;
}

IkResult ExtendedIk::Solve(const Eigen::Isometry3d& T_WT_target, const Eigen::VectorXd& q_seed,
                           const kinematics::EffectContext& context) {
  IkResult refused;
  return Prepare(context, q_seed, refused) ? LevenbergMarquardtIk::Solve(T_WT_target, q_seed)
                                           : refused;
}

IkResult ExtendedIk::SolvePosition(const Eigen::Vector3d& p_WT_W, const Eigen::VectorXd& q_seed,
                                   const kinematics::EffectContext& context) {
  IkResult refused;
  return Prepare(context, q_seed, refused) ? LevenbergMarquardtIk::SolvePosition(p_WT_W, q_seed)
                                           : refused;
}

void ExtendedIk::Evaluate(const Eigen::VectorXd& q, Eigen::Isometry3d& T_WT,
                          kinematics::CompiledChain::Jacobian* J) const {
  if (J) {
    Eigen::Isometry3d T_chain;
    chain().JointJacobian(model_.EffectiveJoints(q, context_, e_), *J, &T_chain);
  }
  T_WT = model_.ToolFrame(q, context_, x_, e_);
}

}  // namespace rcal::ik
