#include "rcal/cell/online_identification.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "rcal/kinematics/identifiability.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::cell {
namespace {

// The identifiable base set at a seeded joint sample around the nominal (`rcal experiment
// paper`'s choice).
std::vector<int> GenericBaseSet(const kinematics::KinematicModel& model,
                                const OnlineIdentificationSettings& s) {
  sim::Rng rng_id(s.ident_seed * 1000 + 1);
  const auto report = kinematics::AnalyzeIdentifiability(
      model, sim::SampleJoints(model, 200, rng_id), model.Nominal(),
      s.position_only ? kinematics::MeasurementKind::kPositionOnly
                      : kinematics::MeasurementKind::kFullPose);
  spdlog::debug("identifiable: rank {} of {} (condition number {:.1f})", report.rank,
                model.num_params(), report.condition_number);
  return report.identifiable;
}

}  // namespace

OnlineIdentification::OnlineIdentification(const io::RobotSpec& robot,
                                           const kinematics::KinematicModel& robot_model,
                                           const OnlineIdentificationSettings& settings)
    : settings_(settings),
      cell_(settings.cell_seed > 0 ? std::optional<Cell>(MakeCell(robot, settings.cell_seed))
                                   : std::nullopt),
      model_(cell_ ? cell_->model : robot_model),
      base_(cell_ ? cell_->base : GenericBaseSet(model_, settings)),
      ekf_(cell_
               ? std::make_unique<identification::EkfIdentifier>(MakeEkf(*cell_, model_.Nominal()))
               : std::make_unique<identification::EkfIdentifier>(model_, base_)),
      started_(!cell_) {
  if (settings.guess_poses < 1)
    throw std::invalid_argument("guess_poses: " + std::to_string(settings.guess_poses) +
                                ", at least 1");
  if (cell_)
    spdlog::debug(
        "cell of seed {}: {} parameters, base set of {}; set-up guess from the first {} "
        "poses",
        settings.cell_seed, model_.num_params(), base_.size(), settings.guess_poses);
}

OnlineIdentification::Outcome OnlineIdentification::Add(
    const TimedPose& pose, const std::function<void(const Update&)>& on_update) {
  Outcome out;
  std::string error = kinematics::Validate(model_, pose.z);
  if (error.empty() && pose.utime <= last_utime_)
    error = "pose_measurement.utime: " + std::to_string(pose.utime) +
            " is not after the last pose (" + std::to_string(last_utime_) + ")";
  if (!error.empty()) {
    out.rejected = error;
    return out;
  }
  const auto apply = [&](const TimedPose& p) {
    out.updates.push_back(Apply(p));
    if (on_update) on_update(out.updates.back());
  };
  if (started_) {
    apply(pose);
    return out;
  }
  // Held back for the set-up guess (time order checked against the held poses too).
  last_utime_ = pose.utime;
  last_pose_index_ = pose.pose_index;
  held_.push_back(pose);
  out.held = true;
  if (static_cast<int>(held_.size()) < settings_.guess_poses) return out;
  std::vector<kinematics::PoseMeasurement> ms;
  for (const auto& h : held_) ms.push_back(h.z);
  ekf_ = std::make_unique<identification::EkfIdentifier>(MakeEkf(*cell_, SetupGuess(*cell_, ms)));
  started_ = true;
  out.started = true;
  const std::vector<TimedPose> held = std::move(held_);
  held_.clear();
  for (const auto& h : held) apply(h);
  return out;
}

OnlineIdentification::Update OnlineIdentification::Apply(const TimedPose& pose) {
  Update u;
  u.utime = pose.utime;
  u.pose_index = pose.pose_index;
  u.dimension = pose.z.dimension();
  const Eigen::VectorXd x_before = ekf_->x();
  u.result = ekf_->Update(pose.z);
  if (!u.result.accepted) return u;
  last_utime_ = pose.utime;
  last_pose_index_ = pose.pose_index;
  const Eigen::VectorXd dx = ekf_->x() - x_before, sigma = ekf_->sigma();
  for (int i : base_)
    u.max_step_sigma = std::max(u.max_step_sigma, std::abs(dx(i)) / std::max(sigma(i), 1e-300));
  return u;
}

void OnlineIdentification::Restore(const identification::EkfCheckpoint& checkpoint,
                                   std::vector<TimedPose> held, int64_t last_utime,
                                   int64_t last_pose_index) {
  if (!held.empty() && (!cell_ || checkpoint.accepted > 0))
    throw std::runtime_error("held: " + std::to_string(held.size()) +
                             " poses held for a set-up guess, but " +
                             (cell_ ? "the EKF has started" : "there is no cell"));
  ekf_->Restore(checkpoint);
  held_ = std::move(held);
  last_utime_ = last_utime;
  last_pose_index_ = last_pose_index;
  if (ekf_->accepted() > 0) started_ = true;
}

}  // namespace rcal::cell
