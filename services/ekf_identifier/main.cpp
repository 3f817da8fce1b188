// ekf_identifier: the online EKF identification of the arm's kinematic parameter errors.
//
// Subscribes POSE_MEASUREMENT (still-window pose measurements; detecting the windows from the raw
// IMU/POSITION/JOINTS streams comes with the estimation library), updates
// rcal::identification::EkfIdentifier, and publishes KINEMATIC_PARAMS and CALIBRATION_STATUS
// after every pose, HEALTH at 1 Hz of sensor time (its `activity` the tracking status). The state
// is checkpointed atomically after every accepted pose, so a restarted process resumes where it
// stopped. Bad messages (fail to decode, wrong sizes, NaN, time not after the last pose) are
// rejected, counted in HEALTH, and leave the state untouched.
//
// Time and sequence (issue 11): POSE_MEASUREMENT passes an estimation::TimeGate (--horizon,
// default an hour of sensor time between poses; --resync-samples): an exact duplicate, a pose
// before the last, or one beyond the horizon or the host-clock ceiling is refused and counted in
// HEALTH, and never becomes the last time or reaches the checkpoint; a pose stream that started
// over (a restarted still_window with a new time base) is re-synchronised after --resync-samples
// consistent poses. A checkpoint whose time is beyond the host-clock ceiling is not trusted: it
// is moved aside as *.rejected. pose_index gaps (poses lost on the wire or in LCM's queue) are
// counted in HEALTH gaps. Joints beyond the model's limits by more than --joint-margin and
// positions beyond transport::SensorRanges::position are refused naming the field.
//
// --cell FILE (schema rcal.cell/1, config/cells/): the arm, its set-up frames (world ← base,
// flange → marker per marker id, flange → IMU, earth ← world), what the cell measures, the priors
// and the identifier settings. Frames the cell file says to guess: the first
// identifier.guess_poses poses are held back, the set-up guessed from them
// (identification::GuessSetup), the EKF started there and then updated with them and every later
// pose. The pose-by-pose logic is rcal::cell::OnlineIdentification, which
// `rcal calibrate --log LOG --cell FILE` runs offline on a recorded log: the same parameters. No
// simulator is involved: a simulated cell is a source of data like any driver. The held poses
// are checkpointed too (schema rcal.ekf_checkpoint/3, `held`), so a restart during the guess
// phase keeps them.
//
// --effects analysis.json (an `rcal analyze` result, or the JSON of `rcal calibrate --effects`):
// the non-geometric effects it lists are identified live with the geometry (issue 15 item 4):
// the state is [base set; effect parameters], starting at 0 with the default weak prior, each
// pose's update under its context (POSE_MEASUREMENT's temperature_c, payload_kg, time_s,
// dq_sign); KINEMATIC_PARAMS carries the effect parameters with their σ, the checkpoint the
// contexts. A context that cannot be true (temperature beyond [−60, 200] °C, a negative payload,
// a dq_sign not −1, 0, +1) refuses its pose, naming the field, with or without effects.
//
// The discrepancy watch (issue 15 item 5, --discrepancy-every N, default 50): every N poses the
// EKF takes (accepted or refused by its gate) rcal analyze's tests run on the identifier's window
// (cell::WatchForDiscrepancy: χ² of the geometric fit against the poses' noise, correlation with
// each candidate effect, selection by nested cross-validation) on a worker thread, so poses keep
// flowing during its second or so; the changes released inside the window are fitted as geometry
// steps (a piecewise geometry, OnlineIdentification::WindowSteps). MODEL_DISCREPANCY names the
// suspected causes with their z and the expected held-out gain.
// --discrepancy-switch: suspects the identifier lacks are switched in
// (cell::OnlineIdentification::SwitchIn: identified from the window's poses on); the checkpoint
// names the effects of its state (key `effects`), so a restart resumes with the extended model.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <Eigen/Core>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <future>
#include <memory>
#include <optional>

#include "rcal/cell/discrepancy_watch.hpp"
#include "rcal/cell/next_poses.hpp"
#include "rcal/cell/online_identification.hpp"
#include "rcal/discrepancy/analysis.hpp"
#include "rcal/estimation/time_gate.hpp"
#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/identification/tracking.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/effects_json.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/next_poses_t.hpp"
#include "rcal/services/common.hpp"
#include "rcal/services/time_options.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/checkpoint_json.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace {

