#include "rcal/transport/ik_corrector_node.hpp"

#include <algorithm>

#include "rcal/transport/adapters.hpp"

namespace rcal::transport {

IkCorrectorNode::IkCorrectorNode(Transport& t, const kinematics::KinematicModel& model,
                                 Options options)
    : t_(t),
      model_(model),
      o_(std::move(options)),
      calibrated_(model, model.Nominal()),
      nominal_(model, model.Nominal()),
      x_(model.Nominal()),
      health_(o_.name) {
  if (!o_.effects.empty())
    extended_.emplace(kinematics::ExtendedModel(model, o_.effects, o_.gravity), x_,
                      o_.effect_values);
  auto undecodable = [this](const std::string& e) { OnUndecodable(e); };
  t_.Subscribe<kinematic_params_t>(
      o_.params_channel, [this](const kinematic_params_t& m) { OnParams(m); }, undecodable);
  t_.Subscribe<ik_request_t>(
      o_.request_channel, [this](const ik_request_t& m) { OnRequest(m); }, undecodable);
}

void IkCorrectorNode::Reject(const std::string& reason) {
  health_.Rejected(reason);
  health_.Tick(latest_, t_, o_.health_channel);
}

void IkCorrectorNode::OnUndecodable(const std::string& reason) {
  health_.Received();
  Reject(reason);
}

void IkCorrectorNode::OnParams(const kinematic_params_t& msg) {
  health_.Received();
  std::string error;
  const auto values = ParamsFromMessage(msg, model_, &error);
  if (!values) return Reject(error);
  x_ = *values;
  calibrated_.SetParameters(x_);
  if (extended_) extended_->SetParameters(x_, extended_->e());
  params_utime_ = msg.utime;
  latest_ = std::max(latest_, msg.utime);
  health_.Tick(latest_, t_, o_.health_channel);
}

void IkCorrectorNode::OnRequest(const ik_request_t& msg) {
  health_.Received();
  std::string error;
  const auto q = FromMessage(msg, model_.num_joints(), &error);
  if (!q) return Reject(error);
  const auto solve = [&](ik::LevenbergMarquardtIk& s) {
    return q->position_only ? s.SolvePosition(q->T_WT.translation(), q->q_seed)
                            : s.Solve(q->T_WT, q->q_seed);
  };
  auto cal = solve(calibrated_);
  const auto nom = solve(nominal_);
  // Where the nominal answer really puts the tool (the calibrated model is the truth here).
  double nominal_error = (model_.ToolFrame(nom.q, x_).translation() - q->T_WT.translation()).norm();
  if (extended_) {
    kinematics::EffectContext ctx;
    ctx.payload_kg = o_.payload_kg;
    ctx.temperature_c = o_.temperature_c;
    ctx.time_s = static_cast<double>(msg.utime) * 1e-6;
    ctx.dq_sign = Eigen::VectorXi::Zero(model_.num_joints());
    for (int j = 0; j < model_.num_joints(); ++j) {
      const double step = cal.q(j) - q->q_seed(j);
      ctx.dq_sign(j) = step > 0 ? 1 : step < 0 ? -1 : 0;
    }
    cal = q->position_only ? extended_->SolvePosition(q->T_WT.translation(), cal.q, ctx)
                           : extended_->Solve(q->T_WT, cal.q, ctx);
    nominal_error = (extended_->model().ToolFrame(nom.q, ctx, x_, extended_->e()).translation() -
                     q->T_WT.translation())
                        .norm();
  }
  if (t_.Publish(o_.command_channel, ToIkCommand(msg, cal, nom, nominal_error, params_utime_)))
    health_.Published();
  latest_ = std::max(latest_, msg.utime);
  health_.Tick(latest_, t_, o_.health_channel);
}

}  // namespace rcal::transport
