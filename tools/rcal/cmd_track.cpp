// rcal track DATA --robot R [--cell FILE] [--trace T.csv] [--json F]: the online identification
// (change detection included) run over a pose dataset's rows in time order (`time` column, else
// file order), the offline twin of the ekf_identifier process. Rows with set=test are never
// fitted: at each one the tool position predicted with the estimate of that moment is compared
// with the measurement. With --cell the identification is cell::OnlineIdentification on the
// cell's model (its base set, set-up guess and checks, exactly as the process runs it); without,
// an EkfIdentifier on the robot's identifiable set (default settings). An LCM log of the pipeline
// (its POSE_MEASUREMENT events) is taken in the order logged, each pose with its own covariance:
// with --cell, the identifier's input and logic, so the trace's NIS are the live ones.
// The trace has one row per data row: time, set, prediction_error_m (test rows), status,
// changed (the parameters or joint named on the row that detected a change), nis.
//
// With --cell, --discrepancy-every N runs the process's discrepancy watch (cell::
// WatchForDiscrepancy) when it is due, and --discrepancy-switch switches what it suspects in, as
// ekf_identifier does (offline the watch's result is applied at the pose it was due; live it
// arrives about a second later, from a worker thread). Each pose goes in with its context (an LCM
// log's logged one, a CSV's temperature, payload, time and approach columns). The JSON lists every
// watch (`discrepancy_watch`) and the effects identified at the end (`effects`).
//
// rcal track --sweep [--seeds N] [--first-seed S] [--quiet-poses N] [--arm FILE… | --random-arms N
// [--first-arm A]] [--jobs J] [--out DIR]: the seeded tracking experiment (track_sweep.hpp) on the
// shipped arms (or random D–H arms), full poses and positions only; prints the table and writes
// DIR/track_sweep.json.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "command.hpp"
#include "parallel.hpp"
#include "pose_log.hpp"
#include "rcal/cell/discrepancy_watch.hpp"
#include "rcal/cell/online_identification.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/identification/tracking.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/effects_json.hpp"
#include "rcal/io/pose_dataset.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/sim/random_arm.hpp"
#include "rcal/transport/channels.hpp"
#include "report.hpp"
#include "robot_setup.hpp"
#include "track_sweep.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;
using identification::TrackRow;
using nlohmann::json;

struct Options {
  std::string data, robot, cell, trace, json_path;
  std::string tip_link, base_link, frames = "auto";
  double position_sigma_mm = 0.05;
  double orientation_sigma_deg = 0.1;
  bool sweep = false;
  int seeds = 20;
  int first_seed = 0;
  int quiet_poses = 10000;
  std::vector<std::string> arms;
  int random_arms = 0;       // sweep: random D–H arms instead of robot files
  unsigned first_arm = 201;  // sweep: seed of the first random arm
  int jobs = 1;              // sweep: worker threads
  std::string out = "out/track";
  int discrepancy_every = 0;  // --cell: the watch every this many poses taken (0: none)
  bool discrepancy_switch = false;
};

// One run of the discrepancy watch over the rows.
struct WatchRun {
  size_t row = 0;               // index of the row after which it ran
  int accepted = 0, taken = 0;  // poses the EKF accepted, and took (accepted or refused)
  cell::DiscrepancyReport report;
  std::vector<std::string> switched_in;
  std::vector<cell::WithdrawnChange> withdrawn;  // changes the switch withdrew
};

std::string Join(const std::vector<std::string>& v, const char* sep) {
  std::string s;
  for (size_t i = 0; i < v.size(); ++i) s += (i ? sep : "") + v[i];
  return s;
}