using namespace rcal;
namespace ch = transport::channels;

// Poses are seconds to minutes apart and irregular: an hour's horizon, no gap count from time
// (pose_index counts the gaps).
estimation::TimeGateSettings PoseTimeGate() {
  estimation::TimeGateSettings s;
  s.horizon_us = 3'600'000'000LL;
  s.resync_samples = 3;
  s.gap_factor = 0.0;
  return s;
}

// ", one of the alternatives, probability 0.63" for a change the poses could not pin on one
// direction (DetectedChange::probability); "" for a step along all its directions.
std::string Alternative(const identification::DetectedChange& c, size_t i) {
  if (i >= c.probability.size()) return "";
  return fmt::format(", one of the alternatives, probability {:.2f}", c.probability[i]);
}

struct Options {
  std::string cell = "config/cells/grb3016.yaml";
  std::string checkpoint;  // empty: no checkpoint
  std::string lcm_url;
  std::string name = "ekf_identifier";
  estimation::TimeGateSettings time = PoseTimeGate();
  int next_poses = 5;  // NEXT_POSES suggestions per pose (0: none)
  // NEXT_POSES: a stop's cost as joint-space distance [rad | m]
  double stop_cost = identification::kDefaultStopCost;
  std::string effects;  // analysis.json: the effects identified with the geometry (empty: none)
  int discrepancy_every = 50;       // MODEL_DISCREPANCY every this many poses taken (0: never)
  bool discrepancy_switch = false;  // switch the suspected effects in
};

class Identifier {
 public:
  Identifier(const Options& o, transport::Transport& t)
      : o_(o),
        t_(t),
        id_(cell::MakeOnlineIdentification(
            io::LoadCell(services::RepoPath(o.cell)),
            o.effects.empty() ? std::string() : services::RepoPath(o.effects))),
        channels_(id_.cell().spec.channels),
        model_id_(transport::ModelId(id_.model())),
        health_(o.name),
        gate_(o.time) {
    const io::BuiltCell& cell = id_.cell();
    if (o.next_poses > 0) advisor_.emplace(cell);
    watch_settings_.every_poses = o.discrepancy_every;
    for (const auto& p : id_.ekf().extended_model().EffectParameters())
      spdlog::info("effect parameter {} [{}] identified live", p.name, p.unit);
    spdlog::info("cell {} ({}): chain {} → {}, {} of {} parameters identifiable{}", cell.spec.name,
                 cell.spec.source, cell.robot_spec.base_link, cell.robot_spec.tip_link,
                 id_.base().size(), id_.model().num_params(),
                 id_.started() ? std::string()
                               : "; set-up guess from the first " +
                                     std::to_string(cell.spec.identifier.guess_poses) + " poses");
    if (!o.checkpoint.empty() && std::filesystem::exists(o.checkpoint)) Resume();
    t_.Subscribe<pose_measurement_t>(
        channels_.pose_measurement, [this](const pose_measurement_t& m) { OnPose(m); },
        [this](const std::string& e) {
          health_.Received();
          Reject(e);
        });
  }

  /// The final HEALTH (on a clean stop): the counts up to the end (a watch still running is
  /// waited for and published first).
  void Finish() {
    if (watch_.valid()) {
      watch_.wait();
      PollWatch();
    }
    health_.Final(t_);
  }

