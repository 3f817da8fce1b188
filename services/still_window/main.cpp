// still_window: the still-window stage of the sensor-level pipeline. Subscribes JOINTS, IMU and
// POSITION, runs rcal::estimation::PosePipeline (orientation KF + position KF + still windows,
// exactly as the offline `rcal experiment paper --sensors` does), and publishes one
// POSE_MEASUREMENT per still window (utime: the window's end, pose_index counting from 0), HEALTH
// at 1 Hz of sensor time.
//
// Why the raw streams and not ORIENTATION + TOOL_POSITION: the offline experiment feeds the raw
// samples to PosePipeline, whose window covariance is the scatter of the *raw* FQA and position
// samples the filters accepted; the filter nodes' messages do not carry those. Running the same
// class on the same samples in the same order reproduces the offline windows to rounding.
//
// Input order: PosePipeline needs non-decreasing sensor time across the three streams (ties
// allowed); a sample older than the last one is rejected and counted (HEALTH). Each stream also
// passes its own estimation::TimeGate (--horizon, --resync-samples): an exact duplicate (same
// channel and utime: counted as such, it would make the window's covariance too small), a sample
// before the last of its stream, or beyond the horizon or the host-clock ceiling is refused and
// counted in HEALTH; a stream re-synchronised (its driver restarted) starts the pipeline over.
// Values beyond the sensor's range (transport::SensorRanges) are refused naming the field. A
// filter of the pipeline whose state went non-finite restarts (HEALTH filter_resets). Magnetic
// field: IMU messages carry tesla; the pipeline is given µT (the unit its FQA noise is tuned for).
// Warm-up: the pose pipeline starts its filters at the first stop (the joints standing still) and
// drops that stop's window (estimation::PosePipelineSettings::rest_from_joints), so a process
// started or restarted anywhere, in a move or inside a stop, publishes only windows of filters
// that converged at rest (as the offline experiment drops the home stop). still_window.warmup S
// drops, in addition, the windows that begin within S seconds of the first sample (0: none).
// Settings (--cell FILE, schema rcal.cell/1): the pipeline's noise model from the cell's sensors
// (io::BuiltCell::pipeline), the still-window settings, the IMU's axes (samples turned into the
// mounting frame, v_I = R_IS·v_S) and the channel names. No simulator is involved.
// Clocks: when the input stamps its drivers on one clock by estimating their offsets (ros2_input
// publishes CLOCK_OFFSET), a window is formed only while every source's offset is locked (or
// fixed) and its σ is below --clock-fraction of the window's length
// (estimation::MayFormStillWindow); otherwise the window is refused and counted (HEALTH rejected,
// naming the source). Without CLOCK_OFFSET (one clock: the
// simulator, a replay) nothing changes.
// Context (for an identifier with non-geometric effects): each pose carries the approach
// direction, the sign of each joint's move from the last still window to this one (none at the
// first), its time (the window's end, s of sensor time), and the arm's temperature and payload
// from ARM_CONDITIONS (the controller's reports, its own time gate; estimation::
// ArmConditionsHistory::ForWindow): the newest report at or before the window's middle, if at
// most --conditions-max-age old (its detected end lies up to a second into the next move). A
// window within which the reported payload changed (a grasp at the stop, or a pick reported as
// the arm left) was measured under two loads: it is refused, named and counted in HEALTH. The
// reports come on their own stream, from another process, and may reach still_window after the
// samples that end a window (under a loaded CPU a grasp made inside a window came after it had
// been decided, and the window went out as a pose): once ARM_CONDITIONS has been seen, a window
// is held until a report after its end has come (ArmConditionsHistory::ReportedPast; reports come
// in time order), or until --conditions-wait seconds of sensor time have passed its end, then
// decided on what came, counted in HEALTH gaps with the reason in last_error (so are the windows
// held when the streams end or restart). Windows go out in the order they were formed. A cell
// that sends no ARM_CONDITIONS gets temperature unknown (NaN) and payload 0, as before; once
// reports have come, a window with none standing (the controller went quiet) goes out so too, and
// is counted in HEALTH gaps with the reason in last_error. A report not measured (NaN) stays
// unknown; a payload not known (NaN) goes out as 0. A controller that reports slowly:
// --conditions-max-age at least its period (the stream's time gate then accepts reports that far
// apart, whatever --horizon says).
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <deque>
#include <limits>
#include <optional>

