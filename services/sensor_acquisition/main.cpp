// sensor_acquisition: the pipeline's sources. Source `sim` (pose level): the truth robot of
// libs/sim (nominal model + the paper's Table 3 errors) stops at joint configurations sampled
// inside the limits; each stop is published as JOINTS and as a POSE_MEASUREMENT with the noise
// model's covariance, at `--rate` stops per second of sensor time.
//
// The stream for --seed S and --poses N is exactly the calibration set of the offline
// `rcal experiment paper --seed S` with N poses: joints drawn in blocks of N (1000 when
// unlimited) from mt19937_64(S·1000 + 3), each block then measured in order from the same
// generator. Sensor time starts at --start-utime and advances 1/rate per pose; --speed paces
// it against the wall clock (1: real time, 0: as fast as possible).
//
// Source `sim --level sensors --sim FILE.sim.yaml`: a simulated cell (schema rcal.cell_sim/1: the
// cell file it simulates, plus the truth only the simulator knows: the arm's errors and the true
// set-up frames; rcal::cell::MakeSimCell) moves through the programme of the offline
// `rcal experiment paper --sensors` (home, then --poses calibration stops drawn with the
// --test-poses test stops from mt19937_64(S·1000 + 3), the sim file's still time at each) and
// rcal::sim::SensorSim, with the sensors the cell file declares (cell::SimSensorSettings),
// publishes every tick as JOINTS, IMU (magnetic field in T) and POSITION (when the sensor fired,
// covariance σ² I) on the cell's channels, utime = --start-utime + t_sim. The demo's sim file
// (config/cells/grb3016.sim.yaml) is the experiment's cell of seed 1. The programme
// ends with the move to the first test stop, so the last calibration window closes exactly as
// offline and no test window follows. Paced by --speed (0: as fast as possible). The simulated
// controller also reports the arm's conditions (ARM_CONDITIONS, once per second of sensor time
// and as the payload changes:
// the arm's temperature warming as sim::SessionSettings says, with --sim-warmup as the time
// constant, plus its 0.3 K sensor noise; the payload it was told to carry: none, or with
// --sim-payloads one per stop, taken on halfway through the move to it, or with
// --sim-payload-at stop halfway through its still interval; --sim-conditions-late S: each report
// published S seconds of sensor time after it is made, as from a slower bridge), and with
// --sim-effect
// (the arm grows with its temperature, or with time; its joints give way under gravity and the
// payload, turn by a periodic gear error or a scale off their readings, or stand off them by their
// backlash in the direction they came in) the tool moves as the extended model says under the
// true, noise-free conditions.
//
// Source `replay FILE`: a raw-stream CSV in the BROAD layout (sources.hpp) published as IMU (every
// row) and POSITION (decimated to --position-rate), utime from the file; or a pose dataset
// (columns q1..qN, x, y, z, ...) published as JOINTS + POSE_MEASUREMENT per pose (utime from its
// time column, else --start-utime + k/--rate; noise σ from --position-noise/--orientation-noise).
// Paced by --speed (1: real time, 0: as fast as possible; over udpm a burst larger than the
// receivers' socket buffers is dropped: use a finite speed or recv_buf_size=N in the LCM URL).
// A real sensor driver implements rcal::sensors::SensorSource.
//
// Following the identifier (--follow-next-poses, sim sources; issue 16): the simulated cell goes
// where ekf_identifier's NEXT_POSES asks instead of to the programme's next random stop, once the
// identifier advises (before that, and whenever no usable advice came, the programme's stop; each
// stop's choice is logged). Pose level: after each stop the process waits up to --follow-timeout
// of wall time for the advice computed after that stop, then goes to its best suggestion. Sensor
// level: a still window's pose is published when the arm leaves the stop, so the advice of a stop
// arrives while the arm moves on; leaving stop k the arm takes the newest advice (computed after
// stop k − 1, one stop behind) and goes to its best suggestion it has not stood at since
// (cell::NextStopToFollow); the programme's timing after that stop follows the new move. The
// suggestions are joints as read; the arm goes where it reads so (sim::TrueJoints). NEXT_POSES
// messages that do not decode or fit the model (joint count, limits, non-finite values) are
// refused naming the field and counted in HEALTH. Test stops are never replaced.
//
// Restarts (--checkpoint FILE, sim sources): a killed simulator must not replay from t = 0 (the
// pipeline rejects sensor time going backwards, and a real sensor just continues). Before
// publishing, the process writes atomically the first tick it may not yet publish (a lease of
// --checkpoint-interval of sensor time, one pose at pose level); a restart with the same command
// line fast-forwards the deterministic programme (same random draws, nothing published) to that
// tick and continues from there, sensor time continuing. A kill loses at most one lease of
// ticks (shorter than the pose pipeline's max_gap, so a still window around it keeps its pose
// or is dropped, never averaged across a move); SIGINT loses nothing. A finished programme stays
// finished (with --linger the restarted process just lingers). A checkpoint of another
// programme (seed, stop counts, start time, rate) is an error naming the key (exit 1). The stops a
// following cell chose are not in the checkpoint: a restarted one resumes on the programme's own
// stops, its sensor time continuing.
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <deque>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/cell/next_poses.hpp"
#include "rcal/cell/sim_cell.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/next_poses_t.hpp"
#include "rcal/services/common.hpp"
#include "rcal/sim/effects.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/sim/sensor_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"
#include "sources.hpp"