  /// A finished discrepancy watch: MODEL_DISCREPANCY, and the switch (--discrepancy-switch).
  void PollWatch() {
    if (!watch_.valid() || watch_.wait_for(std::chrono::seconds(0)) != std::future_status::ready)
      return;
    cell::DiscrepancyReport r;
    try {
      r = watch_.get();
    } catch (const std::exception& e) {
      health_.Error(std::string("discrepancy watch: ") + e.what());
      spdlog::warn("discrepancy watch: {}", e.what());
      return;
    }
    bool switched = false;
    std::string names;
    for (const auto& s : r.suspects)
      names += fmt::format("{}{} (z {:.1f}{})", names.empty() ? "suspected: " : ", ", s.description,
                           s.z, s.in_model ? ", in the model" : "");
    spdlog::info(
        "discrepancy watch over {} poses{}: chi2/dof {:.2f}; {}; held-out position RMS {:.4f} -> "
        "{:.4f} mm{}",
        r.window_poses,
        r.window_steps > 0
            ? fmt::format(" (the {} change(s) released inside it fitted as steps)", r.window_steps)
            : std::string(),
        r.chi2_dof > 0 ? r.chi2 / r.chi2_dof : 0.0,
        names.empty() ? std::string("nothing suspected") : names, r.heldout_rms_before_m * 1e3,
        r.heldout_rms_after_m * 1e3,
        r.correlations.empty() ? std::string()
                               : fmt::format("; residual vs {}: r = {:.2f}",
                                             r.correlations[0].regressor, r.correlations[0].r));
    if (o_.discrepancy_switch && !r.NewEffects().empty()) {
      try {
        const auto added = id_.SwitchIn(r.NewEffects());
        switched = !added.empty();
        if (switched) {
          for (const cell::WithdrawnChange& w : id_.withdrawn()) {
            std::string changed;
            for (const std::string& n : w.names) changed += (changed.empty() ? "" : ", ") + n;
            spdlog::warn(
                "the change detected from pose {} ({}) withdrawn: the window is more likely "
                "without it under the model with the switched-in effects (−2 ln Bayes factor "
                "{:.1f})",
                w.onset_pose_index + 1, changed.empty() ? "detected before a restart" : changed,
                w.evidence_gain);
          }
          SaveState();
          const auto& ekf = id_.ekf();
          const auto params = ekf.extended_model().EffectParameters();
          for (size_t k = 0; k < params.size(); ++k)
            spdlog::info(
                "effect parameter {} [{}] identified live (switched in): {:.4g} ± {:.2g} "
                "from the window's {} poses",
                params[k].name, params[k].unit, ekf.e()(static_cast<Eigen::Index>(k)),
                ekf.sigma_e()(static_cast<Eigen::Index>(k)), ekf.window_size());
        }
      } catch (const std::exception& e) {
        health_.Error(std::string("discrepancy switch: ") + e.what());
        spdlog::warn("discrepancy switch: {}", e.what());
      }
    }
    if (t_.Publish(channels_.model_discrepancy,
                   transport::ToModelDiscrepancy(
                       r, watch_utime_, id_.ekf().accepted(), switched,
                       switched ? id_.withdrawn() : std::vector<cell::WithdrawnChange>{})))
      health_.Published();
    // The state now holds every pose up to the last one: published at its time (a listener that
    // orders KINEMATIC_PARAMS by utime must not see it go back).
    if (switched) Publish(id_.last_utime(), {});
  }
  /// At start: the restored estimate (if any) and a CALIBRATION_STATUS that tells listeners the
  /// process is up and how many poses it resumed with.
  void PublishCurrent() {
    const auto& ekf = id_.ekf();
    health_.Activity(identification::TrackingStatusName(ekf.status()));
    const int64_t utime = ekf.accepted() > 0 ? id_.last_utime() : 0;
    if (ekf.accepted() > 0 &&
        t_.Publish(channels_.kinematic_params,
                   transport::ToKinematicParams(ekf, id_.model().name(), utime)))
      health_.Published();
    if (t_.Publish(channels_.calibration_status, transport::ToCalibrationStatus(ekf, {}, utime)))
      health_.Published();
  }

 private:
  void Resume() {
    try {
      const auto f = transport::LoadCheckpoint(o_.checkpoint);
      if (f.model_id != model_id_)
        throw std::runtime_error("model_id " + f.model_id + " is not " + model_id_);
      if (const std::string why =
              transport::UntrustedCheckpointTime(f, estimation::HostCeilingUs());
          !why.empty())
        throw std::runtime_error(why);
      if (!f.effects_json.empty()) {
        // The state belongs to a model with these effects (--effects, and those the discrepancy
        // watch switched in): the identification takes them before the state is restored.
        const auto effects = io::ParseAnalysisEffects(
                                 {{"effects", nlohmann::json::parse(f.effects_json)}}, id_.model())
                                 .effects;
        for (const auto& e : id_.SwitchIn(effects))
          spdlog::info("checkpoint: its model identifies {} (switched in before the restart)",
                       discrepancy::Describe(id_.model(), e));
      }
      id_.Restore(f.checkpoint, f.held, f.utime, f.last_pose_index);
      if (id_.ekf().accepted() > 0 || !id_.held().empty()) {
        gate_.Restore(f.utime);
        last_pose_index_ = f.last_pose_index;
      }
      spdlog::info(
          "resumed from {}: {} poses accepted, {} held for the set-up guess, last utime {}",
          o_.checkpoint, id_.ekf().accepted(), id_.held().size(), id_.last_utime());
    } catch (const std::exception& e) {
      // A checkpoint that does not fit is reported and kept aside, never silently overwritten.
      const std::string aside = o_.checkpoint + ".rejected";
      std::filesystem::rename(o_.checkpoint, aside);
      spdlog::error("checkpoint not used ({}), moved to {}", e.what(), aside);
      health_.Error(std::string("checkpoint: ") + e.what());
    }
  }