#include "rcal/clock_offset_t.hpp"
#include "rcal/estimation/arm_conditions.hpp"
#include "rcal/estimation/clock_offset.hpp"
#include "rcal/estimation/pose_pipeline.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/services/common.hpp"
#include "rcal/services/time_options.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace {

using namespace rcal;
namespace ch = transport::channels;

class StillWindowNode {
  // A still window formed, awaiting its conditions (Release).
  struct Held {
    kinematics::PoseMeasurement z;
    double t_begin, t_end;  // [s] sensor time
    int imu_samples, position_samples;
    kinematics::EffectContext context;  // approach and time; the conditions when decided
  };

 public:
  /// The final HEALTH (on a clean stop): the counts up to the end.
  void Finish() {
    Release(now_s_, true);
    health_.Final(t_);
  }
  StillWindowNode(const io::BuiltCell& cell, const estimation::TimeGateSettings& time,
                  transport::Transport& t, const std::string& name, double clock_fraction,
                  double conditions_max_age, double conditions_wait)
      : pipeline_(cell.pipeline),
        conditions_wait_(conditions_wait),
        clock_fraction_(clock_fraction),
        conditions_(conditions_max_age),
        warmup_(cell.spec.still_window.warmup),
        R_IS_(cell.spec.imu ? cell.spec.imu->R_IS : Eigen::Matrix3d::Identity()),
        channels_(cell.spec.channels),
        marker_id_(cell.spec.position.markers.front()),
        t_(t),
        health_(name),
        joints_gate_(time),
        imu_gate_(time),
        position_gate_(time),
        conditions_gate_(estimation::ArmConditionsGateSettings(time, conditions_max_age)) {
    t_.Subscribe<joint_state_t>(
        channels_.joints, [this](const joint_state_t& m) { OnJoints(m); },
        [this](const std::string& e) { Bad(e); });
    t_.Subscribe<imu_sample_t>(
        channels_.imu, [this](const imu_sample_t& m) { OnImu(m); },
        [this](const std::string& e) { Bad(e); });
    t_.Subscribe<position_sample_t>(
        channels_.position, [this](const position_sample_t& m) { OnPosition(m); },
        [this](const std::string& e) { Bad(e); });
    t_.Subscribe<clock_offset_t>(
        channels_.clock_offset, [this](const clock_offset_t& m) { OnClock(m); },
        [this](const std::string& e) { Bad(e); });
    t_.Subscribe<arm_conditions_t>(
        channels_.arm_conditions, [this](const arm_conditions_t& m) { OnConditions(m); },
        [this](const std::string& e) { Bad(e); });
  }
  int emitted() const { return emitted_; }

 private:
  static double Seconds(int64_t utime) { return static_cast<double>(utime) * 1e-6; }

