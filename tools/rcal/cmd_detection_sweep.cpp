// rcal detection-sweep --seeds N --json FILE: how often rcal analyze names a hidden effect
// (right cause and joint; thermal: with its source) and how often it reports an effect on clean
// data, over a seeded sweep of simulated datasets (each pose-level cause, random joints,
// magnitudes near the noise floor). Not a timed benchmark: the figures are rates.
//
// Every (effect, magnitude, seed index) cell run has its own seed (DetectionCellSeed), from which
// the joint and the dataset are drawn: a cell's result does not depend on which other effects or
// magnitudes the sweep runs.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <future>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>

#include "command.hpp"
#include "detection_sweep.hpp"
#include "rcal/discrepancy/analysis.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/sim/effects.hpp"
#include "report.hpp"
#include "robot_setup.hpp"

namespace rcal::tool {
namespace {

using kinematics::Effect;
using kinematics::EffectCause;
using nlohmann::json;

struct Options {
  int seeds = 20;
  unsigned first_seed = 1000;
  std::string json_path;
  std::string robot = "config/robots/ur10.urdf";  // the real UR10 (FIGAROH), shipped
  std::string tip_link, base_link;                ///< URDF chain (empty: detected, the root)
  int poses = 60;
  std::vector<double> magnitudes{2.0, 3.0, 5.0};
  double position_sigma_mm = 0.05;
  double orientation_sigma_deg = 0.0;
  double alpha = 0.01;
  std::string size = "visible";
  std::vector<std::string> effects;  ///< kind ids to run (and "clean"); empty: all
  int jobs = 1;                      ///< worker threads (the figures do not depend on it)
};

struct Tally {
  int runs = 0, detected = 0, exact = 0, wrong = 0, wrong_source = 0, extra = 0;
  nlohmann::json detail = nlohmann::json::array();  ///< one entry per run
};

nlohmann::json EffectJson(const Effect& e) {
  nlohmann::json j = {{"cause", kinematics::ToString(e.cause)}, {"joint", e.joint}};
  if (e.cause == EffectCause::kJointPeriodic) j["harmonic"] = e.harmonic;
  if (e.cause == EffectCause::kThermal)
    j["thermal_source"] = e.thermal_source == Effect::ThermalSource::kTime ? "time" : "temperature";
  return j;
}

int Run(const Options& o) {
  // The robot as `rcal analyze` loads it for such data: set-up frames added, and the flange →
  // IMU rotation when orientation is measured.
  io::LoadedRobot robot = LoadRobotForCell(o.robot, o.tip_link, o.base_link, "auto");
  if (o.orientation_sigma_deg > 0) AddOrientationFrame(robot);
  if (o.size != "visible" && o.size != "total") throw std::runtime_error("--size: visible|total");
  const kinematics::KinematicModel& model = robot.model;
  const int nj = model.num_joints();
  sim::PoseNoise noise;
  noise.position_sigma = o.position_sigma_mm * 1e-3;
  noise.orientation = o.orientation_sigma_deg > 0;
  noise.orientation_sigma = o.orientation_sigma_deg / kDeg;
  discrepancy::AnalysisSettings settings;
  settings.alpha = o.alpha;

  // One simulated dataset: geometric errors, set-up frames, session, optional hidden effect.
  const auto simulate = [&](std::uint64_t seed, const std::optional<Effect>& hidden, double k) {
    sim::Rng rng(seed);
    Eigen::VectorXd x = sim::RandomErrors(model, rng, 5e-4, 8.7e-4);
    std::normal_distribution<double> n(0.0, 1.0);
    for (int i : identification::SetupParameters(model)) {
      const auto& P = model.parameters()[i];
      x(i) = P.group == "base" ? 0.05 * n(rng) : 0.0;  // σ 0.05 m or 0.05 rad
      if (P.name == "marker_x") x(i) = 0.05;
      if (P.name == "marker_z") x(i) = 0.1;
    }
    const auto qs = sim::SampleJoints(model, o.poses, rng);
    const auto ctx = sim::SampleSession(nj, o.poses, {}, rng);
    std::vector<sim::TruthEffect> fx;
    if (hidden)
      fx.push_back(sim::EffectOfSize(model, *hidden, qs, ctx, x, k * noise.position_sigma, rng, {},
                                     o.size == "visible"));
    discrepancy::PoseData d;
    d.measurements =
        sim::MeasurePosesWithEffects(sim::MakeEffectTruth(model, fx), x, qs, ctx, noise, rng);
    d.contexts = ctx;
    return d;
  };

  struct Kind {
    std::string id, name;
    EffectCause cause;
    int harmonic;
    Effect::ThermalSource source;
  };
  const std::vector<Kind> all_kinds = {
      {"joint_compliance", "joint_compliance", EffectCause::kJointCompliance, 1,
       Effect::ThermalSource::kTemperature},
      {"joint_periodic_h1", "joint_periodic h1", EffectCause::kJointPeriodic, 1,
       Effect::ThermalSource::kTemperature},
      {"joint_periodic_h2", "joint_periodic h2", EffectCause::kJointPeriodic, 2,
       Effect::ThermalSource::kTemperature},
      {"joint_scale", "joint_scale", EffectCause::kJointScale, 1,
       Effect::ThermalSource::kTemperature},
      {"backlash", "backlash", EffectCause::kBacklash, 1, Effect::ThermalSource::kTemperature},
      {"thermal_temperature", "thermal (temperature)", EffectCause::kThermal, 1,
       Effect::ThermalSource::kTemperature},
      {"thermal_time", "thermal (time)", EffectCause::kThermal, 1, Effect::ThermalSource::kTime}};
  const std::set<std::string> wanted(o.effects.begin(), o.effects.end());
  for (const auto& id : wanted)
    if (id != "clean" &&
        std::none_of(all_kinds.begin(), all_kinds.end(), [&](const Kind& k) { return k.id == id; }))
      throw std::invalid_argument(
          "--effects: unknown '" + id +
          "' (known: joint_compliance, joint_periodic_h1, joint_periodic_h2, joint_scale, "
          "backlash, thermal_temperature, thermal_time, clean)");
  std::vector<Kind> kinds;
  for (const Kind& k : all_kinds)
    if (wanted.empty() || wanted.count(k.id)) kinds.push_back(k);
  const bool run_clean = wanted.empty() || wanted.count("clean");
  // Every cell run is a task with its own seed; tasks run on --jobs threads and are tallied in
  // their fixed order afterwards, so the figures do not depend on the number of jobs.
  struct Task {
    unsigned seed_index;
    const Kind* kind;  // nullptr: clean data
    double k;
  };
  struct Done {
    DetectionOutcome r;
    bool any = false;  // clean data: an effect was reported
    json detail;
  };
  std::vector<Task> tasks;
  for (int s = 0; s < o.seeds; ++s) {
    const unsigned seed_index = o.first_seed + s;
    if (run_clean) tasks.push_back({seed_index, nullptr, 0.0});
    for (const Kind& kind : kinds)
      for (double k : o.magnitudes) tasks.push_back({seed_index, &kind, k});
  }
  const auto run_task = [&](const Task& task) {
    Done out;
    if (!task.kind) {
      const std::uint64_t cell_seed = DetectionCellSeed("clean", 0.0, task.seed_index);
      const auto d = simulate(DetectionSubSeed(cell_seed, 2), std::nullopt, 0);
      const auto a = discrepancy::Analyze(model, d, settings);
      json found = json::array();
      for (const auto& e : a.effects) found.push_back(EffectJson(e.effect));
      out.any = !a.effects.empty();
      out.detail = {{"seed_index", task.seed_index}, {"cell_seed", cell_seed}, {"found", found}};
      return out;
    }
    const Kind& kind = *task.kind;
    const std::uint64_t cell_seed = DetectionCellSeed(kind.id, task.k, task.seed_index);
    Effect f{kind.cause};
    f.harmonic = kind.harmonic;
    f.thermal_source = kind.source;
    if (kind.cause == EffectCause::kThermal) {
      f.reference = kind.source == Effect::ThermalSource::kTime ? 0.0 : 20.0;
    } else {
      // Compliance on the joints that carry gravity torque (2–4 of a 6R arm); others anywhere.
      std::uniform_int_distribution<int> j(
          kind.cause == EffectCause::kJointCompliance ? 1 : 0,
          kind.cause == EffectCause::kJointCompliance ? std::min(3, nj - 1) : nj - 1);
      sim::Rng pick(DetectionSubSeed(cell_seed, 1));
      f.joint = j(pick);
    }
    const auto d = simulate(DetectionSubSeed(cell_seed, 2), f, task.k);
    const auto a = discrepancy::Analyze(model, d, settings);
    // Detected: the cause and joint of the vocabulary, thermal with its source (the other source
    // is a wrong cause, counted apart too); exact: the harmonic order too.
    std::vector<Effect> found;
    json found_json = json::array();
    for (const auto& e : a.effects) {
      found.push_back(e.effect);
      found_json.push_back(EffectJson(e.effect));
    }
    out.r = ScoreDetection(f, found);
    out.detail = {{"seed_index", task.seed_index}, {"cell_seed", cell_seed},
                  {"hidden", EffectJson(f)},       {"found", found_json},
                  {"detected", out.r.detected},    {"exact", out.r.exact},
                  {"wrong", out.r.wrong},          {"wrong_source", out.r.wrong_source},
                  {"extra", out.r.extra}};
    return out;
  };
  std::vector<Done> results(tasks.size());
  {
    const auto t_start = std::chrono::steady_clock::now();
    const size_t per_seed = tasks.size() / std::max(1, o.seeds);
    std::atomic<size_t> next{0}, done{0};
    std::mutex log_mutex;
    const auto worker = [&] {
      for (size_t i = next++; i < tasks.size(); i = next++) {
        results[i] = run_task(tasks[i]);
        const size_t n = ++done;
        if (per_seed == 0 || n % per_seed != 0) continue;
        const double elapsed =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
        std::lock_guard lock(log_mutex);
        spdlog::info("{}/{} cell runs done: {:.0f} s elapsed, ~{:.0f} s left", n, tasks.size(),
                     elapsed, elapsed / n * static_cast<double>(tasks.size() - n));
      }
    };
    std::vector<std::future<void>> pool;
    for (int k = 1; k < o.jobs; ++k) pool.push_back(std::async(std::launch::async, worker));
    worker();
    for (auto& f : pool) f.get();
  }
  std::map<std::pair<std::string, double>, Tally> tallies;
  Tally clean;
  for (size_t i = 0; i < tasks.size(); ++i) {
    const Done& r = results[i];
    if (!tasks[i].kind) {
      ++clean.runs;
      clean.wrong += r.any;
      clean.detail.push_back(r.detail);
      continue;
    }
    Tally& t = tallies[{tasks[i].kind->name, tasks[i].k}];
    ++t.runs;
    t.detected += r.r.detected;
    t.exact += r.r.exact;
    t.wrong += r.r.wrong;
    t.wrong_source += r.r.wrong_source;
    t.extra += r.r.extra;
    t.detail.push_back(r.detail);
  }

  json rows = json::array();
  std::printf(
      "\n| hidden effect | size (RMS / σ) | runs | detected (cause + joint, thermal: + source) | "
      "exact (+ harmonic) | wrong effect only | of which thermal, wrong source | extra effect "
      "too |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (const Kind& kind : kinds)
    for (double k : o.magnitudes) {
      const Tally& t = tallies[{kind.name, k}];
      rows.push_back({{"effect", kind.name},
                      {"rms_over_noise", k},
                      {"runs", t.runs},
                      {"detection_rate", double(t.detected) / t.runs},
                      {"exact_rate", double(t.exact) / t.runs},
                      {"wrong_effect_rate", double(t.wrong) / t.runs},
                      {"wrong_thermal_source_rate", double(t.wrong_source) / t.runs},
                      {"extra_effect_rate", double(t.extra) / t.runs},
                      {"detected", t.detected},
                      {"wrong", t.wrong},
                      {"wrong_thermal_source", t.wrong_source},
                      {"extra", t.extra},
                      {"cells", t.detail}});
      std::printf("| %s | %g | %d | %.0f %% | %.0f %% | %.0f %% | %.0f %% | %.0f %% |\n",
                  kind.name.c_str(), k, t.runs, 100.0 * t.detected / t.runs,
                  100.0 * t.exact / t.runs, 100.0 * t.wrong / t.runs,
                  100.0 * t.wrong_source / t.runs, 100.0 * t.extra / t.runs);
    }
  if (run_clean)
    std::printf("| none (clean data) | – | %d | false positive: %d / %d | | | | |\n", clean.runs,
                clean.wrong, clean.runs);
  const json j = {{"robot", model.name()},
                  {"poses", o.poses},
                  {"position_noise_m", noise.position_sigma},
                  {"orientation_noise_rad", noise.orientation ? noise.orientation_sigma : 0.0},
                  {"alpha", o.alpha},
                  {"size", o.size},
                  {"seeds", o.seeds},
                  {"first_seed", o.first_seed},
                  {"seed_rule",
                   "each (effect, magnitude, seed index) cell: its own seed, a hash of the three "
                   "(cell_seed); the joint and the dataset are drawn from streams of it"},
                  {"rows", rows},
                  {"clean_runs", clean.runs},
                  {"false_positives", clean.wrong},
                  {"false_positive_rate", clean.runs ? double(clean.wrong) / clean.runs : 0.0},
                  {"clean_cells", clean.detail}};
  if (!o.json_path.empty()) io::AtomicWriteFile(o.json_path, j.dump(2));
  return 0;
}

const RegisterCommand kSweep(
    "detection-sweep", "Detection and false-positive rates of rcal analyze on simulated data",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--seeds", o->seeds, "datasets per cell")->capture_default_str();
      sub.add_option("--first-seed", o->first_seed, "index of the first seed of each cell")
          ->capture_default_str();
      sub.add_option("--effects", o->effects,
                     "hidden effects to run: joint_compliance, joint_periodic_h1, "
                     "joint_periodic_h2, joint_scale, backlash, thermal_temperature, "
                     "thermal_time, clean (default: all)")
          ->delimiter(',');
      sub.add_option("--json", o->json_path, "write the rates here");
      sub.add_option("--robot", o->robot, "robot file (YAML or URDF)")->capture_default_str();
      sub.add_option("--tip", o->tip_link, "URDF tip link (default: detected)");
      sub.add_option("--base-link", o->base_link, "URDF base link (default: the root)");
      sub.add_option("--poses", o->poses, "poses per dataset")->capture_default_str();
      sub.add_option("--magnitudes", o->magnitudes,
                     "effect sizes as RMS marker displacement / position σ")
          ->delimiter(',');
      sub.add_option("--jobs", o->jobs, "worker threads (the figures do not depend on it)")
          ->capture_default_str()
          ->check(cli::Range(1, 64));
      sub.add_option("--position-sigma-mm", o->position_sigma_mm, "position noise σ per axis")
          ->capture_default_str();
      sub.add_option("--orientation-sigma-deg", o->orientation_sigma_deg,
                     "orientation noise σ; 0: positions only")
          ->capture_default_str();
      sub.add_option("--alpha", o->alpha, "false-positive rate per selection round")
          ->capture_default_str();
      sub.add_option("--size", o->size,
                     "visible: effect size counts only what geometry cannot absorb; total: the "
                     "whole marker displacement")
          ->capture_default_str();
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