namespace {

// Publishes a source's samples on `channels`, pacing recorded ones by utime against the wall
// clock.
int RunSource(rcal::sensors::SensorSource& source, rcal::transport::Transport& t, double speed,
              const rcal::io::CellChannels& channels) {
  using namespace rcal;
  transport::Health health("sensor_acquisition");
  spdlog::info("sensor_acquisition: {}, speed {}", source.Describe(), speed);
  std::optional<int64_t> utime0;
  long long wall0 = 0;
  int64_t published = 0;
  while (!services::StopRequested() && !source.Finished()) {
    const auto e = source.Next(100);
    if (!e) continue;
    const int64_t utime = sensors::Utime(*e);
    if (!utime0) {
      utime0 = utime;
      wall0 = services::MonotonicMicros();
    }
    if (source.Recorded() && speed > 0) {
      const long long due = wall0 + static_cast<long long>((utime - *utime0) / speed);
      while (!services::StopRequested()) {
        const long long now = services::MonotonicMicros();
        if (now >= due) break;
        std::this_thread::sleep_for(std::chrono::microseconds(std::min(due - now, 50'000LL)));
      }
    }
    bool ok = false;
    if (const auto* imu = std::get_if<transport::ImuSample>(&*e))
      ok = t.Publish(channels.imu, transport::ToMessage(*imu));
    else if (const auto* pos = std::get_if<transport::PositionSample>(&*e))
      ok = t.Publish(channels.position, transport::ToMessage(*pos));
    else if (const auto* js = std::get_if<joint_state_t>(&*e))
      ok = t.Publish(channels.joints, *js);
    else if (const auto* c = std::get_if<transport::ArmConditions>(&*e))
      ok = t.Publish(channels.arm_conditions, transport::ToArmConditions(*c));
    else
      ok = t.Publish(channels.pose_measurement, std::get<pose_measurement_t>(*e));
    if (ok) {
      health.Published();
      ++published;
    } else {
      health.Error("publish failed at utime " + std::to_string(utime));
    }
    health.Tick(utime, t);
    t.HandleTimeout(0);  // keeps LCM's receive queue empty
  }
  health.Final(t);
  spdlog::info("done: {} samples published", published);
  return 0;
}

// Waits until sensor time `utime` is due at `speed` (0: never waits).
void Pace(int64_t utime, int64_t utime0, long long wall0, double speed) {
  if (speed <= 0) return;
  const long long due = wall0 + static_cast<long long>((utime - utime0) / speed);
  while (!rcal::services::StopRequested()) {
    const long long now = rcal::services::MonotonicMicros();
    if (now >= due) break;
    std::this_thread::sleep_for(std::chrono::microseconds(std::min(due - now, 50'000LL)));
  }
}

// --follow-next-poses: the newest usable NEXT_POSES. A message that does not decode or fit the
// model is refused and counted (HEALTH, naming the field); one older than the newest is stale.
class NextPosesInbox {
 public:
  NextPosesInbox(rcal::transport::Transport& t, const std::string& channel,
                 const rcal::kinematics::KinematicModel& model, rcal::transport::Health& health)
      : t_(t), model_(model), health_(health) {
    t.Subscribe<rcal::next_poses_t>(
        channel, [this](const rcal::next_poses_t& m) { OnMessage(m); },
        [this](const std::string& e) {
          health_.Received();
          health_.Rejected(e);
          spdlog::warn("{}", e);
        });
  }
  const std::optional<rcal::transport::NextPoses>& newest() const { return newest_; }
  /// A stop went where the advice asked (true) or to the programme's stop (false).
  void Count(bool followed) { ++(followed ? followed_ : programme_); }
  /// The end's summary line.
  void LogSummary() const {
    spdlog::info("following NEXT_POSES: {} stops followed, {} the programme's", followed_,
                 programme_);
  }
  /// Handles messages until the newest advice was computed at or after sensor time `utime` [µs],
  /// for at most `timeout_s` of wall time. Returns whether it came.
  bool WaitFor(int64_t utime, double timeout_s) {
    const long long end =
        rcal::services::MonotonicMicros() + static_cast<long long>(timeout_s * 1e6);
    while (!(newest_ && newest_->utime >= utime) && !rcal::services::StopRequested() &&
           rcal::services::MonotonicMicros() < end)
      t_.HandleTimeout(10);
    return newest_ && newest_->utime >= utime;
  }

 private:
  void OnMessage(const rcal::next_poses_t& m) {
    health_.Received();
    std::string error;
    auto n = rcal::transport::NextPosesFromMessage(m, model_, &error);
    if (!n) {
      health_.Rejected(error);
      spdlog::warn("NEXT_POSES refused: {}", error);
      return;
    }
    if (newest_ && n->utime < newest_->utime) {
      health_.Stale("next_poses.utime " + std::to_string(n->utime) + " before the newest " +
                    std::to_string(newest_->utime));
      return;
    }
    newest_ = std::move(n);
  }
  rcal::transport::Transport& t_;
  const rcal::kinematics::KinematicModel& model_;
  rcal::transport::Health& health_;
  std::optional<rcal::transport::NextPoses> newest_;
  int followed_ = 0, programme_ = 0;
};

// --checkpoint: where a restarted simulated source resumes (sensors::SimCheckpoint, a lease
// written before the ticks it covers are published).
struct Resume {
  std::string path;         // empty: no checkpoint, every start begins the programme
  double interval_s = 0.1;  // sensors level: sensor time per lease [s]
};

class Lease {
 public:
  Lease(const Resume& r, const rcal::sensors::SimProgramme& programme, int64_t ticks,
        std::function<int64_t(int64_t)> utime_of)
      : path_(r.path),
        programme_(programme),
        ticks_(std::max<int64_t>(ticks, 1)),
        utime_of_(std::move(utime_of)) {
    if (path_.empty()) return;
    if (const auto c = rcal::sensors::LoadSimCheckpoint(path_, programme_)) {
      first_ = c->next_tick;
      finished_ = c->finished;
      spdlog::info("{}: resuming at tick {} (sensor time {} µs){}", path_, c->next_tick,
                   c->next_utime, c->finished ? ", the programme is finished" : "");
    }
    end_ = first_;
  }
  /// First tick to publish (the programme's end when it was finished).
  int64_t first() const { return finished_ ? std::numeric_limits<int64_t>::max() : first_; }
  /// Before publishing tick k: extends the lease when k is outside it.
  void Before(int64_t k) {
    if (path_.empty() || k < end_) return;
    end_ = k + ticks_;
    Save(end_, false);
  }
  /// Stopped before tick k (SIGINT) or at the programme's end: nothing published is lost.
  void Stopped(int64_t k, bool finished) {
    if (path_.empty() || finished_) return;
    Save(k, finished);
  }

 private:
  void Save(int64_t next, bool finished) {
    rcal::sensors::SaveSimCheckpoint(path_, {programme_, next, utime_of_(next), finished});
  }
  std::string path_;
  rcal::sensors::SimProgramme programme_;
  int64_t ticks_;
  std::function<int64_t(int64_t)> utime_of_;
  int64_t first_ = 0, end_ = 0;
  bool finished_ = false;
};

// The sensor-level simulation of a cell (see the file comment): the cell file's model and sensors,
// the sim file's truth.
int RunSensorSim(const rcal::io::BuiltCell& built, const rcal::cell::CellSimSpec& sim_spec,
                 unsigned seed, int num_cal, int num_test,
                 const std::vector<std::string>& step_offsets,
                 const std::vector<std::string>& sim_effects,
                 const std::vector<double>& payloads_kg,
                 rcal::cell::SimArmConditions::PayloadChangeAt payload_at, double warmup_s,
                 double conditions_late_s, bool follow, bool linger, int64_t start_utime,
                 double speed, const Resume& resume, rcal::transport::LcmTransport& t) {
  using namespace rcal;
  // SimulateWindows' programme: the home pose, then the calibration and test stops.
  cell::SimProgramme sim_run = cell::MakeSimProgramme(built, sim_spec, seed, num_cal, num_test);
  const auto& model = sim_run.cell.model;
  const io::CellChannels& channels = built.spec.channels;
  sim::ToolMotionTruth& truth = sim_run.truth;
  // The arm's conditions: a warming temperature (the session's curve, τ = warmup_s), a payload per
  // stop with --sim-payloads (none without); with --sim-effect the arm grows with the temperature,
  // its joints give way under the payload or stand off their readings (gear, scale, backlash).
  cell::SimArmConditions conditions(warmup_s, start_utime, seed);
  if (!payloads_kg.empty()) {
    if (follow)
      throw std::runtime_error(
          "--follow-next-poses and --sim-payloads: not both at --level sensors (a payload is "
          "taken on in the move to a programme's stop, which following moves)");
    conditions.SetPayloads(truth.trajectory(), payloads_kg, payload_at);
    spdlog::info("the simulated arm carries a payload per stop, drawn from {} kg, taken on {}",
                 fmt::join(payloads_kg, ", "),
                 payload_at == cell::SimArmConditions::PayloadChangeAt::kAtStop
                     ? "at the stop (its window is measured under two loads)"
                     : "halfway through the move to it");
  }
  for (const std::string& line : conditions.ApplyEffects(sim_effects, sim_run))
    spdlog::info("{}", line);
  if (follow && !step_offsets.empty())
    throw std::runtime_error(
        "--follow-next-poses and --step-offset: not both at --level sensors (the step's time is "
        "the programme's stop, which following moves); use --level poses");
  sim::SensorSimSettings ss = cell::SimSensorSettings(built, sim_spec);
  for (const std::string& text : step_offsets) {
    const sim::JointOffsetStep step =
        cell::OffsetStepInProgramme(sim_run, sim::ParseJointOffsetStep(text, model));
    ss.offset_steps.push_back(step);
    spdlog::info(
        "joint {} reads {:+.6g} [rad | m] off from sensor time {:.2f} s ({}): its offset "
        "steps mid-run",
        model.joints()[step.joint].name, -step.delta, step.t_s, text);
  }
  sim::SensorSim sensors(truth, ss, seed);
  const Eigen::Matrix3d pos_cov =
      ss.position.sigma * ss.position.sigma * Eigen::Matrix3d::Identity();
  transport::Health health("sensor_acquisition");
  spdlog::info(
      "sensor_acquisition sim sensors on {}: cell {} ({}), seed {}, {} calibration stops, {} "
      "ticks ({:.1f} s of sensor time), speed {}{}",
      t.url(), built.spec.name, sim_spec.source, seed, num_cal, sensors.num_ticks(),
      truth.trajectory().duration(), speed,
      follow ? ", following NEXT_POSES (the programme's timing after the first followed stop "
               "changes)"
             : "");
  std::optional<NextPosesInbox> advice;
  if (follow) advice.emplace(t, channels.next_poses, model, health);
  const sensors::SimProgramme programme{"sensors", seed,        num_cal,
                                        num_test,  start_utime, ss.rate_hz};
  auto tick_utime = [&](int64_t k) {
    return start_utime + std::llround(static_cast<double>(k) / ss.rate_hz * 1e6);
  };
  Lease lease(resume, programme, std::llround(resume.interval_s * ss.rate_hz), tick_utime);
  // Fast-forward: the skipped ticks draw the same random numbers, so the rest of the programme
  // is exactly the uninterrupted one's.
  const int64_t first = std::min(lease.first(), sensors.num_ticks());
  for (int64_t k = 0; k < first; ++k) sensors.Next();
  if (first >= sensors.num_ticks())
    spdlog::info("the programme is finished: nothing to publish");
  else if (first > 0)
    spdlog::info("resumed at tick {} of {} (sensor time {} µs)", first, sensors.num_ticks(),
                 tick_utime(first));
  const long long wall0 = services::MonotonicMicros();
  const int64_t utime0 = tick_utime(first);
  int64_t published = 0, k = first;
  // Following: the calibration stop the arm leaves next (waypoint 0 is home; 1..num_cal the
  // calibration stops; the last waypoint, the first test stop, is never replaced).
  auto departs = [&](int stop) { return truth.trajectory().StillInterval(stop).second; };  // [s]
  int leaving = 1;
  while (leaving < num_cal && departs(leaving) < static_cast<double>(first) / ss.rate_hz) ++leaving;
  auto choose_next = [&](int stop) {
    const auto& a = advice->newest();
    if (!a) {
      advice->Count(false);
      return;  // the identifier does not advise yet: the programme's stop
    }
    // The stops stood at after the pose the advice was computed for (it cannot know them).
    std::vector<Eigen::VectorXd> since;
    for (int j = 1; j <= stop; ++j)
      if (tick_utime(std::llround(truth.trajectory().StillInterval(j).first * ss.rate_hz)) >
          a->utime)
        since.push_back(truth.trajectory().waypoint(j));
    const auto q = cell::NextStopToFollow(a->q, since);
    if (!q) {
      advice->Count(false);
      spdlog::info(
          "stop {}: the programme's (NEXT_POSES after utime {} has no stop not yet "
          "measured)",
          stop + 1, a->utime);
      return;
    }
    truth.Retarget(stop + 1, *q);
    advice->Count(true);
    spdlog::info(
        "stop {}: NEXT_POSES after utime {} ({} poses used, {} stop(s) behind), predicted task "
        "RMS {:.4f} mm",
        stop + 1, a->utime, a->poses_used, since.size(), a->predicted_rms_m * 1e3);
  };
  auto count = [&](bool ok) {
    if (ok) {
      health.Published();
      ++published;
    }
  };
  // The controller's reports made and not yet published: (sensor time made [s], report).
  std::deque<std::pair<double, transport::ArmConditions>> reports;
  while (!services::StopRequested()) {
    // Leaving a calibration stop: where to next (before the first tick of the move).
    const double t_next = static_cast<double>(k) / ss.rate_hz;  // [s] of the next tick
    while (advice && leaving < num_cal && departs(leaving) < t_next) choose_next(leaving++);
    const auto f = sensors.Next();
    if (!f) break;
    const int64_t utime = start_utime + std::llround(f->t * 1e6);
    Pace(utime, utime0, wall0, speed);
    if (services::StopRequested()) break;
    lease.Before(k++);
    count(t.Publish(channels.joints, transport::ToJointState(model, f->q, utime)));
    // The controller's report, once per second and when the payload it was told to carry
    // changes (a pick or place is reported as it is made; stateless, so a resumed run reports
    // the same): the temperature as its sensor reads it (its noise drawn from the report's own
    // seed) and the payload.
    if (const auto tick = std::llround(f->t * ss.rate_hz);
        tick % std::max<int64_t>(1, std::llround(ss.rate_hz)) == 0 ||
        conditions.ReportedPayload(f->t) != conditions.ReportedPayload(f->t - 1.0 / ss.rate_hz)) {
      transport::ArmConditions c;
      c.utime = utime;
      c.temperature_c = conditions.Reported(f->t, tick);
      c.payload_kg = conditions.ReportedPayload(f->t);
      reports.emplace_back(f->t, c);
    }
    // Each report conditions_late_s after it was made (stamped when made).
    while (!reports.empty() && f->t - reports.front().first >= conditions_late_s - 1e-9) {
      count(t.Publish(channels.arm_conditions, transport::ToArmConditions(reports.front().second)));
      reports.pop_front();
    }
    transport::ImuSample imu;
    imu.utime = utime;
    imu.gyro_B = f->imu.gyro_S;
    imu.f_B = f->imu.accel_S;
    imu.has_mag = true;
    imu.m_B = f->imu.mag_S * 1e-6;  // µT → T
    count(t.Publish(channels.imu, transport::ToMessage(imu)));
    if (f->position) {
      transport::PositionSample pos;
      pos.utime = start_utime + std::llround(f->position->t * 1e6);
      pos.p = f->position->p_M;
      pos.covariance = pos_cov;
      count(t.Publish(channels.position, transport::ToMessage(pos)));
    }
    health.Tick(utime, t);
    t.HandleTimeout(0);  // keeps LCM's receive queue empty
  }
  for (const auto& [made, c] : reports)  // the end of the programme: the rest at once
    count(t.Publish(channels.arm_conditions, transport::ToArmConditions(c)));
  lease.Stopped(k, k >= sensors.num_ticks());
  health.Final(t);
  spdlog::info("done: {} samples published", published);
  if (advice) advice->LogSummary();
  if (linger) {
    // Under a supervisor: stay up (an exit would be restarted, and without --checkpoint replay
    // the programme).
    spdlog::info("lingering until stopped");
    while (!services::StopRequested()) t.HandleTimeout(100);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace rcal;
  namespace ch = transport::channels;
  std::string source = "sim", level = "poses", robot_path = "config/robots/grb3016.yaml", lcm_url;
  unsigned seed = 1;
  int poses = 0;
  double rate = 2.0, speed = 1.0, position_noise = 5e-5, orientation_noise = 1.745e-3;
  int64_t start_utime = 1'000'000;
  CLI::App app{
      "sensor_acquisition: publishes the pipeline's sensor streams.\n"
      "Source sim: the simulated GRB3016 (Table 3 errors) publishes JOINTS and POSE_MEASUREMENT "
      "per still pose, HEALTH at 1 Hz of sensor time.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  std::string replay_file;
  rcal::sensors::RawCsvReplaySettings replay;
  app.add_option("--source", source, "sim | replay (FILE: a raw-stream CSV, BROAD layout)")
      ->check(CLI::IsMember({"sim", "replay"}))
      ->capture_default_str();
  app.add_option("--level", level,
                 "sim: poses (JOINTS + POSE_MEASUREMENT per stop) | sensors (JOINTS, IMU, POSITION "
                 "at 100 Hz from the sensor-level simulation of `rcal experiment paper --sensors`)")
      ->check(CLI::IsMember({"poses", "sensors"}))
      ->capture_default_str();
  int test_poses = 50;
  bool linger = false;
  app.add_flag("--linger", linger,
               "sim sensors: after the programme, stay up until SIGINT/SIGTERM instead of exiting "
               "(under the supervisor, which restarts exited processes)");
  app.add_option("--test-poses", test_poses,
                 "sim sensors: test stops drawn after the calibration stops (as the offline "
                 "experiment's --test; not driven to)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--robot", robot_path,
                 "replay of a pose dataset: the robot (YAML or URDF) its rows are checked against");
  std::string cell_path;
  app.add_option("--cell", cell_path,
                 "replay: the cell file (schema rcal.cell/1): its channels, and its robot for the "
                 "rows of a pose dataset (instead of --robot)");
  std::string sim_path;
  app.add_option("--sim", sim_path,
                 "sim: the simulated cell (schema rcal.cell_sim/1: the cell file it simulates and "
                 "the truth only the simulator knows); default config/cells/grb3016_poses.sim.yaml "
                 "(poses), config/cells/grb3016.sim.yaml (sensors)");
  app.add_option("--seed", seed,
                 "random seed (sim poses: the offline experiment's; sim sensors: default the sim "
                 "file's)")
      ->capture_default_str();
  app.add_option("--poses", poses, "poses to publish, then exit (0: unlimited)")
      ->capture_default_str();
  app.add_option("--rate", rate, "poses per second of sensor time")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--speed", speed, "sensor time per wall time (0: as fast as possible)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--start-utime", start_utime, "sensor time of the first pose [µs]")
      ->capture_default_str();
  app.add_option("--position-noise", position_noise,
                 "replay of a pose dataset: σ per axis in the POSE_MEASUREMENT covariance [m]")
      ->capture_default_str();
  app.add_option("--orientation-noise", orientation_noise,
                 "replay of a pose dataset: σ per axis [rad]")
      ->capture_default_str();
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  app.add_option("file", replay_file,
                 "replay: the raw-stream CSV (t_s, gyr_*, acc_*, mag_*, pos_*)");
  app.add_option("--position-rate", replay.position_rate,
                 "replay: POSITION rate [Hz] (0: every row)")
      ->capture_default_str();
  app.add_option("--mag-scale", replay.mag_scale, "replay: magnetometer file unit → T")
      ->capture_default_str();
  app.add_option("--position-sigma", replay.position_sigma,
                 "replay: σ per axis in the POSITION covariance [m]")
      ->capture_default_str();
  app.add_option("--max-rows", replay.max_rows, "replay: rows to publish (0: all)")
      ->capture_default_str();
  app.add_option("--utime-offset", replay.utime_offset, "replay: added to every utime [µs]")
      ->capture_default_str();
  Resume resume;
  app.add_option("--checkpoint", resume.path,
                 "sim: resume file, written atomically (JSON): a restart with the same command "
                 "line continues the programme where it stopped, sensor time continuing (at most "
                 "--checkpoint-interval of sensor time is lost by a kill), never from t = 0; a "
                 "file of another programme is an error (exit 1)");
  app.add_option("--checkpoint-interval", resume.interval_s,
                 "sim sensors: sensor time covered by one checkpoint write [s]")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  bool include_test = false;
  app.add_flag("--include-test", include_test,
               "replay of a pose dataset: also the rows of the test set");
  std::vector<std::string> step_offsets;
  app.add_option("--step-offset", step_offsets,
                 "sim: JOINT=DELTA@STOP (e.g. j2=1e-3@25): from the approach to calibration stop "
                 "STOP on, joint JOINT (j1..jN or its name) reads DELTA [rad | m] less than where "
                 "it stands, as after an encoder swap and re-mastering: the joint's offset steps "
                 "by DELTA mid-run (repeatable)");
  std::vector<std::string> sim_effects;
  app.add_option(
      "--sim-effect", sim_effects,
      "sim: a non-geometric effect the simulated arm has (at either level), "
      "CAUSE[:JOINT]=V[,V] as "
      "rcal simulate --effect takes it (joint_compliance:j2=2e-6, joint_periodic:j3=1e-4,"
      "5e-5, joint_scale:j4=2e-4, backlash:j5=5e-5, thermal=1.2e-5, thermal:time=3e-9; "
      "repeatable). Every stop's context is published with its pose either way: time since "
      "the start, a warming temperature, a payload of 0, 5 or 10 kg, the approach "
      "direction");
  std::vector<double> payloads_kg;
  app.add_option("--sim-payloads", payloads_kg,
                 "sim sensors: the arm carries a payload per stop drawn from these [kg] (e.g. "
                 "0,5,10), taken on halfway through the move to it, reported on ARM_CONDITIONS; "
                 "without: none")
      ->delimiter(',')
      ->check(CLI::Range(0.0, 1000.0));
  std::string payload_at_text = "move";
  app.add_option("--sim-payload-at", payload_at_text,
                 "sim sensors, --sim-payloads: where the arm takes a new payload on: move (halfway "
                 "through the move to the stop) or stop (halfway through the stop: a grasp at the "
                 "measurement stop, whose still window still_window then refuses)")
      ->check(CLI::IsMember({"move", "stop"}))
      ->capture_default_str();
  double warmup_s = sim::SessionSettings{}.warmup_time_constant_s;
  app.add_option("--sim-warmup", warmup_s,
                 "sim sensors: the time constant [s] of the arm's warm-up (+12 K) that the "
                 "simulated controller reports on ARM_CONDITIONS")
      ->check(CLI::Range(1.0, 1e6))
      ->capture_default_str();
  double conditions_late_s = 0.0;
  app.add_option("--sim-conditions-late", conditions_late_s,
                 "sim sensors: the simulated controller's ARM_CONDITIONS reports reach LCM this "
                 "long [s of sensor time] after they are made (stamped when made): a controller "
                 "bridge slower than the sensors")
      ->check(CLI::Range(0.0, 60.0))
      ->capture_default_str();
  bool follow = false;
  app.add_flag("--follow-next-poses", follow,
               "sim: go where ekf_identifier's NEXT_POSES asks (its best suggestion) instead of to "
               "the programme's next random stop, once it advises (issue 16)");
  double follow_timeout_s = 2.0;
  app.add_option("--follow-timeout", follow_timeout_s,
                 "sim poses, --follow-next-poses: wall time to wait for the advice after a stop "
                 "[s]; without it the last advice's next best stop")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  if (app.get_option("--sim-payload-at")->count() > 0 && payloads_kg.empty()) {
    std::fprintf(stderr, "sensor_acquisition: --sim-payload-at needs --sim-payloads\n");
    return 2;
  }
  const auto payload_at = payload_at_text == "stop"
                              ? cell::SimArmConditions::PayloadChangeAt::kAtStop
                              : cell::SimArmConditions::PayloadChangeAt::kMidMove;
  if (!payloads_kg.empty() && (source != "sim" || level != "sensors")) {
    // The pose-level simulator draws its own payload per stop (0, 5 or 10 kg); a replay has its
    // file's.
    std::fprintf(stderr,
                 "sensor_acquisition: --sim-payloads is for --source sim --level sensors\n");
    return 2;
  }
  if (source == "replay" && replay_file.empty()) {
    std::fprintf(stderr, "sensor_acquisition: --source replay needs FILE\n");
    return 2;
  }

  try {
    services::InstallStopHandlers();
    transport::LcmTransport t(lcm_url);
    if (source == "replay") {
      const std::string path = services::RepoPath(replay_file);
      std::optional<io::BuiltCell> replay_cell;
      if (!cell_path.empty()) replay_cell = io::LoadCell(services::RepoPath(cell_path));
      const io::CellChannels channels =
          replay_cell ? replay_cell->spec.channels : io::CellChannels{};
      if (sensors::IsRawStreamCsv(path)) {
        sensors::RawCsvReplaySource src(path, replay);
        return RunSource(src, t, speed, channels);
      }
      sensors::PoseDatasetReplaySettings ps;
      ps.rate = rate;
      ps.start_utime = start_utime;
      ps.position_sigma = position_noise;
      ps.orientation_sigma = orientation_noise;
      ps.include_test = include_test;
      // With --robot, the rows are checked against it (limits, reach) before any is published.
      std::optional<io::LoadedRobot> replay_robot;
      if (replay_cell) {
        ps.model = &replay_cell->model;
      } else if (app.get_option("--robot")->count() > 0) {
        replay_robot = io::LoadRobot(services::RepoPath(robot_path));
        ps.model = &replay_robot->model;
      } else {
        spdlog::warn(
            "sensor_acquisition: {} is not checked against a robot's joint limits and "
            "reach (give --cell or --robot)",
            path);
      }
      sensors::PoseDatasetReplaySource src(path, ps);
      return RunSource(src, t, speed, channels);
    }
    if (sim_path.empty())
      sim_path = level == "sensors" ? "config/cells/grb3016.sim.yaml"
                                    : "config/cells/grb3016_poses.sim.yaml";
    const cell::CellSimSpec sim_spec = cell::LoadCellSimSpec(services::RepoPath(sim_path));
    const io::BuiltCell built = io::LoadCell(sim_spec.cell);
    if (app.get_option("--seed")->count() == 0) seed = sim_spec.seed;
    if (level == "sensors")
      return RunSensorSim(built, sim_spec, seed, poses > 0 ? poses : sim_spec.num_cal, test_poses,
                          step_offsets, sim_effects, payloads_kg, payload_at, warmup_s,
                          conditions_late_s, follow, linger, start_utime, speed, resume, t);
    // Pose level: the cell's model at the sim file's truth, measured as the cell's position sensor
    // measures (its largest σ per axis; orientation when it is a 6-DoF tracker), one pose per stop.
    const auto& model = built.model;
    const Eigen::VectorXd x_true = cell::TrueErrors(built, sim_spec);
    sim::PoseNoise noise;
    noise.position_sigma = built.spec.position.sigma.maxCoeff();
    noise.orientation_sigma = built.spec.position.orientation_sigma;
    noise.orientation = built.spec.position.orientation;
    if (built.spec.imu)
      throw std::runtime_error(sim_path +
                               ": --level poses simulates a pose-level cell (a 6-DoF tracker or "
                               "positions, no IMU); this cell has an IMU: use --level sensors");
    // The markers the cell's position sensor measures, as slots of the model.
    std::vector<int> slots;
    for (int id : built.spec.position.markers)
      slots.push_back(model.markers().empty() ? 0 : model.MarkerSlot(id));
    // Offset steps: pose k is stop k + 1; its "time" for the step is its stop number.
    std::vector<sim::JointOffsetStep> steps;
    for (const std::string& text : step_offsets) {
      const sim::JointOffsetStepSpec spec = sim::ParseJointOffsetStep(text, model);
      steps.push_back({static_cast<double>(spec.stop), spec.joint, spec.delta});
      spdlog::info(
          "joint {} reads {:+.6g} [rad | m] off from stop {} ({}): its offset steps "
          "mid-run",
          model.joints()[spec.joint].name, -spec.delta, spec.stop, text);
    }
    // Non-geometric effects of the simulated arm (none: its geometry alone), and the conditions
    // of each stop, drawn from their own generator so that the poses' noise is the same with and
    // without them.
    std::vector<sim::TruthEffect> truth_effects;
    for (const std::string& text : sim_effects) {
      truth_effects.push_back(sim::ParseEffectSpec(text, model));
      spdlog::info("the simulated arm has {} ({})",
                   kinematics::ToString(truth_effects.back().effect.cause), text);
    }
    const sim::EffectTruth effect_truth = sim::MakeEffectTruth(model, truth_effects);
    sim::Rng rng(seed * 1000 + 3);
    const sim::SessionSettings session;
    sim::Rng context_rng(seed * 1000 + 7);
    Eigen::VectorXd q_before;  // where the arm stood at the stop before (truth)
    auto stop_context = [&](int64_t k, const Eigen::VectorXd& q) {
      auto c = sim::StopContext(static_cast<double>(k) / rate, q, q_before, session, context_rng);
      q_before = q;
      return c;
    };
    auto measure = [&](int slot, const Eigen::VectorXd& q, const kinematics::EffectContext& c) {
      if (truth_effects.empty())
        return sim::MeasurePose(model.ForMarker(slot), x_true, q, noise, rng);
      return sim::MeasureTruePose(
          effect_truth.model.ForMarker(slot).Forward(q, c, x_true, effect_truth.e), q, noise, rng);
    };
    transport::Health health("sensor_acquisition");
    std::optional<NextPosesInbox> advice;
    if (follow) advice.emplace(t, built.spec.channels.next_poses, model, health);
    spdlog::info("sensor_acquisition sim on {}: {} poses at {} Hz, speed {}", t.url(),
                 poses > 0 ? std::to_string(poses) : "unlimited", rate, speed);

    const int block = poses > 0 ? poses : 1000;
    std::vector<Eigen::VectorXd> qs;
    size_t next = 0;
    const double period_us = 1e6 / rate;
    auto pose_utime = [&](int64_t k) {
      return start_utime + static_cast<int64_t>(std::llround(static_cast<double>(k) * period_us));
    };
    // One pose per lease: a restart resumes at the first pose not yet published.
    Lease lease(resume, {"poses", seed, poses, 0, start_utime, rate}, 1, pose_utime);
    const int64_t first = lease.first();
    if (first > 0 && first < std::numeric_limits<int64_t>::max())
      spdlog::info("resumed at pose {} (sensor time {} µs)", first, pose_utime(first));
    const long long wall0 = services::MonotonicMicros();
    int64_t k = 0;
    Eigen::VectorXd q_last;  // where the arm stood last (truth)
    for (; (poses == 0 || k < poses) && !services::StopRequested(); ++k) {
      if (next == qs.size()) {
        qs = sim::SampleJoints(model, block, rng);
        next = 0;
      }
      Eigen::VectorXd q = qs[next++];
      const int64_t utime = pose_utime(k);
      if (k < first) {
        // Fast-forward: the same random numbers as the uninterrupted programme.
        const auto c = stop_context(k, q);
        for (int slot : slots) measure(slot, q, c);
        continue;
      }
      if (speed > 0) {
        const long long due = wall0 + static_cast<long long>((utime - pose_utime(first)) / speed);
        while (!services::StopRequested()) {
          const long long now = services::MonotonicMicros();
          if (now >= due) break;
          std::this_thread::sleep_for(std::chrono::microseconds(std::min(due - now, 50'000LL)));
        }
      }
      if (services::StopRequested()) break;
      // Following: once the identifier advises, wait for its advice after the last stop's
      // measurements, then go to its best suggestion (joints as read; the arm stands where they
      // read so).
      if (advice && advice->newest() && k > first) {
        const int64_t last = pose_utime(k - 1) + static_cast<int64_t>(slots.size()) - 1;
        const bool came = advice->WaitFor(last, follow_timeout_s);
        std::vector<Eigen::VectorXd> since;
        if (!came) since.push_back(sim::JointsAsRead(q_last, static_cast<double>(k), steps));
        const auto choice = cell::NextStopToFollow(advice->newest()->q, since);
        advice->Count(choice.has_value());
        if (choice) {
          q = sim::TrueJoints(*choice, static_cast<double>(k + 1), steps);
          spdlog::info(
              "pose {}: NEXT_POSES after utime {} ({} poses used){}, predicted task "
              "RMS {:.4f} mm",
              k + 1, advice->newest()->utime, advice->newest()->poses_used,
              came ? "" : " (the advice of the last stop did not come in time)",
              advice->newest()->predicted_rms_m * 1e3);
        } else {
          spdlog::info("pose {}: the programme's stop (no usable NEXT_POSES)", k + 1);
        }
      } else if (advice) {
        advice->Count(false);
      }
      q_last = q;
      lease.Before(k);
      const Eigen::VectorXd q_read = sim::JointsAsRead(q, static_cast<double>(k + 1), steps);
      if (t.Publish(built.spec.channels.joints, transport::ToJointState(model, q_read, utime)))
        health.Published();
      // Each marker the tracker measures at this stop, in the cell's order, 1 µs apart (a tracker
      // measures its reflectors one after the other); pose_index counts the measurements.
      const int n = static_cast<int>(slots.size());
      const kinematics::EffectContext context = stop_context(k, q);
      for (int j = 0; j < n; ++j) {
        auto z = measure(slots[j], q, context);
        z.marker = slots[j];
        const auto index = static_cast<int32_t>(k * n + j);
        if (t.Publish(built.spec.channels.pose_measurement,
                      transport::ToMessage(z, utime + j, index,
                                           transport::MarkerId(model, slots[j]), context)))
          health.Published();
      }
      health.Tick(utime, t);
      t.HandleTimeout(0);  // keeps LCM's receive queue empty
    }
    lease.Stopped(k, poses > 0 && k >= poses);
    if (advice) advice->LogSummary();
    spdlog::info("done");
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