  void Bad(const std::string& e) {
    health_.Received();
    health_.Rejected(e);
    spdlog::warn("rejected: {}", e);
  }
  // The stream's time gate; false when refused (counted). On a re-synchronisation the pipeline
  // starts over: its samples so far belong to the old time base.
  bool Admit(estimation::TimeGate& gate, int64_t utime, const char* field) {
    const auto v = health_.Gate(gate, utime, field);
    if (v == estimation::TimeVerdict::kResynchronised) {
      spdlog::warn("{}", health_.last_error());
      Release(now_s_, true);  // the old time base's windows, on what came
      now_s_ = -std::numeric_limits<double>::infinity();
      pipeline_.Reset();
      dropped_ = 0;
      resets_ = 0;
      disagreements_ = 0;
    }
    if (estimation::Usable(v)) return true;
    spdlog::warn("rejected: {}", health_.last_error());
    Beat();
    return false;
  }
  // Heartbeats follow accepted time only: a refused time never schedules one.
  void Beat() {
    std::optional<int64_t> last;
    for (const auto* g : {&joints_gate_, &imu_gate_, &position_gate_})
      if (g->last()) last = std::max(last.value_or(INT64_MIN), *g->last());
    if (last) health_.Tick(*last, t_);
  }
  void Done(int64_t utime, const estimation::Status& s) {
    if (const auto r = pipeline_.counters().filter_resets; r > resets_) {
      resets_ = r;
      health_.FilterReset(s.error());
      spdlog::error("filter reset: {}", s.error());
    }
    if (!s.ok()) {
      health_.Rejected(s.error());
      spdlog::warn("rejected: {}", s.error());
    }
    if (!t_first_) t_first_ = Seconds(utime);
    if (const auto& c = pipeline_.counters(); c.windows_dropped > dropped_) {
      dropped_ = c.windows_dropped;
      spdlog::warn("window dropped ({} so far): {}", dropped_, c.last_error);
    }
    if (const auto& c = pipeline_.counters(); c.heading_disagreements > disagreements_) {
      disagreements_ = c.heading_disagreements;
      spdlog::warn(
          "window heading disagrees with the previous window carried by the gyro (a disturbed "
          "field?): its heading variance widened ({} so far)",
          disagreements_);
    }
    for (const auto& p : pipeline_.TakePoses()) Emit(p);
    now_s_ = std::max(now_s_, Seconds(utime));
    Release(now_s_);
    health_.Tick(utime, t_);
  }
  void OnJoints(const joint_state_t& m) {
    health_.Received();
    if (m.num_joints < 1 || static_cast<int>(m.q.size()) != m.num_joints)
      return Bad("joint_state.q: size does not match num_joints");
    Eigen::VectorXd q(m.num_joints);
    for (int i = 0; i < m.num_joints; ++i) q(i) = m.q[i];
    if (!q.allFinite()) return Bad("joint_state.q: not finite");
    if (!Admit(joints_gate_, m.utime, "joint_state.utime")) return;
    Done(m.utime, pipeline_.AddJoints(Seconds(m.utime), q));
  }
  void OnImu(const imu_sample_t& m) {
    health_.Received();
    std::string error;
    const auto s = transport::ImuFromMessage(m, &error);
    if (!s) return Bad(error);
    if (!s->has_mag) return Bad("imu_sample: no magnetic field");
    if (!Admit(imu_gate_, m.utime, "imu_sample.utime")) return;
    // The sensor's axes turned into the mounting frame (the cell's imu.axes).
    Done(s->utime, pipeline_.AddImu(Seconds(s->utime), R_IS_ * s->gyro_B, R_IS_ * s->f_B,
                                    R_IS_ * s->m_B * 1e6));
  }
  void OnPosition(const position_sample_t& m) {
    health_.Received();
    std::string error;
    const auto s = transport::PositionFromMessage(m, &error);
    if (!s) return Bad(error);
    if (m.marker_id != marker_id_) return;
    if (!Admit(position_gate_, m.utime, "position_sample.utime")) return;
    Done(s->utime, pipeline_.AddPosition(Seconds(s->utime), s->p));
  }
  void OnClock(const clock_offset_t& m) {
    health_.Received();
    std::string error;
    auto clocks = transport::ClockOffsetsFromMessage(m, &error);
    if (!clocks) return Bad(error);
    clocks_ = std::move(*clocks);
  }
  void OnConditions(const arm_conditions_t& m) {
    health_.Received();
    std::string error;
    const auto c = transport::ArmConditionsFromMessage(m, &error);
    if (!c) return Bad(error);
    // Its own gate: a duplicate, an older or a far-future report is refused and counted; the
    // controller restarting on a new time base drops the reports of the old one.
    const auto v = health_.Gate(conditions_gate_, c->utime, "arm_conditions.utime");
    if (v == estimation::TimeVerdict::kResynchronised) conditions_.Clear();
    if (!estimation::Usable(v)) {
      spdlog::warn("rejected: {}", health_.last_error());
      return;
    }
    if (!conditions_seen_)
      spdlog::info("ARM_CONDITIONS: {:.2f} °C, payload {:.3f} kg: poses carry them from now on",
                   c->temperature_c, c->payload_kg);
    conditions_seen_ = true;
    conditions_.Add({Seconds(c->utime), c->temperature_c, c->payload_kg});
    Release(now_s_);
  }
  // The arm's conditions standing at the middle of the window [t_begin, t_end] [s] into `context`
  // (file comment). False: the window is refused (the payload changed within it), counted.
  bool TakeConditions(double t_begin, double t_end, kinematics::EffectContext& context) {
    if (!conditions_seen_) return true;
    const auto w = conditions_.ForWindow(t_begin, t_end);
    if (w.payload_change) {
      health_.Rejected(fmt::format(
          "window {:.3f}–{:.3f} s refused: arm_conditions.payload_kg changed from {:.3f} to "
          "{:.3f} kg at {:.3f} s within it (a pose measured under two loads)",
          t_begin, t_end, w.payload_before_kg, w.payload_change->payload_kg, w.payload_change->t));
      spdlog::warn("{}", health_.last_error());
      return false;
    }
    if (!w.standing) {
      health_.Gap(1);
      health_.Error(fmt::format(
          "window {:.3f}–{:.3f} s: no ARM_CONDITIONS report within {} s before its middle "
          "(temperature not known)",
          t_begin, t_end, conditions_.max_age()));
      if (!conditions_missing_) spdlog::warn("{}", health_.last_error());
      conditions_missing_ = true;
      return true;
    }
    if (conditions_missing_) spdlog::info("ARM_CONDITIONS stand for the windows again");
    conditions_missing_ = false;
    context.temperature_c = w.standing->temperature_c;
    context.payload_kg = std::isnan(w.standing->payload_kg) ? 0.0 : w.standing->payload_kg;
    return true;
  }
  // Why a window of `length_s` may not be formed with the clocks as they are ("" when it may):
  // estimation::MayFormStillWindow for every source whose offset is estimated.
  std::string ClockVeto(double length_s) const {
    if (!clocks_) return "";
    for (const transport::SourceClock& c : *clocks_) {
      if (c.fixed) continue;  // one clock
      const auto source =
          c.source == "imu" ? estimation::ClockSource::kImu : estimation::ClockSource::kMarker;
      if (const estimation::Status st =
              estimation::MayFormStillWindow(c.offset, source, length_s, clock_fraction_);
          !st.ok())
        return c.source + ": " + st.error();
    }
    return "";
  }
  // The direction each joint moved in from the last stop to this one (the sign of the net move,
  // which on a stop-to-stop move of the arm is the direction of its last motion; an encoder
  // dithering by a count at rest does not flip it), and this stop becomes the last. Empty (not
  // known) at the first stop seen.
  Eigen::VectorXi Approach(const Eigen::VectorXd& q) {
    Eigen::VectorXi dir;
    if (q_last_stop_.size() == q.size()) {
      dir = Eigen::VectorXi::Zero(q.size());
      for (int j = 0; j < q.size(); ++j)
        if (q(j) != q_last_stop_(j)) dir(j) = q(j) > q_last_stop_(j) ? 1 : -1;
    }
    q_last_stop_ = q;
    return dir;
  }

