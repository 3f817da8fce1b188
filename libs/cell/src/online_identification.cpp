#include "rcal/cell/online_identification.hpp"

#include <Eigen/Eigenvalues>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "rcal/identification/chi_square.hpp"
#include "rcal/identification/extended_measurement.hpp"
#include "rcal/identification/setup_guess.hpp"
#include "rcal/identification/tracking.hpp"
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

namespace {
bool SameMeasurement(const kinematics::PoseMeasurement& a, const kinematics::PoseMeasurement& b) {
  return a.marker == b.marker && a.q.size() == b.q.size() && a.q == b.q && a.p_WM_W == b.p_WM_W &&
         a.has_orientation == b.has_orientation && (!a.has_orientation || a.R_EI == b.R_EI);
}
}  // namespace

OnlineIdentification::Update OnlineIdentification::Apply(const TimedPose& pose) {
  Update u;
  u.utime = pose.utime;
  u.pose_index = pose.pose_index;
  u.dimension = pose.z.dimension();
  const Eigen::VectorXd x_before = ekf_->x();
  u.result = ekf_->Update(pose.z, pose.context);
  const bool gated = !u.result.accepted && u.result.gate > 0 && u.result.nis > u.result.gate;
  if (u.result.accepted || gated) {
    seen_.push_back(pose);
    // Older than the window's first pose: folded into the prior, no longer the window's.
    const auto& history = ekf_->history();
    while (!seen_.empty() && seen_.size() > history.size() &&
           (history.empty() || !SameMeasurement(seen_.front().z, history.front())))
      seen_.pop_front();
    // Bounded: an arm the gate refuses pose after pose (a change not detected) must not grow it
    // without end; at most as many refused poses as the window holds (and 100), the oldest
    // refused one dropped first (never a pose of the window: the entries of seen_ that are the
    // history's, in order, are its poses; the others are refused ones).
    while (seen_.size() > history.size() + std::max<size_t>(history.size(), 100)) {
      size_t h = 0, i = 0;
      while (i < seen_.size() && h < history.size() && SameMeasurement(seen_[i].z, history[h])) {
        ++h;
        ++i;
      }
      if (i >= seen_.size()) break;  // nothing refused left to drop
      seen_.erase(seen_.begin() + static_cast<std::ptrdiff_t>(i));
    }
  }
  if (u.result.change) {
    // The release's onset: the window's entry onset_poses_ago before this pose (the history's
    // tail is the poses the change test took, retaken from the onset on). Kept to name the
    // change should SwitchIn withdraw it; at most as many as the window can hold releases.
    const auto& history = ekf_->history();
    const auto back = static_cast<size_t>(u.result.change->onset_poses_ago);
    if (back < history.size())
      releases_.push_back({history[history.size() - 1 - back],
                           identification::ChangeNames(cell_.model, *u.result.change)});
    while (releases_.size() > std::max<size_t>(history.size(), 1)) releases_.pop_front();
  }
  if (u.result.reattributed && !releases_.empty()) {  // the second look renamed the latest
    releases_.back().names = identification::ChangeNames(cell_.model, *u.result.reattributed);
  }
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
  // The window as restored: its accepted poses (the refused ones between them are not kept).
  seen_.clear();
  for (size_t k = 0; k < checkpoint.history.size(); ++k)
    seen_.push_back(
        {checkpoint.history[k], 0, -1,
         k < checkpoint.contexts.size() ? checkpoint.contexts[k] : kinematics::EffectContext{}});
  // The start it ran from (its parameters outside the base set are fixed there).
  if (checkpoint.x_fixed.size() == start_.size()) start_ = checkpoint.x_fixed;
  held_ = std::move(held);
  last_utime_ = last_utime;
  last_pose_index_ = last_pose_index;
  if (ekf_->accepted() > 0 || guessed_.empty()) started_ = true;
}

size_t OnlineIdentification::WindowStart() const {
  const auto& history = ekf_->history();
  if (history.empty()) return seen_.size();
  for (size_t i = 0; i < seen_.size(); ++i)
    if (SameMeasurement(seen_[i].z, history.front())) return i;
  // The window's first poses were dropped from seen_ (its bound): the poses as they arrived since.
  return 0;
}

std::vector<TimedPose> OnlineIdentification::Window() const {
  return std::vector<TimedPose>(seen_.begin() + static_cast<std::ptrdiff_t>(WindowStart()),
                                seen_.end());
}

int OnlineIdentification::WindowSize() const {
  return static_cast<int>(seen_.size() - WindowStart());
}