// The cell's online identification over the rows (the process's logic).
std::vector<TrackRow> TrackCell(cell::OnlineIdentification& id,
                                const std::vector<kinematics::PoseMeasurement>& ms,
                                const std::vector<kinematics::EffectContext>& contexts,
                                const std::vector<bool>& is_test, const Options& o,
                                std::vector<WatchRun>* watches) {
  cell::DiscrepancyWatchSettings watch;
  watch.every_poses = o.discrepancy_every;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<TrackRow> rows;
  for (size_t k = 0; k < ms.size(); ++k) {
    TrackRow row;
    row.test = is_test[k];
    row.prediction_error_m = row.nis = nan;
    if (row.test) {
      row.rejected = kinematics::Validate(id.model(), ms[k]);
      if (row.rejected.empty())
        row.prediction_error_m = identification::PositionError(id.model(), ms[k], id.ekf().x());
    } else {
      // Sensor time: the row order (rows are sorted by time already), 1 ms apart.
      const auto out =
          id.Add({ms[k], static_cast<int64_t>(k + 1) * 1000, static_cast<int64_t>(k), contexts[k]});
      row.rejected = out.rejected;
      for (const auto& u : out.updates) {
        if (u.pose_index != static_cast<int64_t>(k)) continue;
        row.nis = u.result.nis;
        row.accepted = u.result.accepted;
        if (!u.result.accepted) row.rejected = u.result.reason;
        identification::RecordChanges(id.model(), u.result, row);
      }
      if (out.held) row.rejected = "held for the set-up guess";
      if (!std::isnan(row.nis) && cell::WatchDue(id, watch)) {  // after the row's EKF update
        WatchRun w{k,
                   id.ekf().accepted(),
                   id.ekf().accepted() + id.ekf().rejected(),
                   cell::WatchForDiscrepancy(id, watch),
                   {},
                   {}};
        if (o.discrepancy_switch) {
          for (const auto& e : id.SwitchIn(w.report.NewEffects()))
            w.switched_in.push_back(discrepancy::Describe(id.model(), e));
          w.withdrawn = id.withdrawn();
        }
        watches->push_back(std::move(w));
      }
    }
    row.status = id.ekf().status();
    rows.push_back(std::move(row));
  }
  return rows;
}