  void Emit(const estimation::StillPose& p) {
    const kinematics::PoseMeasurement z = p.ToMeasurement();
    const Eigen::VectorXi approach = Approach(z.q);  // also for a window not published
    if (t_first_ && p.t_begin - *t_first_ < warmup_) {
      spdlog::info("window {:.3f}–{:.3f} s dropped: warm-up", p.t_begin, p.t_end);
      return;
    }
    if (const std::string veto = ClockVeto(p.t_end - p.t_begin); !veto.empty()) {
      health_.Rejected("window " + std::to_string(p.t_begin) + "–" + std::to_string(p.t_end) +
                       " s refused: " + veto);
      spdlog::warn("window {:.3f}–{:.3f} s refused: {}", p.t_begin, p.t_end, veto);
      return;
    }
    Held w{z, p.t_begin, p.t_end, p.imu_samples, p.position_samples, {}};
    w.context.time_s = p.t_end;
    w.context.dq_sign = approach;
    held_.push_back(std::move(w));
  }
  // The windows held for their conditions, in order, decided once ARM_CONDITIONS has reported past
  // their end, or once sensor time `now_s` [s] is --conditions-wait past it, or at once (`all`:
  // the streams ended or restarted; a cell that sends no ARM_CONDITIONS holds nothing).
  void Release(double now_s, bool all = false) {
    while (!held_.empty()) {
      Held& w = held_.front();
      const bool known = !conditions_seen_ || conditions_.ReportedPast(w.t_end);
      if (!known && !all && now_s - w.t_end < conditions_wait_) return;
      if (!known) {
        health_.Gap(1);
        health_.Error(fmt::format(
            "window {:.3f}–{:.3f} s decided without ARM_CONDITIONS past its end ({}): a payload "
            "change within it may not be seen",
            w.t_begin, w.t_end,
            all ? "the streams ended or restarted"
                : fmt::format("waited {} s of sensor time", conditions_wait_)));
        spdlog::warn("{}", health_.last_error());
      }
      Decide(w);
      held_.pop_front();
    }
  }
  void Decide(Held& w) {
    if (!TakeConditions(w.t_begin, w.t_end, w.context)) return;
    const int64_t utime = std::llround(w.t_end * 1e6);
    if (t_.Publish(channels_.pose_measurement,
                   transport::ToMessage(w.z, utime, emitted_, marker_id_, w.context))) {
      health_.Published();
      spdlog::info("pose {}: window {:.3f}–{:.3f} s, {} IMU / {} position samples", emitted_,
                   w.t_begin, w.t_end, w.imu_samples, w.position_samples);
      ++emitted_;
    } else {
      health_.Error("publish failed");
    }
  }

