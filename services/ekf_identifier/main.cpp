// ekf_identifier: the online EKF identification of the arm's kinematic parameter errors.
//
// Subscribes POSE_MEASUREMENT (still-window pose measurements; detecting the windows from the raw
// IMU/POSITION/JOINTS streams comes with the estimation library), updates
// rcal::identification::EkfIdentifier, and publishes KINEMATIC_PARAMS and CALIBRATION_STATUS
// after every pose, HEALTH at 1 Hz of sensor time. The state is checkpointed atomically after
// every accepted pose, so a restarted process resumes where it stopped. Bad messages (fail to
// decode, wrong sizes, NaN, time not after the last pose) are rejected, counted in HEALTH, and
// leave the state untouched.
//
// --cell-seed S (sensor level): the model, base set and start of the offline
// `rcal experiment paper --sensors --seed S` (rcal::cell::MakeCell: the arm plus the set-up
// frames base/earth/marker/IMU). The first --guess-poses poses are held back, the set-up guess is
// fitted to them (SetupGuess), the EKF is started there (MakeEkf) and then updated with them and
// every later pose, exactly as the offline RunOnline. The held poses are checkpointed too
// (schema rcal.ekf_checkpoint/2, `held`), so a restart during the guess phase keeps them.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <Eigen/Core>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>

#include "rcal/cell/sim_cell.hpp"
#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/services/common.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/checkpoint_json.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace {

using namespace rcal;
namespace ch = transport::channels;

struct Options {
  std::string robot = "config/robots/grb3016.yaml";
  std::string checkpoint;  // empty: no checkpoint
  std::string lcm_url;
  unsigned ident_seed = 1;
  unsigned cell_seed = 0;  // > 0: the sensor-level experiment's cell
  int guess_poses = 6;
  bool position_only = false;
  std::string name = "ekf_identifier";
};

class Identifier {
 public:
  Identifier(const Options& o, transport::Transport& t)
      : o_(o),
        t_(t),
        robot_(io::LoadRobot(services::RepoPath(o.robot))),
        cell_(o.cell_seed > 0 ? std::optional<cell::Cell>(cell::MakeCell(robot_.spec, o.cell_seed))
                              : std::nullopt),
        model_(cell_ ? cell_->model : robot_.model),
        base_(cell_ ? cell_->base : BaseSet(model_, o)),
        ekf_(cell_ ? std::make_unique<identification::EkfIdentifier>(
                         cell::MakeEkf(*cell_, model_.Nominal()))
                   : std::make_unique<identification::EkfIdentifier>(model_, base_)),
        model_id_(transport::ModelId(model_)),
        health_(o.name) {
    started_ = !cell_;
    if (cell_)
      spdlog::info(
          "cell of seed {}: {} parameters, base set of {}; set-up guess from the first {} "
          "poses",
          o.cell_seed, model_.num_params(), base_.size(), o.guess_poses);
    if (!o.checkpoint.empty() && std::filesystem::exists(o.checkpoint)) Resume();
    if (ekf_->accepted() > 0) started_ = true;
    t_.Subscribe<pose_measurement_t>(
        ch::kPoseMeasurement, [this](const pose_measurement_t& m) { OnPose(m); },
        [this](const std::string& e) {
          health_.Received();
          Reject(e);
        });
  }

  /// At start: the restored estimate (if any) and a CALIBRATION_STATUS that tells listeners the
  /// process is up and how many poses it resumed with.
  void PublishCurrent() {
    const int64_t utime = ekf_->accepted() > 0 ? last_utime_ : 0;
    if (ekf_->accepted() > 0 &&
        t_.Publish(ch::kKinematicParams, transport::ToKinematicParams(*ekf_, model_.name(), utime)))
      health_.Published();
    if (t_.Publish(ch::kCalibrationStatus, transport::ToCalibrationStatus(*ekf_, {}, utime)))
      health_.Published();
  }

