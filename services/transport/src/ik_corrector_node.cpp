#include "rcal/transport/ik_corrector_node.hpp"

#include <algorithm>

#include "rcal/estimation/time_gate.hpp"
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

void IkCorrectorNode::Announce() {
  health_.Published();
  t_.Publish(o_.health_channel, health_.Message(0));
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
  // Effect values identified live (ekf_identifier --effects) replace the options' when they are
  // this model's effects; an estimate without any keeps them; others are refused.
  std::optional<Eigen::VectorXd> effects;
  if (extended_ && msg.num_effect_params > 0) {
    effects = EffectsFromMessage(msg, extended_->model(), &error);
    if (!effects) return Reject(error);
  }
  if (const int64_t ceiling = estimation::HostCeilingUs(); msg.utime > ceiling) {
    health_.OutOfHorizon("kinematic_params.utime: " + std::to_string(msg.utime) +
                         " is beyond the time ceiling (" + std::to_string(ceiling) + ")");
    health_.Tick(latest_, t_, o_.health_channel);
    return;
  }
  const std::pair<int32_t, int64_t> order{msg.poses_used, msg.utime};
  const std::pair<int32_t, int64_t> in_use{params_poses_used_, params_utime_};
  if (params_poses_used_ >= 0 && order == in_use) {
    health_.Duplicate("kinematic_params: poses_used " + std::to_string(msg.poses_used) +
                      ", utime " + std::to_string(msg.utime) + " duplicates the estimate in use");
    health_.Tick(latest_, t_, o_.health_channel);
    return;
  }
  if (params_poses_used_ >= 0 && order < in_use) {
    // Stale, unless a run of them says the identifier started over.
    stale_run_ = stale_run_ > 0 && order > stale_last_ ? stale_run_ + 1 : 1;
    stale_last_ = order;
    if (stale_run_ < std::max(1, o_.restart_params)) {
      health_.Stale("kinematic_params: poses_used " + std::to_string(msg.poses_used) + ", utime " +
                    std::to_string(msg.utime) + " is older than the estimate in use (poses_used " +
                    std::to_string(params_poses_used_) + ", utime " +
                    std::to_string(params_utime_) + ")");
      health_.Tick(latest_, t_, o_.health_channel);
      return;
    }
    health_.Resync("kinematic_params: the identifier started over (" + std::to_string(stale_run_) +
                   " newer estimates in a row from poses_used " + std::to_string(msg.poses_used) +
                   ")");
  }
  Use(msg, *values, effects);
}

void IkCorrectorNode::Use(const kinematic_params_t& msg, const Eigen::VectorXd& values,
                          const std::optional<Eigen::VectorXd>& effects) {
  stale_run_ = 0;
  x_ = values;
  calibrated_.SetParameters(x_);
  if (extended_) extended_->SetParameters(x_, effects ? *effects : extended_->e());
  params_utime_ = msg.utime;
  params_poses_used_ = msg.poses_used;
  latest_ = std::max(latest_, msg.utime);
  health_.Tick(latest_, t_, o_.health_channel);
}

void IkCorrectorNode::OnRequest(const ik_request_t& msg) {
  health_.Received();
  std::string error;
  const auto q = FromMessage(msg, model_.num_joints(), &error);
  if (!q) return Reject(error);
  if (last_request_ && *last_request_ == std::make_pair(msg.request_id, msg.utime)) {
    health_.Duplicate("ik_request: request_id " + std::to_string(msg.request_id) + ", utime " +
                      std::to_string(msg.utime) + " duplicates the last request");
    health_.Tick(latest_, t_, o_.health_channel);
    return;
  }
  last_request_ = std::make_pair(msg.request_id, msg.utime);
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