  estimation::PosePipeline pipeline_;
  std::deque<Held> held_;
  double conditions_wait_;
  double clock_fraction_;
  // The input's latest CLOCK_OFFSET, if it sends one.
  std::optional<std::vector<transport::SourceClock>> clocks_;
  // The controller's ARM_CONDITIONS reports (none: the cell sends none).
  estimation::ArmConditionsHistory conditions_;
  bool conditions_seen_ = false, conditions_missing_ = false;
  double warmup_;
  Eigen::Matrix3d R_IS_;
  io::CellChannels channels_;
  // The marker whose samples form the windows: the cell's first (a window per marker for
  // several is not built yet; other markers' samples are ignored, as position_kf ignores them).
  int32_t marker_id_ = 0;
  transport::Transport& t_;
  transport::Health health_;
  std::optional<double> t_first_;
  double now_s_ = -std::numeric_limits<double>::infinity();  // newest sample's time [s]
  int emitted_ = 0;
  Eigen::VectorXd q_last_stop_;  // joints of the last still window (its pose or not)
  std::int64_t dropped_ = 0, resets_ = 0, disagreements_ = 0;
  estimation::TimeGate joints_gate_, imu_gate_, position_gate_, conditions_gate_;
};

}  // namespace

int main(int argc, char** argv) {
  std::string lcm_url, name = "still_window", cell_path = "config/cells/grb3016.yaml";
  estimation::TimeGateSettings time;
  CLI::App app{
      "still_window: still-window pose measurements from the raw sensor streams.\n"
      "Subscribes JOINTS, IMU, POSITION (and ARM_CONDITIONS, CLOCK_OFFSET); runs the pose pipeline "
      "(orientation + position KF, "
      "still windows); publishes POSE_MEASUREMENT per window and HEALTH.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  app.add_option("--cell", cell_path,
                 "cell file (schema rcal.cell/1): sensors, still-window settings, channels")
      ->capture_default_str();
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  services::AddTimeGateOptions(app, &time, "sample");
  app.add_option("--name", name, "process name in HEALTH")->capture_default_str();
  double clock_fraction = estimation::ClockOffsetSettings{}.still_window_sigma_fraction;
  app.add_option("--clock-fraction", clock_fraction,
                 "with CLOCK_OFFSET: a window needs every source's offset locked and its σ below "
                 "this fraction of the window's length")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  double conditions_max_age = 10.0;
  app.add_option("--conditions-max-age", conditions_max_age,
                 "ARM_CONDITIONS: how old [s] the newest report before a window's middle may be "
                 "and still give its pose the temperature and payload")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  double conditions_wait = 2.0;
  app.add_option("--conditions-wait", conditions_wait,
                 "ARM_CONDITIONS: how long [s of sensor time] after a window's end it waits for a "
                 "report past its end before it is decided on what came (a payload change "
                 "reported late falls inside it); at least the controller's report period")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  try {
    services::InstallStopHandlers();
    const io::BuiltCell cell = io::LoadCell(services::RepoPath(cell_path));
    transport::LcmTransport t(lcm_url);
    spdlog::info("still_window on {}: cell {} ({}), {}", t.url(), cell.spec.name, cell.spec.source,
                 cell.pipeline.use_orientation ? "position and orientation" : "positions only");
    StillWindowNode node(cell, time, t, name, clock_fraction, conditions_max_age, conditions_wait);
    if (const int rc =
            rcal::services::ServeUntilStopped([&](int ms) { return t.HandleTimeout(ms); });
        rc != 0)
      return rc;
    node.Finish();
    spdlog::info("stopped: {} poses published", node.emitted());
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