 private:
  // The identifiable base set, exactly as the offline `rcal experiment paper` finds it.
  static std::vector<int> BaseSet(const kinematics::KinematicModel& model, const Options& o) {
    sim::Rng rng_id(o.ident_seed * 1000 + 1);
    const auto report = kinematics::AnalyzeIdentifiability(
        model, sim::SampleJoints(model, 200, rng_id), model.Nominal(),
        o.position_only ? kinematics::MeasurementKind::kPositionOnly
                        : kinematics::MeasurementKind::kFullPose);
    spdlog::info("identifiable: rank {} of {} (condition number {:.1f})", report.rank,
                 model.num_params(), report.condition_number);
    return report.identifiable;
  }

  void Resume() {
    try {
      const auto f = transport::LoadCheckpoint(o_.checkpoint);
      if (f.model_id != model_id_)
        throw std::runtime_error("model_id " + f.model_id + " is not " + model_id_);
      if (!f.held.empty() && (!cell_ || f.checkpoint.accepted > 0))
        throw std::runtime_error("held: " + std::to_string(f.held.size()) +
                                 " poses held for a set-up guess, but " +
                                 (cell_ ? "the EKF has started" : "there is no --cell-seed"));
      ekf_->Restore(f.checkpoint);
      held_ = f.held;
      last_utime_ = f.utime;
      last_pose_index_ = f.last_pose_index;
      spdlog::info(
          "resumed from {}: {} poses accepted, {} held for the set-up guess, last utime {}",
          o_.checkpoint, ekf_->accepted(), held_.size(), last_utime_);
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

  void OnPose(const pose_measurement_t& msg) {
    health_.Received();
    std::string error;
    auto z = transport::FromMessage(msg, &error);
    if (z) error = kinematics::Validate(model_, *z);
    if (error.empty() && msg.utime <= last_utime_)
      error = "pose_measurement.utime: " + std::to_string(msg.utime) +
              " is not after the last pose (" + std::to_string(last_utime_) + ")";
    if (!error.empty()) {
      Reject(error);
      health_.Tick(std::max(msg.utime, last_utime_), t_);
      return;
    }
    if (!started_) {
      // Held back for the set-up guess (time order checked against the held poses too).
      last_utime_ = msg.utime;
      last_pose_index_ = msg.pose_index;
      held_.push_back({*z, msg.utime, msg.pose_index});
      const bool guess = static_cast<int>(held_.size()) >= std::max(o_.guess_poses, 1);
      if (!guess) SaveState();  // before the log line: a logged held pose survives a kill
      spdlog::info("pose {}: held for the set-up guess ({} of {})", msg.pose_index, held_.size(),
                   o_.guess_poses);
      if (!guess) {
        health_.Tick(msg.utime, t_);
        return;
      }
      std::vector<kinematics::PoseMeasurement> ms;
      for (const auto& h : held_) ms.push_back(h.z);
      const Eigen::VectorXd x0 = cell::SetupGuess(*cell_, ms);
      ekf_ = std::make_unique<identification::EkfIdentifier>(cell::MakeEkf(*cell_, x0));
      started_ = true;
      spdlog::info("set-up guess from {} poses; EKF started", ms.size());
      const auto held = std::move(held_);
      held_.clear();
      for (const auto& h : held) Apply(h.z, h.utime, h.pose_index);
      return;
    }
    Apply(*z, msg.utime, msg.pose_index);
  }

  void Apply(const kinematics::PoseMeasurement& zz, int64_t utime, int64_t pose_index) {
    const auto* z = &zz;
    const Eigen::VectorXd x_before = ekf_->x();
    const auto r = ekf_->Update(*z);
    if (!r.accepted) {
      Reject("pose " + std::to_string(pose_index) + ": " + r.reason);
    } else {
      last_utime_ = utime;
      last_pose_index_ = pose_index;
      SaveState();
    }
    transport::StatusFigures fig;
    fig.last_nis = r.nis;
    const Eigen::VectorXd dx = ekf_->x() - x_before, sigma = ekf_->sigma();
    double max_step = 0;
    for (int i : base_) max_step = std::max(max_step, std::abs(dx(i)) / std::max(sigma(i), 1e-300));
    // Converged: enough equations for the unknowns, and the last pose moved no parameter by more
    // than a tenth of its σ.
    fig.converged =
        ekf_->accepted() * z->dimension() >= 2 * static_cast<int>(base_.size()) && max_step < 0.1;
    Publish(utime, fig);
    health_.Tick(utime, t_);
    spdlog::info("pose {}: {} (accepted {}, rejected {}, NIS {:.2f})", pose_index,
                 r.accepted ? "accepted" : "rejected", ekf_->accepted(), ekf_->rejected(), r.nis);
  }

  // The EKF state and the poses held for the set-up guess, atomically (--checkpoint).
  void SaveState() {
    if (o_.checkpoint.empty()) return;
    try {
      transport::SaveCheckpoint(
          o_.checkpoint, {model_id_, last_utime_, last_pose_index_, ekf_->Checkpoint(), held_});
    } catch (const std::exception& e) {
      health_.Error(e.what());
      spdlog::error("{}", e.what());
    }
  }

  void Publish(int64_t utime, transport::StatusFigures fig) {
    if (t_.Publish(ch::kKinematicParams, transport::ToKinematicParams(*ekf_, model_.name(), utime)))
      health_.Published();
    const auto history = ekf_->Checkpoint().history;
    if (!history.empty()) {
      const auto stats = identification::ErrorsAgainstMeasurements(model_, ekf_->x(), history);
      fig.rms_position_residual = stats.rms_position_m;
      fig.rms_orientation_residual = stats.rms_orientation_rad;
      std::vector<Eigen::VectorXd> qs;
      for (const auto& m : history) qs.push_back(m.q);
      fig.condition_number =
          kinematics::AnalyzeIdentifiability(model_, qs, ekf_->x(),
                                             history.front().has_orientation
                                                 ? kinematics::MeasurementKind::kFullPose
                                                 : kinematics::MeasurementKind::kPositionOnly)
              .condition_number;
    }
    if (t_.Publish(ch::kCalibrationStatus, transport::ToCalibrationStatus(*ekf_, fig, utime)))
      health_.Published();
  }

  Options o_;
  transport::Transport& t_;
  io::LoadedRobot robot_;
  std::optional<cell::Cell> cell_;
  kinematics::KinematicModel model_;
  std::vector<int> base_;
  std::unique_ptr<identification::EkfIdentifier> ekf_;
  std::vector<transport::HeldPose> held_;
  bool started_ = true;
  std::string model_id_;
  transport::Health health_;
  int64_t last_utime_ = std::numeric_limits<int64_t>::min();
  int64_t last_pose_index_ = -1;
};

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "ekf_identifier: online EKF identification of the kinematic parameter errors.\n"
      "Subscribes POSE_MEASUREMENT; publishes KINEMATIC_PARAMS, CALIBRATION_STATUS and HEALTH.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  app.add_option("--robot", o.robot, "robot YAML or URDF")->capture_default_str();
  app.add_option("--checkpoint", o.checkpoint,
                 "state file, written atomically after every accepted pose and resumed from at "
                 "start (empty: none)");
  app.add_option("--lcm-url", o.lcm_url, "LCM URL");
  app.add_option("--ident-seed", o.ident_seed,
                 "seed of the joint sample that selects the identifiable parameter set")
      ->capture_default_str();
  app.add_flag("--position-only", o.position_only, "identify from positions only");
  app.add_option("--cell-seed", o.cell_seed,
                 "> 0: the model, base set and set-up guess of `rcal experiment paper --sensors "
                 "--seed S` (arm + set-up frames)")
      ->capture_default_str();
  app.add_option("--guess-poses", o.guess_poses,
                 "with --cell-seed: poses the set-up guess is fitted to before the EKF starts")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--name", o.name, "process name in HEALTH")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  try {
    rcal::services::InstallStopHandlers();
    rcal::transport::LcmTransport t(o.lcm_url);
    spdlog::info("ekf_identifier on {}", t.url());
    Identifier id(o, t);
    id.PublishCurrent();
    if (const int rc =
            rcal::services::ServeUntilStopped([&](int ms) { return t.HandleTimeout(ms); });
        rc != 0)
      return rc;
    spdlog::info("stopped");
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