std::vector<identification::GeometryStep> OnlineIdentification::WindowSteps() const {
  std::vector<identification::GeometryStep> steps;
  const auto& history = ekf_->history();
  const auto& inflations = ekf_->inflations();
  const auto& identified = ekf_->identified();
  const int ng = static_cast<int>(identified.size());
  const size_t start = WindowStart();
  for (size_t k = 0; k < history.size() && k < inflations.size(); ++k) {
    if (inflations[k].size() == 0) continue;
    int first = -1;
    for (size_t i = start; i < seen_.size() && first < 0; ++i)
      if (SameMeasurement(seen_[i].z, history[k])) first = static_cast<int>(i - start);
    if (first < 1) continue;
    // The released directions, in the geometric parameters.
    const Eigen::MatrixXd U =
        identification::InflationDirections(Eigen::MatrixXd(inflations[k].topLeftCorner(ng, ng)));
    if (U.cols() == 0) continue;
    identification::GeometryStep st;
    st.first_pose = first;
    st.directions = Eigen::MatrixXd::Zero(cell_.model.num_params(), U.cols());
    for (int r = 0; r < ng; ++r) st.directions.row(identified[r]) = U.row(r);
    steps.push_back(std::move(st));
  }
  return steps;
}

std::vector<kinematics::Effect> OnlineIdentification::SwitchIn(
    const std::vector<kinematics::Effect>& effects) {
  withdrawn_.clear();
  std::vector<kinematics::Effect> added, all = effects_;
  for (const auto& e : effects) {
    const auto same = [&](const kinematics::Effect& o) { return o.SameAs(e); };
    if (std::none_of(all.begin(), all.end(), same)) {
      all.push_back(e);
      added.push_back(e);
    }
  }
  if (added.empty()) return added;
  if (!started_ || (ekf_->accepted() == 0 && ekf_->history().empty())) {
    // Nothing identified yet (a restart about to restore a checkpoint of the extended model, or
    // the set-up guess still holding poses): the EKF simply starts with the effects.
    const kinematics::ExtendedModel check(cell_.model, all, gravity_);  // throws, nothing changed
    effects_ = all;
    ekf_ = MakeEkf(start_);
    return added;
  }
  const identification::EkfCheckpoint old = ekf_->Checkpoint();
  const kinematics::ExtendedModel& old_ext = ekf_->extended_model();
  // Old state index of each new state entry (−1: a new effect parameter): the base set first,
  // then each effect's parameters at its offset.
  const auto n = static_cast<int>(base_.size());
  const kinematics::ExtendedModel new_ext(cell_.model, all, gravity_);  // throws, nothing changed
  std::vector<int> from(n + new_ext.num_effect_params(), -1);
  for (int i = 0; i < n; ++i) from[i] = i;
  for (size_t k = 0; k < old_ext.effects().size(); ++k)
    for (int j = 0; j < old_ext.effects()[k].num_params(); ++j)
      from[n + new_ext.effect_offset(static_cast<int>(k)) + j] =
          n + old_ext.effect_offset(static_cast<int>(k)) + j;  // old effects keep their order
  std::vector<kinematics::Effect> kept = effects_;
  effects_ = all;
  std::unique_ptr<identification::EkfIdentifier> ekf = MakeEkf(start_);
  identification::EkfCheckpoint c = ekf->Checkpoint();  // the new parameters' prior
  const auto m = static_cast<Eigen::Index>(from.size());
  for (Eigen::Index i = 0; i < m; ++i) {
    if (from[i] < 0) continue;
    c.x0(i) = old.x0(from[i]);
    c.x(i) = old.x(from[i]);
    c.x_lin(i) = old.x_lin(from[i]);
    for (Eigen::Index j = 0; j < m; ++j) {
      c.P0(i, j) = from[j] < 0 ? 0.0 : old.P0(from[i], from[j]);
      c.P(i, j) = from[j] < 0 ? 0.0 : old.P(from[i], from[j]);
    }
  }
  // The window as the poses arrived: the old history's entries (with their inflations) and,
  // between them, the poses the old gate refused.
  const std::vector<TimedPose> window = Window();
  std::vector<bool> was_refused;
  c.history.clear();
  c.contexts.clear();
  c.inflations.clear();
  size_t h = 0;
  for (const TimedPose& p : window) {
    const bool in_history = h < old.history.size() && SameMeasurement(p.z, old.history[h]);
    Eigen::MatrixXd w;
    if (in_history && h < old.inflations.size() && old.inflations[h].size() != 0) {
      w = Eigen::MatrixXd::Zero(m, m);
      for (Eigen::Index i = 0; i < m; ++i)
        for (Eigen::Index j = 0; j < m; ++j)
          if (from[i] >= 0 && from[j] >= 0) w(i, j) = old.inflations[h](from[i], from[j]);
    }
    // The release awaiting its second look stays pending at its pose.
    if (in_history && static_cast<int>(h) == old.second_look_onset) {
      c.second_look_onset = static_cast<int>(c.history.size());
      c.second_look_alternatives = old.second_look_alternatives;
    }
    if (in_history) ++h;
    c.history.push_back(p.z);
    c.contexts.push_back(p.context);
    c.inflations.push_back(w);
    was_refused.push_back(!in_history);
  }
  c.accepted = old.accepted;
  c.rejected = old.rejected;
  c.relinearizations = old.relinearizations;
  c.x_fixed = old.x_fixed;
  // New parameters: converging again until they settle.
  c.status = identification::TrackingStatus::kConverging;
  c.small_steps = 0;
  const int passes = std::max(cell_.ekf.max_relinearize_passes, 1);
  try {
    ekf->Restore(c);
    ekf->Refine(passes);
    // A refused pose the new model still cannot explain (beyond its gate at the new estimate) is
    // an outlier, not evidence: dropped, and the window relinearised without it.
    const double p_gate = cell_.ekf.gate_probability;
    identification::EkfCheckpoint d = ekf->Checkpoint();
    d.history.clear();
    d.contexts.clear();
    d.inflations.clear();
    d.second_look_onset = -1;  // set again below, at its pose among those kept
    int taken = 0;
    for (size_t k = 0; k < c.history.size(); ++k) {
      if (was_refused[k] && p_gate < 1.0) {
        Eigen::VectorXd r;
        Eigen::MatrixXd H;
        identification::ExtendedResidualAndJacobian(
            ekf->extended_model(), c.history[k], c.contexts[k], ekf->x(), ekf->e(), base_, r, &H);
        const Eigen::MatrixXd S = H * ekf->P() * H.transpose() + c.history[k].covariance;
        const double nis = r.dot(S.llt().solve(r));
        if (!(nis <= identification::ChiSquareQuantile(p_gate, static_cast<double>(r.size()))))
          continue;
      }
      taken += was_refused[k] ? 1 : 0;
      if (static_cast<int>(k) == c.second_look_onset)
        d.second_look_onset = static_cast<int>(d.history.size());
      d.history.push_back(c.history[k]);
      d.contexts.push_back(c.contexts[k]);
      d.inflations.push_back(c.inflations[k]);
    }
    // The refused poses taken count as accepted now.
    d.accepted = c.accepted + taken;
    d.rejected = std::max(0, c.rejected - taken);
    const bool dropped = d.history.size() != c.history.size();
    if (dropped) {  // relinearised again without them, from the state before the first pass
      d.x = c.x;
      d.P = c.P;
      d.x_lin = c.x_lin;
    }
    ekf->Restore(d);
    if (dropped) ekf->Refine(passes);
    withdrawn_ = WithdrawExplainedChanges(*ekf, window, passes);
  } catch (...) {
    effects_ = kept;
    throw;
  }
  ekf_ = std::move(ekf);
  return added;
}

