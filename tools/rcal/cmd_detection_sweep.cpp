// rcal detection-sweep --seeds N --json FILE: how often rcal analyze names a hidden effect
// (right cause and joint) and how often it reports an effect on clean data, over a seeded sweep
// of simulated datasets (each pose-level cause, random joints, magnitudes near the noise floor).
// Not a timed benchmark: the figures are rates.
#include <spdlog/spdlog.h>

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>

#include "command.hpp"
#include "rcal/discrepancy/analysis.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "rcal/sim/effects.hpp"
#include "report.hpp"

namespace rcal::tool {
namespace {

using kinematics::Effect;
using kinematics::EffectCause;
using nlohmann::json;

struct Options {
  int seeds = 20;
  unsigned first_seed = 1000;
  std::string json_path;
  std::string robot = "../shared/data/figaroh_ur10/robot.urdf";
  int poses = 60;
  std::vector<double> magnitudes{2.0, 3.0, 5.0};
  double position_sigma_mm = 0.05;
  double orientation_sigma_deg = 0.0;
  double alpha = 0.01;
  std::string size = "visible";
};

struct Tally {
  int runs = 0, detected = 0, exact = 0, wrong = 0, extra = 0;
};

int Run(const Options& o) {
  io::UrdfOptions uo;
  uo.add_base_frame = true;
  uo.add_marker = true;
  io::LoadedRobot robot = io::LoadRobot(ResolvePath(o.robot), uo);
  if (!robot.from_urdf) {
    if (!robot.spec.base) robot.spec.base = io::FrameSpec{};
    if (!robot.spec.marker && !robot.spec.tool) robot.spec.marker = io::FrameSpec{};
    robot.model = io::BuildModel(robot.spec);
  }
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
  const auto simulate = [&](unsigned seed, const std::optional<Effect>& hidden, double k) {
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
    std::string name;
    EffectCause cause;
    int harmonic;
    Effect::ThermalSource source;
  };
  const std::vector<Kind> kinds = {
      {"joint_compliance", EffectCause::kJointCompliance, 1, Effect::ThermalSource::kTemperature},
      {"joint_periodic h1", EffectCause::kJointPeriodic, 1, Effect::ThermalSource::kTemperature},
      {"joint_periodic h2", EffectCause::kJointPeriodic, 2, Effect::ThermalSource::kTemperature},
      {"joint_scale", EffectCause::kJointScale, 1, Effect::ThermalSource::kTemperature},
      {"backlash", EffectCause::kBacklash, 1, Effect::ThermalSource::kTemperature},
      {"thermal (temperature)", EffectCause::kThermal, 1, Effect::ThermalSource::kTemperature},
      {"thermal (time)", EffectCause::kThermal, 1, Effect::ThermalSource::kTime}};
  std::map<std::pair<std::string, double>, Tally> tallies;
  Tally clean;
  sim::Rng pick(12345);
  for (int s = 0; s < o.seeds; ++s) {
    const unsigned seed = o.first_seed + s;
    {
      const auto d = simulate(seed, std::nullopt, 0);
      const auto a = discrepancy::Analyze(model, d, settings);
      ++clean.runs;
      clean.wrong += !a.effects.empty();
    }
    for (const Kind& kind : kinds) {
      for (double k : o.magnitudes) {
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
          f.joint = j(pick);
        }
        const auto d = simulate(seed, f, k);
        const auto a = discrepancy::Analyze(model, d, settings);
        Tally& t = tallies[{kind.name, k}];
        ++t.runs;
        // Detected: the cause and joint of the vocabulary (thermal: either source); exact: the
        // harmonic order or thermal source too.
        bool hit = false, exact = false;
        for (const auto& e : a.effects) {
          hit |= e.effect.cause == f.cause && e.effect.joint == f.joint;
          exact |= e.effect.SameAs(f);
        }
        t.detected += hit;
        t.exact += exact;
        t.wrong += !a.effects.empty() && !hit;
        t.extra += hit && a.effects.size() > 1;
      }
    }
    spdlog::info("seed {}/{} done", s + 1, o.seeds);
  }

  json rows = json::array();
  std::printf(
      "\n| hidden effect | size (RMS / σ) | runs | detected (cause + joint) | exact (harmonic, "
      "source) | wrong effect only | extra effect too |\n| --- | --- | --- | --- | --- | --- | "
      "--- |\n");
  for (const Kind& kind : kinds)
    for (double k : o.magnitudes) {
      const Tally& t = tallies[{kind.name, k}];
      rows.push_back({{"effect", kind.name},
                      {"rms_over_noise", k},
                      {"runs", t.runs},
                      {"detection_rate", double(t.detected) / t.runs},
                      {"exact_rate", double(t.exact) / t.runs},
                      {"wrong_effect_rate", double(t.wrong) / t.runs},
                      {"extra_effect_rate", double(t.extra) / t.runs}});
      std::printf("| %s | %g | %d | %.0f %% | %.0f %% | %.0f %% | %.0f %% |\n", kind.name.c_str(),
                  k, t.runs, 100.0 * t.detected / t.runs, 100.0 * t.exact / t.runs,
                  100.0 * t.wrong / t.runs, 100.0 * t.extra / t.runs);
    }
  std::printf("| none (clean data) | – | %d | false positive: %.0f %% | | | |\n", clean.runs,
              100.0 * clean.wrong / clean.runs);
  const json j = {{"robot", model.name()},
                  {"poses", o.poses},
                  {"position_noise_m", noise.position_sigma},
                  {"orientation_noise_rad", noise.orientation ? noise.orientation_sigma : 0.0},
                  {"alpha", o.alpha},
                  {"size", o.size},
                  {"seeds", o.seeds},
                  {"first_seed", o.first_seed},
                  {"rows", rows},
                  {"clean_runs", clean.runs},
                  {"false_positive_rate", double(clean.wrong) / clean.runs}};
  if (!o.json_path.empty()) io::AtomicWriteFile(o.json_path, j.dump(2));
  return 0;
}

const RegisterCommand kSweep(
    "detection-sweep", "Detection and false-positive rates of rcal analyze on simulated data",
    [](CLI::App& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--seeds", o->seeds, "datasets per cell")->capture_default_str();
      sub.add_option("--first-seed", o->first_seed, "seed of the first dataset")
          ->capture_default_str();
      sub.add_option("--json", o->json_path, "write the rates here");
      sub.add_option("--robot", o->robot, "robot file (YAML or URDF)")->capture_default_str();
      sub.add_option("--poses", o->poses, "poses per dataset")->capture_default_str();
      sub.add_option("--magnitudes", o->magnitudes,
                     "effect sizes as RMS marker displacement / position σ")
          ->delimiter(',');
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