  void Reject(const std::string& reason) {
    health_.Rejected(reason);
    spdlog::warn("rejected: {}", reason);
  }

  // Heartbeats follow accepted time only: a refused time never schedules one.
  void Beat() {
    if (gate_.last()) health_.Tick(*gate_.last(), t_);
  }

  // Joints within the model's limits (+ the cell's margin) and the position within the sensor's
  // range.
  std::string Implausible(const kinematics::PoseMeasurement& z) const {
    const auto& joints = id_.model().joints();
    const double margin = id_.cell().spec.identifier.joint_margin;
    for (int i = 0; i < z.q.size() && i < static_cast<int>(joints.size()); ++i)
      if (z.q(i) < joints[i].lower - margin || z.q(i) > joints[i].upper + margin)
        return "pose_measurement.q[" + std::to_string(i) + "]: " + std::to_string(z.q(i)) +
               " is beyond the joint's limits [" + std::to_string(joints[i].lower) + ", " +
               std::to_string(joints[i].upper) + "] by more than " + std::to_string(margin);
    if (const double r = z.p_WM_W.norm(); r > transport::SensorRanges{}.position)
      return "pose_measurement.p: " + std::to_string(r) +
             " m from the sensor is beyond the position sensor's range";
    return "";
  }

  void OnPose(const pose_measurement_t& msg) {
    health_.Received();
    std::string error;
    auto z = transport::FromMessage(msg, &error, &id_.model());
    std::optional<kinematics::EffectContext> context;
    if (z) context = transport::ContextFromMessage(msg, &error);
    if (z && context) error = Implausible(*z);
    if (!z || !context || !error.empty()) {
      Reject(error);
      Beat();
      return;
    }
    const auto verdict = health_.Gate(gate_, msg.utime, "pose_measurement.utime");
    if (!estimation::Usable(verdict)) {
      spdlog::warn("rejected: {}", health_.last_error());
      Beat();
      return;
    }
    if (verdict == estimation::TimeVerdict::kResynchronised) {
      // The pose stream started over with a new time base: keep the estimate, take its time.
      spdlog::warn("{}", health_.last_error());
      id_.Restore(id_.ekf().Checkpoint(), id_.held(), msg.utime - 1, -1);
      last_pose_index_.reset();
    }
    // pose_index counts from 0 per still_window run: a step of more than one is poses lost; a
    // step back is a restarted still_window, not a loss.
    if (last_pose_index_ && msg.pose_index > *last_pose_index_ + 1)
      health_.Gap(msg.pose_index - *last_pose_index_ - 1);
    last_pose_index_ = msg.pose_index;
    last_q_ = z->q;
    if (advisor_) advisor_->Measured(*z);
    const auto out = id_.Add({std::move(*z), msg.utime, msg.pose_index, std::move(*context)},
                             [this](const cell::OnlineIdentification::Update& u) { Applied(u); });
    if (!out.rejected.empty()) {
      Reject(out.rejected);
      Beat();
      return;
    }
    if (out.held) {
      const int guess_poses = id_.cell().spec.identifier.guess_poses;
      if (!out.started) SaveState();  // before the log line: a logged held pose survives a kill
      spdlog::info("pose {} (pose_index {}): held for the set-up guess ({} of {})",
                   msg.pose_index + 1, msg.pose_index,
                   out.started ? guess_poses : static_cast<int>(id_.held().size()), guess_poses);
      if (out.started) spdlog::info("set-up guess from {} poses; EKF started", guess_poses);
      if (!out.started) health_.Tick(msg.utime, t_);
    }
  }