int RunData(const Options& o) {
  if (o.robot.empty() && o.cell.empty())
    throw std::runtime_error("rcal track: --robot or --cell is required with DATA");
  if (o.cell.empty() && (o.discrepancy_every > 0 || o.discrepancy_switch))
    throw std::runtime_error(
        "rcal track: --discrepancy-every and --discrepancy-switch need --cell");
  io::LoadedRobot robot;
  std::unique_ptr<cell::OnlineIdentification> id;
  if (!o.cell.empty()) {
    // The cell's model (its set-up frames, markers and priors), as the process has it.
    id = std::make_unique<cell::OnlineIdentification>(io::LoadCell(ResolvePath(o.cell)));
    robot.model = id->model();
  } else {
    robot = LoadRobotForCell(o.robot, o.tip_link, o.base_link, o.frames);
  }
  io::PoseDataset data = LoadPoseDataFor(robot, o.data);
  // A log of the pipeline is the process's own input: each pose with the covariance its still
  // window gave, in the order logged (the order the identifier received them). Through the
  // dataset path it got the fixed --position-sigma-mm instead, and the replay was another filter.
  std::optional<PoseLog> log;
  if (IsLcmLog(ResolvePath(o.data)))
    log = ReadPoseLog(ResolvePath(o.data), robot.model, transport::channels::kPoseMeasurement);
  if (!id) {
    SetUpMarkers(robot, data, {}, o.frames == "auto");
    if (o.frames == "auto" && data.has_orientation) AddOrientationFrame(robot);
  }
  // Time order: the `time` column when every row has one (stable: ties keep file order).
  const bool timed = !log && std::all_of(data.samples.begin(), data.samples.end(),
                                         [](const auto& s) { return std::isfinite(s.time); });
  if (timed)
    std::stable_sort(
        data.samples.begin(), data.samples.end(),
        [](const io::PoseSample& a, const io::PoseSample& b) { return a.time < b.time; });
  const kinematics::KinematicModel& model = robot.model;
  std::vector<kinematics::PoseMeasurement> ms;
  if (log) {
    for (const auto& p : log->poses) ms.push_back(p.measurement);
  } else {
    ms = ToMeasurements(data, model);
    identification::SetNoise(ms, o.position_sigma_mm / kMm, o.orientation_sigma_deg / kDeg);
  }
  std::vector<bool> is_test;
  for (const auto& s : data.samples) is_test.push_back(s.set == io::PoseSample::kTest);

  std::vector<TrackRow> rows;
  std::vector<WatchRun> watches;
  if (id) {
    std::vector<kinematics::EffectContext> contexts;
    if (log)
      for (const auto& p : log->poses) contexts.push_back(p.context);
    else
      contexts = io::ToContexts(data);
    rows = TrackCell(*id, ms, contexts, is_test, o, &watches);
  } else {
    std::vector<kinematics::PoseMeasurement> fit;
    for (size_t k = 0; k < ms.size(); ++k)
      if (!is_test[k]) fit.push_back(ms[k]);
    const auto kind = data.has_orientation ? kinematics::MeasurementKind::kFullPose
                                           : kinematics::MeasurementKind::kPositionOnly;
    std::vector<Eigen::VectorXd> qs;
    for (const auto& m : fit) qs.push_back(m.q);
    const std::vector<int> base =
        kinematics::AnalyzeIdentifiability(model, qs, model.Nominal(), kind).identifiable;
    identification::EkfIdentifier ekf(model, base);
    rows = identification::Track(ekf, ms, is_test);
  }

  // The trace.
  std::ostringstream csv;
  csv << "time,set,prediction_error_m,status,changed,nis\n";
  char buf[64];
  for (size_t k = 0; k < rows.size(); ++k) {
    const TrackRow& r = rows[k];
    const auto& s = data.samples[k];
    if (std::isfinite(s.time)) {
      std::snprintf(buf, sizeof buf, "%.6f", s.time);
      csv << buf;
    } else {
      csv << k;
    }
    csv << ','
        << (s.set == io::PoseSample::kTest  ? "test"
            : s.set == io::PoseSample::kCal ? "cal"
                                            : "")
        << ',';
    if (r.test && std::isfinite(r.prediction_error_m)) {
      std::snprintf(buf, sizeof buf, "%.9g", r.prediction_error_m);
      csv << buf;
    }
    csv << ',' << identification::TrackingStatusName(r.status) << ",\"" << Join(r.changed, ";")
        << "\",";
    if (!r.test && std::isfinite(r.nis)) {
      std::snprintf(buf, sizeof buf, "%.6g", r.nis);
      csv << buf;
    }
    csv << '\n';
  }
  if (!o.trace.empty()) io::AtomicWriteFile(o.trace, csv.str());

  // The summary: each change, the test error between changes, re-convergence.
  json changes = json::array();
  std::vector<size_t> change_rows;
  for (size_t k = 0; k < rows.size(); ++k) {
    if (rows[k].changed.empty()) continue;
    change_rows.push_back(k);
    // Each name with its step [m | rad], and its probability when the names are alternatives.
    const auto named = [](const std::vector<std::string>& names, const std::vector<double>& step,
                          const std::vector<double>& probability) {
      json out = json::array();
      for (size_t i = 0; i < names.size(); ++i) {
        json e = {{"name", names[i]}, {"step", step[i]}};
        if (i < probability.size()) e["probability"] = probability[i];
        out.push_back(e);
      }
      return out;
    };
    const json steps = named(rows[k].changed, rows[k].steps, rows[k].probability);
    int reconverged = -1, poses = 0;
    for (size_t j = k + 1; j < rows.size() && reconverged < 0; ++j) {
      if (rows[j].test) continue;
      ++poses;
      if (rows[j].status == identification::TrackingStatus::kConverged) reconverged = poses;
      if (!rows[j].changed.empty()) break;
    }
    json c = {{"row", data.samples[k].row}, {"changed", steps}};
    // Its second look, when it renamed the change (before the next change).
    for (size_t j = k + 1; j < rows.size(); ++j) {
      if (!rows[j].changed.empty()) break;
      if (rows[j].renamed.empty()) continue;
      c["second_look"] = {
          {"row", data.samples[j].row},
          {"changed", named(rows[j].renamed, rows[j].renamed_steps, rows[j].renamed_probability)}};
    }
    if (std::isfinite(data.samples[k].time)) c["time_s"] = data.samples[k].time;
    if (reconverged > 0) c["reconverged_after_poses"] = reconverged;
    changes.push_back(c);
  }
  json segments = json::array();
  change_rows.push_back(rows.size());
  size_t from = 0;
  for (size_t end : change_rows) {
    std::vector<double> e;
    for (size_t k = from; k < end; ++k)
      if (rows[k].test && std::isfinite(rows[k].prediction_error_m))
        e.push_back(rows[k].prediction_error_m);
    if (end > from)
      segments.push_back({{"first_row", data.samples[from].row},
                          {"last_row", data.samples[end - 1].row},
                          {"test_rows", e.size()},
                          {"median_test_error_m", e.empty() ? json(nullptr) : json(Median(e))}});
    from = end;
  }
  int fitted = 0, accepted = 0;
  for (const auto& r : rows)
    if (!r.test) ++fitted, accepted += r.accepted;
  json j = {{"data", o.data},
            {"robot", o.robot},
            {"rows", rows.size()},
            {"fitted_rows", fitted},
            {"accepted", accepted},
            {"changes", changes},
            {"segments", segments},
            {"final_status",
             rows.empty() ? "converging" : identification::TrackingStatusName(rows.back().status)}};
  if (id) {
    json jw = json::array();
    for (const WatchRun& w : watches) {
      json withdrawn = json::array();
      for (const auto& c : w.withdrawn)
        withdrawn.push_back(
            {{"onset_row", c.onset_pose_index >= 0
                               ? data.samples[static_cast<size_t>(c.onset_pose_index)].row
                               : -1},
             {"changed", c.names},
             {"evidence_gain", c.evidence_gain}});
      json suspects = json::array();
      for (const auto& x : w.report.suspects)
        suspects.push_back({{"effect", x.description}, {"z", x.z}, {"in_model", x.in_model}});
      jw.push_back(
          {{"row", data.samples[w.row].row},
           {"accepted", w.accepted},
           {"taken", w.taken},
           {"window_poses", w.report.window_poses},
           {"window_steps", w.report.window_steps},
           {"chi2_per_dof", w.report.chi2_dof > 0 ? w.report.chi2 / w.report.chi2_dof : 0.0},
           {"suspects", suspects},
           {"heldout_rms_before_m", w.report.heldout_rms_before_m},
           {"heldout_rms_after_m", w.report.heldout_rms_after_m},
           {"switched_in", w.switched_in},
           {"withdrawn_changes", withdrawn}});
      std::printf("  discrepancy watch after row %d (%d poses taken, %d accepted): %s%s\n",
                  data.samples[w.row].row, w.taken, w.accepted,
                  suspects.empty() ? "nothing suspected" : suspects.dump().c_str(),
                  w.switched_in.empty() ? "" : "; switched in");
    }
    j["discrepancy_watch"] = jw;
    const auto& ekf = id->ekf();
    j["effects"] = io::EffectsJson(ekf.extended_model(), ekf.e(), ekf.sigma_e());
  }
  if (!o.json_path.empty()) io::AtomicWriteFile(o.json_path, j.dump(2) + "\n");
  std::printf("%zu rows (%d fitted, %d accepted), %zu change(s) detected, final status %s\n",
              rows.size(), fitted, accepted, changes.size(),
              j["final_status"].get<std::string>().c_str());
  for (const auto& c : changes)
    std::printf("  row %d: %s\n", c["row"].get<int>(), c["changed"].dump().c_str());
  return 0;
}