std::vector<WithdrawnChange> OnlineIdentification::WithdrawExplainedChanges(
    identification::EkfIdentifier& ekf, const std::vector<TimedPose>& window, int passes) const {
  // The releases still in the window: each put one inflation on the window's pose at its onset.
  const identification::EkfCheckpoint c = ekf.Checkpoint();
  std::vector<size_t> released;
  for (size_t k = 0; k < c.inflations.size(); ++k)
    if (c.inflations[k].size() != 0) released.push_back(k);
  std::vector<WithdrawnChange> withdrawn;
  double with_release = ekf.WindowEvidence();  // of `ekf` as it stands
  // Newest first: a later release was fitted on top of the earlier ones.
  for (size_t i = released.size(); i-- > 0;) {
    const size_t k = released[i];
    identification::EkfCheckpoint without = ekf.Checkpoint();
    without.inflations[k] = Eigen::MatrixXd();
    if (without.second_look_onset == static_cast<int>(k)) without.second_look_onset = -1;
    const std::unique_ptr<identification::EkfIdentifier> trial = MakeEkf(start_);
    trial->Restore(without);
    trial->Refine(passes);
    const double without_release = trial->WindowEvidence();
    if (!(without_release <= with_release)) continue;  // the poses still need the step
    WithdrawnChange w;
    for (const TimedPose& p : window)
      if (SameMeasurement(p.z, c.history[k])) w.onset_pose_index = p.pose_index;
    for (const Release& r : releases_)
      if (SameMeasurement(r.onset, c.history[k])) w.names = r.names;
    w.evidence_gain = with_release - without_release;
    withdrawn.push_back(std::move(w));
    ekf.Restore(trial->Checkpoint());
    with_release = without_release;
  }
  return withdrawn;
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