  // After each EKF update (also each held pose applied when the guess completes).
  void Applied(const cell::OnlineIdentification::Update& u) {
    // Not held across StartWatch: a finished watch it collects may switch effects in, which
    // replaces the identifier (a reference kept from before it dangled: ekf_identifier crashed
    // on the pose after a live switch-in whose watch had finished by then).
    const identification::EkfIdentifier* ekf = &id_.ekf();
    if (!u.result.accepted)
      Reject("pose " + std::to_string(u.pose_index) + ": " + u.result.reason);
    else
      SaveState();
    health_.Activity(identification::TrackingStatusName(ekf->status()));  // HEALTH says it too
    transport::StatusFigures fig;
    fig.last_nis = u.result.nis;
    // Converged: enough equations for the unknowns, and the last pose moved no parameter by more
    // than a tenth of its σ.
    fig.converged = ekf->accepted() * u.dimension >= 2 * static_cast<int>(id_.base().size()) &&
                    u.max_step_sigma < 0.1;
    Publish(u.utime, fig);
    PublishNextPoses(u.utime);
    StartWatch(u);
    ekf = &id_.ekf();  // the watch may have switched effects in: the identifier now
    health_.Tick(u.utime, t_);
    if (u.result.change) {  // issue 15: named, released, re-converging (CALIBRATION_STATUS too)
      const auto names = identification::ChangeNames(id_.model(), *u.result.change);
      for (size_t i = 0; i < names.size(); ++i)
        spdlog::warn("pose {}: change detected: {} by {:.6g} [m | rad]{}, released",
                     u.pose_index + 1, names[i], u.result.change->step(i),
                     Alternative(*u.result.change, i));
    }
    if (u.result.reattributed) {  // the second look: the window renamed the last change
      const auto names = identification::ChangeNames(id_.model(), *u.result.reattributed);
      for (size_t i = 0; i < names.size(); ++i)
        spdlog::warn(
            "pose {}: the change from {} poses back renamed by its second look: {} by "
            "{:.6g} [m | rad]{}, released instead",
            u.pose_index + 1, u.result.reattributed->onset_poses_ago, names[i],
            u.result.reattributed->step(i), Alternative(*u.result.reattributed, i));
    }
    // Poses are numbered from 1 as `rcal watch` numbers them (pose_index counts from 0); the
    // effect parameters (--effects) with their σ.
    std::string effects;
    const auto params = ekf->extended_model().EffectParameters();
    for (size_t k = 0; k < params.size(); ++k)
      effects += fmt::format("; {} {:.4g} ± {:.2g} {}", params[k].name,
                             ekf->e()(static_cast<Eigen::Index>(k)),
                             ekf->sigma_e()(static_cast<Eigen::Index>(k)), params[k].unit);
    spdlog::info("pose {} (pose_index {}): {} (accepted {}, rejected {}, NIS {:.2f}){}",
                 u.pose_index + 1, u.pose_index, u.result.accepted ? "accepted" : "rejected",
                 ekf->accepted(), ekf->rejected(), u.result.nis, effects);
  }

  // The discrepancy watch on a copy of the window, on a worker thread (one at a time).
  void StartWatch(const cell::OnlineIdentification::Update& u) {
    PollWatch();
    if (watch_.valid() || !cell::WatchDue(id_, watch_settings_)) return;
    watch_utime_ = u.utime;
    watch_ = std::async(std::launch::async,
                        [model = id_.model(), window = cell::WatchWindow(id_),
                         effects = id_.effects(), gravity = id_.gravity(), s = watch_settings_]() {
                          return cell::WatchForDiscrepancy(model, window, effects, gravity, s);
                        });
  }

  // The EKF state and the poses held for the set-up guess, atomically (--checkpoint).
  void SaveState() {
    if (o_.checkpoint.empty()) return;
    try {
      const auto& ekf = id_.ekf();
      transport::SaveCheckpoint(
          o_.checkpoint,
          {model_id_, id_.last_utime(), id_.last_pose_index(), ekf.Checkpoint(), id_.held(),
           ekf.num_effect_params() > 0
               ? io::EffectsJson(ekf.extended_model(), ekf.e(), ekf.sigma_e()).dump()
               : std::string()});
    } catch (const std::exception& e) {
      health_.Error(e.what());
      spdlog::error("{}", e.what());
    }
  }