int RunSweep(const Options& o) {
  if (o.random_arms > 0 && !o.arms.empty())
    throw std::runtime_error("rcal track --sweep: --arm or --random-arms, not both");
  if (o.first_seed + o.seeds > 1000)
    throw std::runtime_error(
        "rcal track --sweep: --first-seed + --seeds past 1000 (seeds 0 … 999)");
  // The arms, each measured as full poses and as positions only: one task each.
  std::vector<TrackSweepArm> tasks;
  if (o.random_arms > 0) {
    sim::RandomArmSettings with_imu;
    with_imu.imu_frame = true;
    for (int a = 0; a < o.random_arms; ++a) {
      const unsigned seed = o.first_arm + static_cast<unsigned>(a);
      const kinematics::KinematicModel arm = sim::RandomDhArm(seed, with_imu);
      tasks.push_back({arm.name(), arm, true});
      tasks.push_back({arm.name(), sim::RandomDhArm(seed), false});
    }
  } else {
    std::vector<std::string> arms = o.arms;
    if (arms.empty())
      arms = {"config/robots/grb3016.yaml", "config/robots/ur10.urdf",
              "tests/data/arms/panda_like.urdf", "tests/data/arms/kr6_like.urdf"};
    for (const std::string& path : arms)
      for (bool full : {true, false}) {
        io::LoadedRobot robot = LoadRobotForCell(path, "", "", "auto");
        if (full) AddOrientationFrame(robot);
        tasks.push_back({fs::path(path).stem().string(), robot.model, full});
      }
  }
  TrackSweepSettings s;
  s.seeds = o.seeds;
  s.first_seed = o.first_seed;
  s.quiet_poses = o.quiet_poses;
  std::vector<std::vector<TrackSweepResult>> results(tasks.size());
  Parallel(static_cast<int>(tasks.size()), o.jobs, [&](int i) {
    results[i] = RunTrackSweep(tasks[i], s);
    spdlog::info("{} ({}): done", tasks[i].name, tasks[i].full_pose ? "full pose" : "positions");
  });
  json jres = json::array();
  std::printf(
      "| arm | measured | step | detected | delay median (max) [poses] | right joint/link named "
      "| detected within 5 poses: rcal / best possible | best possible within 30 "
      "| error after 30 / before, median | false alarms / poses | steady state / former filter, "
      "median |\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (size_t i = 0; i < tasks.size(); ++i) {
    const bool full = tasks[i].full_pose;
    for (const TrackSweepResult& r : results[i]) {
      std::vector<double> d(r.delays.begin(), r.delays.end());
      const double max_delay = d.empty() ? 0 : *std::max_element(d.begin(), d.end());
      const bool quiet = r.quiet_poses > 0;
      auto mean = [](const std::vector<double>& v) {
        double sum = 0;
        for (double x : v) sum += x;
        return v.empty() ? 0.0 : sum / static_cast<double>(v.size());
      };
      const double pct = r.seeds ? 100.0 / r.seeds : 0.0;
      std::printf(
          "| %s | %s | %s | %d/%d | %.0f (%.0f) | %.0f %%%s | %.0f %% / %.0f %% | %.0f %% | %.2f | "
          "%s | %s |\n",
          r.arm.c_str(), full ? "full pose" : "positions", r.kind.c_str(), r.detected, r.seeds,
          Median(d), max_delay, pct * r.named_right,
          r.named_indistinguishable > 0
              ? fmt::format(" ({} by a joint on the same axis)", r.named_indistinguishable).c_str()
              : "",
          pct * r.detected_within_oracle_poses, 100.0 * mean(r.oracle_power),
          100.0 * mean(r.oracle_power_after), Median(r.recovery),
          quiet ? (std::to_string(r.false_alarms) + " / " + std::to_string(r.quiet_poses)).c_str()
                : "",
          quiet ? (std::to_string(Median(r.steady_ratio)).substr(0, 5)).c_str() : "");
      std::fflush(stdout);
      jres.push_back({{"arm", r.arm},
                      {"full_pose", full},
                      {"step", r.kind},
                      {"seeds", r.seeds},
                      {"detected", r.detected},
                      {"delays_poses", r.delays},
                      {"named_right", r.named_right},
                      {"named_indistinguishable", r.named_indistinguishable},
                      {"recovery_ratio", r.recovery},
                      {"error_before_m", r.error_before_m},
                      {"error_after_m", r.error_after_m},
                      {"false_alarms", r.false_alarms},
                      {"quiet_poses", r.quiet_poses},
                      {"steady_ratio", r.steady_ratio},
                      {"stepped", r.stepped},
                      {"seed_delay", r.seed_delay},
                      {"named", r.named},
                      {"named_at_detection", r.named_at_detection},
                      {"named_right_at_detection", r.named_right_at_detection},
                      {"alternatives_at_detection", r.alternatives_at_detection},
                      {"right_among_alternatives", r.right_among_alternatives},
                      {"detected_within_5", r.detected_within_oracle_poses},
                      {"oracle_power_5", r.oracle_power},
                      {"oracle_power_30", r.oracle_power_after},
                      {"oracle_false_alarm", s.oracle_false_alarm},
                      {"first_seed", s.first_seed}});
    }
  }
  io::AtomicWriteFile(fs::path(o.out) / "track_sweep.json", json{{"results", jres}}.dump(1) + "\n");
  return 0;
}

