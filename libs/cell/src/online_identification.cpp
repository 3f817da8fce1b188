#include "rcal/cell/online_identification.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "rcal/identification/setup_guess.hpp"
#include "rcal/io/effects_json.hpp"
#include "rcal/kinematics/identifiability.hpp"

namespace rcal::cell {

std::vector<int> CellBaseSet(const io::BuiltCell& cell) {
  const kinematics::KinematicModel& model = cell.model;
  const unsigned seed = cell.spec.identifier.base_set_seed;
  // The measurements the cell makes: every marker its position sensor measures, at each of 200
  // joint vectors spread over the limits, with orientation when the cell measures it.
  std::mt19937_64 rng(seed * 1000 + 1);
  std::vector<int> slots;
  for (int id : cell.spec.position.markers)
    if (const int slot = model.MarkerSlot(id); slot >= 0) slots.push_back(slot);
  if (slots.empty()) slots.push_back(0);
  std::vector<kinematics::PoseMeasurement> ms;
  for (const Eigen::VectorXd& q : kinematics::SampleJointsInLimits(model, 200, rng))
    for (int slot : slots) {
      kinematics::PoseMeasurement m;
      m.q = q;
      m.marker = slot;
      m.has_orientation = cell.spec.measures_orientation();
      ms.push_back(m);
    }
  const Eigen::VectorXd x = identification::GenericSetupPlacement(model, model.Nominal(), seed);
  return kinematics::AnalyzeIdentifiability(model, ms, x).identifiable;
}

OnlineIdentification::OnlineIdentification(io::BuiltCell cell,
                                           std::vector<kinematics::Effect> effects,
                                           kinematics::GravityModel gravity)
    : cell_(std::move(cell)),
      guessed_(cell_.Guessed()),
      base_(CellBaseSet(cell_)),
      effects_(std::move(effects)),
      gravity_(gravity),
      start_(cell_.model.Nominal()),
      ekf_(MakeEkf(start_)),
      started_(guessed_.empty()) {
  const int guess_poses = cell_.spec.identifier.guess_poses;
  if (!guessed_.empty() && guess_poses < 3)
    throw std::invalid_argument(cell_.spec.source +
                                ": identifier.guess_poses: " + std::to_string(guess_poses) +
                                ", at least 3 to guess the set-up frames");
  spdlog::debug("cell {}: {} parameters, base set of {}; {}", cell_.spec.name,
                cell_.model.num_params(), base_.size(),
                guessed_.empty()
                    ? std::string("no frame to guess")
                    : "set-up guess from the first " + std::to_string(guess_poses) + " poses");
}

std::unique_ptr<identification::EkfIdentifier> OnlineIdentification::MakeEkf(
    const Eigen::VectorXd& x0) const {
  // Parameters outside the base set stay at x0: the guess for a set-up frame, the drawing for the
  // arm.
  std::unique_ptr<identification::EkfIdentifier> ekf;
  Eigen::VectorXd sigma_e;
  if (effects_.empty()) {
    ekf = std::make_unique<identification::EkfIdentifier>(cell_.model, base_, cell_.ekf, x0);
  } else {
    const kinematics::ExtendedModel ext(cell_.model, effects_, gravity_);
    ekf = std::make_unique<identification::EkfIdentifier>(ext, base_, cell_.ekf, x0);
    sigma_e = cell_.ekf.prior_sigma_effects.size() == ext.num_effect_params()
                  ? cell_.ekf.prior_sigma_effects
                  : identification::DefaultEffectPriorSigma(ext);
  }
  const Eigen::VectorXd sigma = cell_.PriorSigma();
  const auto n = static_cast<Eigen::Index>(base_.size());
  Eigen::VectorXd start = Eigen::VectorXd::Zero(n + sigma_e.size()), var(n + sigma_e.size());
  for (Eigen::Index i = 0; i < n; ++i) {
    start(i) = x0(base_[i]);
    var(i) = sigma(base_[i]) * sigma(base_[i]);
  }
  var.tail(sigma_e.size()) = sigma_e.array().square();  // the effects start at 0
  ekf->SetState(start, var.asDiagonal());
  return ekf;
}

OnlineIdentification::Outcome OnlineIdentification::Add(
    const TimedPose& pose, const std::function<void(const Update&)>& on_update) {
  Outcome out;
  std::string error = kinematics::Validate(model(), pose.z);
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
  if (static_cast<int>(held_.size()) < cell_.spec.identifier.guess_poses) return out;
  std::vector<kinematics::PoseMeasurement> ms;
  for (const auto& h : held_) ms.push_back(h.z);
  const identification::SetupGuess guess = identification::GuessSetup(model(), ms);
  for (int i : guessed_) start_(i) = guess.x(i);  // frames of mode prior/fixed stay nominal
  if (!guess.outliers.empty())
    spdlog::warn("set-up guess: {} of {} poses left out as outliers", guess.outliers.size(),
                 ms.size());
  ekf_ = MakeEkf(start_);
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
  u.result = ekf_->Update(pose.z, pose.context);
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
  if (!held.empty() && (guessed_.empty() || checkpoint.accepted > 0))
    throw std::runtime_error(
        "held: " + std::to_string(held.size()) + " poses held for a set-up guess, but " +
        (guessed_.empty() ? "the cell guesses no frame" : "the EKF has started"));
  ekf_->Restore(checkpoint);
  // The start it ran from (its parameters outside the base set are fixed there).
  if (checkpoint.x_fixed.size() == start_.size()) start_ = checkpoint.x_fixed;
  held_ = std::move(held);
  last_utime_ = last_utime;
  last_pose_index_ = last_pose_index;
  if (ekf_->accepted() > 0 || guessed_.empty()) started_ = true;
}

OnlineIdentification MakeOnlineIdentification(io::BuiltCell cell, const std::string& effects_path) {
  if (effects_path.empty()) return OnlineIdentification(std::move(cell));
  const io::AnalysisEffects ae = io::ReadAnalysisEffects(effects_path, cell.model);
  kinematics::GravityModel gravity;
  if (std::isfinite(ae.link_density_kg_per_m))
    gravity.link_density_kg_per_m = ae.link_density_kg_per_m;
  if (ae.effects.empty())
    spdlog::warn("{}: lists no effect; identifying the geometry alone", effects_path);
  return OnlineIdentification(std::move(cell), ae.effects, gravity);
}

}  // namespace rcal::cell