  void Publish(int64_t utime, transport::StatusFigures fig) {
    const auto& ekf = id_.ekf();
    const auto& model = id_.model();
    if (t_.Publish(channels_.kinematic_params,
                   transport::ToKinematicParams(ekf, model.name(), utime)))
      health_.Published();
    const auto checkpoint = ekf.Checkpoint();
    const auto& history = checkpoint.history;
    if (!history.empty()) {
      // With effects: the residual of the extended model, each pose under its context.
      const auto stats =
          ekf.num_effect_params() > 0
              ? identification::ErrorsAgainstMeasurements(ekf.extended_model(), ekf.x(), ekf.e(),
                                                          history, checkpoint.contexts)
              : identification::ErrorsAgainstMeasurements(model, ekf.x(), history);
      fig.rms_position_residual = stats.rms_position_m;
      fig.rms_orientation_residual = stats.rms_orientation_rad;
      fig.condition_number =
          kinematics::AnalyzeIdentifiability(model, history, ekf.x()).condition_number;
    }
    if (t_.Publish(channels_.calibration_status, transport::ToCalibrationStatus(ekf, fig, utime)))
      health_.Published();
  }

  // NEXT_POSES after each update, from the joints of the last pose received.
  void PublishNextPoses(int64_t utime) {
    if (!advisor_ || last_q_.size() != id_.model().num_joints()) return;
    const auto advice = advisor_->Suggest(id_.ekf(), last_q_, o_.next_poses, o_.stop_cost);
    if (t_.Publish(channels_.next_poses, transport::ToNextPoses(advice, utime, id_.ekf().accepted(),
                                                                id_.model().num_joints())))
      health_.Published();
  }
  std::optional<cell::NextPoseAdvisor> advisor_;
  Eigen::VectorXd last_q_;
  cell::DiscrepancyWatchSettings watch_settings_;
  std::future<cell::DiscrepancyReport> watch_;
  int64_t watch_utime_ = 0;

  Options o_;
  transport::Transport& t_;
  cell::OnlineIdentification id_;
  io::CellChannels channels_;
  std::string model_id_;
  transport::Health health_;
  estimation::TimeGate gate_;
  std::optional<int64_t> last_pose_index_;
};

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "ekf_identifier: online EKF identification of the kinematic parameter errors.\n"
      "Subscribes POSE_MEASUREMENT; publishes KINEMATIC_PARAMS, CALIBRATION_STATUS, NEXT_POSES, "
      "MODEL_DISCREPANCY and HEALTH.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  app.add_option("--cell", o.cell,
                 "cell file (schema rcal.cell/1): the robot, set-up frames, sensors, priors and "
                 "channels")
      ->capture_default_str();
  app.add_option("--checkpoint", o.checkpoint,
                 "state file, written atomically after every accepted pose and resumed from at "
                 "start (empty: none)");
  app.add_option("--lcm-url", o.lcm_url, "LCM URL");
  app.add_option("--name", o.name, "process name in HEALTH")->capture_default_str();
  services::AddTimeGateOptions(app, &o.time, "pose");
  app.add_option("--next-poses", o.next_poses,
                 "NEXT_POSES: suggested next stops published after each pose (0: none)")
      ->capture_default_str()
      ->check(CLI::Range(0, 100));
  app.add_option(
         "--next-poses-stop-cost", o.stop_cost,
         "NEXT_POSES: what a stop costs, as joint-space distance [rad | m]: suggestions are "
         "ranked by gain / (distance + this); large: by gain alone")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("--effects", o.effects,
                 "non-geometric effects identified live with the geometry: the analysis.json of "
                 "rcal analyze (its `effects`), or the JSON of rcal calibrate --effects");
  app.add_option("--discrepancy-every", o.discrepancy_every,
                 "MODEL_DISCREPANCY: rcal analyze's tests on the window every this many poses the "
                 "EKF takes, accepted or refused by its gate (0: never)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1000000));
  app.add_flag("--discrepancy-switch", o.discrepancy_switch,
               "switch the effects MODEL_DISCREPANCY suspects in: identified live from then on "
               "(the checkpoint keeps them)");
  CLI11_PARSE(app, argc, argv);
  try {
    rcal::services::InstallStopHandlers();
    rcal::transport::LcmTransport t(o.lcm_url);
    spdlog::info("ekf_identifier on {}", t.url());
    Identifier id(o, t);
    id.PublishCurrent();
    if (const int rc = rcal::services::ServeUntilStopped([&](int ms) {
          const int r = t.HandleTimeout(ms);
          id.PollWatch();
          return r;
        });
        rc != 0)
      return rc;
    id.Finish();
    spdlog::info("stopped");
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