const RegisterCommand kTrack(
    "track",
    "Run the online identification (change detection, re-convergence) over a pose dataset in "
    "time order, or the seeded tracking sweep",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("data", o->data, "pose dataset CSV (rcal or FIGAROH layout)");
      sub.add_option("--robot", o->robot, "robot file (YAML or URDF)");
      sub.add_option("--cell", o->cell,
                     "cell file: run the cell's online identification (as ekf_identifier does)");
      sub.add_option("--trace", o->trace,
                     "write the trace CSV (time, set, prediction_error_m, status, changed, nis)");
      sub.add_option("--json", o->json_path, "write the summary JSON (changes, segments)");
      sub.add_option("--tip", o->tip_link, "URDF: last link of the chain (the flange)");
      sub.add_option("--base-link", o->base_link, "URDF: first link of the chain");
      sub.add_option("--frames", o->frames,
                     "auto: add world←base, marker and IMU frames the robot file lacks; none")
          ->capture_default_str();
      sub.add_option("--position-sigma-mm", o->position_sigma_mm,
                     "position noise per axis (a CSV's rows; an LCM log's poses carry their own)")
          ->capture_default_str();
      sub.add_option("--orientation-sigma-deg", o->orientation_sigma_deg,
                     "orientation noise per axis")
          ->capture_default_str();
      sub.add_option("--discrepancy-every", o->discrepancy_every,
                     "--cell: the process's discrepancy watch every this many poses the EKF "
                     "takes, accepted or refused by its gate (0: none; ekf_identifier's default is "
                     "50)")
          ->capture_default_str()
          ->check(cli::Range(0, 1000000));
      sub.add_flag("--discrepancy-switch", o->discrepancy_switch,
                   "--cell: switch what the watch suspects in (ekf_identifier "
                   "--discrepancy-switch)");
      sub.add_flag("--sweep", o->sweep, "run the seeded tracking sweep instead (no DATA)");
      sub.add_option("--seeds", o->seeds, "sweep: seeds per arm and step")
          ->capture_default_str()
          ->check(cli::Range(1, 1000));
      sub.add_option("--first-seed", o->first_seed,
                     "sweep: the first seed (the README's table: 0; another range gives figures on "
                     "runs nothing was chosen on)")
          ->capture_default_str()
          ->check(cli::Range(0, 999));
      sub.add_option("--quiet-poses", o->quiet_poses,
                     "sweep: poses of the unchanged arm per seed (false alarms)")
          ->capture_default_str();
      sub.add_option("--arm", o->arms, "sweep: robot files (default: four shipped arms)");
      sub.add_option("--random-arms", o->random_arms,
                     "sweep: this many random D–H arms (sim/random_arm.hpp) instead of robot files")
          ->check(cli::Range(0, 1000));
      sub.add_option("--first-arm", o->first_arm, "sweep: seed of the first random arm")
          ->capture_default_str();
      sub.add_option("--jobs", o->jobs, "sweep: worker threads (the figures do not depend on it)")
          ->capture_default_str()
          ->check(cli::Range(1, 256));
      sub.add_option("--out", o->out, "sweep: output folder")->capture_default_str();
      return [o]() {
        if (o->sweep) return RunSweep(*o);
        if (o->data.empty()) throw std::runtime_error("rcal track: DATA is required (or --sweep)");
        return RunData(*o);
      };
    });

}  // namespace
}  // namespace rcal::tool
