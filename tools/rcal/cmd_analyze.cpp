// rcal analyze DATA.csv --robot ROBOT [--out DIR]: where the geometric model disagrees with a pose
// dataset, the cause, the extended model and its gain on held-out poses (discrepancy/analysis.hpp).
// Writes DIR/report.md with plots and DIR/analysis.json (SI units).
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include "analyze_imu.hpp"
#include "command.hpp"
#include "pose_log.hpp"
#include "rcal/discrepancy/analysis.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/identification/sanity.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/effects_json.hpp"
#include "rcal/io/plot.hpp"
#include "rcal/io/pose_dataset.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "report.hpp"
#include "robot_setup.hpp"
#include "significance_json.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct Options {
  std::string data;
  std::string robot;
  std::string tip_link, base_link;
  std::string out = "out/analyze";
  std::string json_path;
  std::string frames = "auto";
  int folds = 5;
  int repeats = 2;
  unsigned seed = 1;
  double alpha = 0.01;
  double position_sigma_mm = 0.1;
  double orientation_sigma_deg = 0.1;
  double stated_position_sigma_mm = 0.0;
  double stated_orientation_sigma_deg = 0.0;
  double link_density = 10.0;
  bool imu = false;         // an LCM log: analyse its IMU channel instead of its poses
  bool allow_gaps = false;  // an LCM log that lost data: go on with what was read
};

// Human units for a regressor: joint angles in degrees, the rest as they are.
double HumanScale(const std::string& unit) {
  return unit == "rad" ? kDeg : 1.0;
}
std::string HumanUnit(const std::string& unit) {
  return unit == "rad" ? "deg" : unit;
}

std::string ValueText(double v, double sigma, const std::string& unit) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "%.4g ± %.2g %s", v, sigma, unit.c_str());
  return buf;
}

io::Series Histogram(const std::string& title, const std::vector<double>& v_mm, double lo,
                     double hi, int bins) {
  io::Series s{title, {}, {}, "linespoints"};
  const double w = (hi - lo) / bins;
  std::vector<double> count(bins, 0.0);
  for (double v : v_mm) count[std::clamp(static_cast<int>((v - lo) / w), 0, bins - 1)] += 1;
  for (int b = 0; b < bins; ++b) {
    s.x.push_back(lo + (b + 0.5) * w);
    s.y.push_back(count[b]);
  }
  return s;
}

int Run(const Options& o) {
  // BROAD layout, or a log's IMU channel: the IMU-stream analysis, no robot.
  if (o.imu || IsImuStreamCsv(ResolvePath(o.data))) {
    AnalyzeImuOptions imu_options{o.data, o.out, o.json_path, o.alpha};
    imu_options.allow_gaps = o.allow_gaps;
    if (o.imu && !IsLcmLog(ResolvePath(o.data)))
      throw std::runtime_error("rcal analyze --imu: " + o.data + " is not an LCM log");
    return RunAnalyzeImu(imu_options);
  }
  if (o.robot.empty()) throw std::runtime_error("rcal analyze: --robot is required for pose data");
  io::LoadedRobot robot = LoadRobotForCell(o.robot, o.tip_link, o.base_link, o.frames);
  const io::PoseDataset data = LoadPoseDataFor(robot, o.data, o.allow_gaps);
  SetUpMarkers(robot, data, {}, o.frames == "auto");
  if (o.frames == "auto" && data.has_orientation)
    AddOrientationFrame(robot, IsLcmLog(ResolvePath(o.data)));
  const kinematics::KinematicModel& model = robot.model;

  discrepancy::PoseData pd;
  bool has_test = false;
  pd.measurements = ToMeasurements(data, model);
  for (const auto& s : data.samples) {
    kinematics::EffectContext c;
    c.temperature_c = s.temperature;
    c.payload_kg = std::isfinite(s.payload) ? s.payload : 0.0;
    c.time_s = s.time;
    c.dq_sign = s.dq_sign;
    pd.contexts.push_back(c);
    pd.is_test.push_back(s.set == io::PoseSample::kTest);
    has_test |= pd.is_test.back();
  }
  identification::SetNoise(pd.measurements, o.position_sigma_mm / kMm,
                           o.orientation_sigma_deg / kDeg);
  discrepancy::AnalysisSettings settings;
  settings.folds = o.folds;
  settings.repeats = o.repeats;
  settings.seed = o.seed;
  settings.alpha = o.alpha;
  settings.stated_position_sigma_m = o.stated_position_sigma_mm / kMm;
  settings.stated_orientation_sigma_rad = o.stated_orientation_sigma_deg / kDeg;
  settings.gravity.link_density_kg_per_m = o.link_density;
  spdlog::info("chain {}", ChainText(robot));
  spdlog::info("{}: {} poses{}, {}, robot {} with {} parameters", o.data, pd.measurements.size(),
               has_test ? " (with a cal/test split)" : "",
               data.has_orientation ? "position and orientation" : "positions only", model.name(),
               model.num_params());
  const discrepancy::Analysis a = discrepancy::Analyze(model, pd, settings);
  // A geometric fit that describes no arm this robot file could be (identification/sanity.hpp):
  // its effects mean nothing, so no analysis.json is written for `calibrate --effects` or
  // ik_corrector to use (an earlier run's is removed); report.md says why; exit code 3.
  identification::CalibrationFigures figures;
  figures.robot = o.robot;
  figures.arm_reach_m = io::ArmReach(model, false);
  figures.nominal_rms_position_m = a.base_fit.nominal_fit.rms_position_m;
  if (settings.estimate_noise) {
    figures.position_sigma_m = a.base_fit.position_sigma_m;
    if (data.has_orientation) figures.orientation_sigma_rad = a.base_fit.orientation_sigma_rad;
  }
  const std::vector<std::string> rejected = identification::CalibrationImplausible(figures);

  const fs::path out(o.out);
  fs::create_directories(out);

  // Plots: the residual against the regressor of each found effect (or of the strongest
  // correlation when none), before and after; held-out error histograms.
  std::vector<const discrepancy::RegressorCorrelation*> shown;
  for (const auto& f : a.effects)
    for (const auto& c : a.correlations)
      if (c.effect.SameAs(f.effect) && c.column == 0) shown.push_back(&c);
  if (shown.empty() && !a.correlations.empty()) shown.push_back(&a.correlations.front());
  std::vector<std::string> plot_files;
  for (size_t k = 0; k < shown.size(); ++k) {
    const auto& c = *shown[k];
    io::Series before{"geometric model", {}, {}, "points"},
        after{"extended model", {}, {}, "points"};
    const double hs = HumanScale(c.unit);
    // A two-valued regressor (approach direction) draws before and after side by side.
    const double shift = c.effect.cause == kinematics::EffectCause::kBacklash ? 0.08 : 0.0;
    for (size_t i = 0; i < c.values.size(); ++i) {
      before.x.push_back(c.values[i] * hs - shift);
      before.y.push_back(c.residual_before_m[i] * kMm);
      after.x.push_back(c.values[i] * hs + shift);
      after.y.push_back(c.residual_after_m[i] * kMm);
    }
    const std::string file = "residual_" + std::to_string(k + 1) + ".png";
    if (io::PlotPng({"Residual along the motion of " + c.regressor,
                     c.regressor + " [" + HumanUnit(c.unit) + "]",
                     "residual [mm]",
                     {before, after}},
                    out / file))
      plot_files.push_back(file);
    else
      plot_files.push_back("");
  }
  {
    std::vector<double> b, f;
    for (double v : a.gain.position_before_m) b.push_back(v * kMm);
    for (double v : a.gain.position_after_m) f.push_back(v * kMm);
    double hi = 0;
    for (double v : b) hi = std::max(hi, v);
    for (double v : f) hi = std::max(hi, v);
    const int bins = std::clamp(static_cast<int>(std::sqrt(b.size())) + 2, 5, 30);
    io::PlotPng({"Held-out position error (" + a.gain.scheme + ")",
                 "position error [mm]",
                 "poses",
                 {Histogram("geometric model", b, 0, hi * 1.001 + 1e-9, bins),
                  Histogram("extended model", f, 0, hi * 1.001 + 1e-9, bins)}},
                out / "heldout_errors.png");
  }

  // analysis.json (SI).
  json jeffects = json::array();
  for (const auto& f : a.effects) {
    json params = json::array();
    for (size_t i = 0; i < f.parameters.size(); ++i)
      params.push_back({{"name", f.parameters[i].name},
                        {"unit", f.parameters[i].unit},
                        {"value", f.values(i)},
                        {"sigma", f.sigma(i)}});
    json je = {{"cause", f.cause},
               {"joints", f.joints},
               {"values", params},
               {"heldout_rms_without_m", f.heldout_rms_without_m}};
    PutZ(je, "selection_z", f.z);
    if (f.outer_folds_selecting >= 0) je["outer_folds_selecting"] = f.outer_folds_selecting;
    if (f.effect.cause == kinematics::EffectCause::kThermal) {
      je["source"] = f.effect.thermal_source == kinematics::Effect::ThermalSource::kTime
                         ? "time"
                         : "temperature";
      je["reference"] = f.effect.reference;
    }
    if (f.effect.cause == kinematics::EffectCause::kJointPeriodic)
      je["harmonic"] = f.effect.harmonic;
    jeffects.push_back(je);
  }
  // Selected on the fit poses but not gaining on held-out ones: never under "effects" (so
  // calibrate --effects and ik_corrector never use them), listed with the reason and figures.
  json jrejected = json::array();
  for (const auto& r : a.rejected) {
    json jr = {{"effect", discrepancy::Describe(model, r.effect)},
               {"cause", kinematics::ToString(r.effect.cause)},
               {"joints", r.effect.joint >= 0 ? json::array({model.joints()[r.effect.joint].name})
                                              : json::array()},
               {"reason", r.reason},
               {"heldout_rms_with_m", r.heldout_rms_with_m},
               {"heldout_rms_without_m", r.heldout_rms_without_m}};
    PutZ(jr, "selection_z", r.z);
    if (r.outer_folds_selecting >= 0) jr["outer_folds_selecting"] = r.outer_folds_selecting;
    jrejected.push_back(jr);
  }
  json jnoise = json::array();
  for (const auto& t : a.noise_tests) {
    json jt = {{"against", t.against},
               {"position_sigma_m", t.position_sigma_m},
               {"orientation_sigma_rad", t.orientation_sigma_rad},
               {"chi2", t.chi2},
               {"dof", t.dof}};
    PutP(jt, "", t.log_p);
    jnoise.push_back(jt);
  }
  json jcorr = json::array();
  for (size_t k = 0; k < a.correlations.size() && k < 12; ++k) {
    json jc = {{"regressor", a.correlations[k].regressor},
               {"unit", a.correlations[k].unit},
               {"correlation", a.correlations[k].correlation}};
    PutP(jc, "", a.correlations[k].log_p);
    jcorr.push_back(jc);
  }
  json jrounds = json::array();
  for (const auto& r : a.rounds) {
    json jr = {{"best", discrepancy::Describe(model, r.tried[r.best])},
               {"z_critical", r.z_critical},
               {"candidates", r.tried.size()},
               {"accepted", r.accepted},
               {"heldout_rms_current_m", r.heldout_rms_current_m},
               {"heldout_rms_best_m", r.heldout_rms_best_m}};
    PutZ(jr, "z", r.z[r.best]);
    jrounds.push_back(jr);
  }
  json jgain = {{"heldout_rms_before_m", a.gain.heldout_rms_before_m},
                {"heldout_rms_after_m", a.gain.heldout_rms_after_m},
                {"relative_gain", a.gain.relative_gain},
                {"scheme", a.gain.scheme},
                {"nested", a.gain.nested}};
  PutZ(jgain, "z", a.gain.z);
  if (a.gain.nested) {
    json outer = json::array();
    for (const auto& c : a.gain.outer_selections) {
      json names = json::array();
      for (const auto& f : c) names.push_back(discrepancy::Describe(model, f));
      outer.push_back(names);
    }
    jgain["outer_selections"] = outer;
    jgain["heldout_rms_after_not_nested_m"] = a.gain.heldout_rms_after_not_nested_m;
  }
  // What the selection saw, so that calibrate --effects can tell whether its held-out rows were
  // among them: the rows fitted (every row without a split, the cal rows with one).
  json fingerprints = json::array();
  for (size_t i = 0; i < pd.measurements.size(); ++i)
    if (!pd.is_test[i]) fingerprints.push_back(io::PoseFingerprint(pd.measurements[i]));
  const json selected_on = {
      {"data", o.data},
      {"rows", pd.measurements.size()},
      {"rows_fitted", a.num_fit_poses},
      {"split", has_test ? "set column: selection on the cal rows, gain on the test rows"
                         : "none: selection on every row, gain by nested k-fold"},
      {"row_fingerprints", fingerprints}};
  const json j = {
      {"data", o.data},
      {"robot", model.name()},
      {"chain", {{"base_link", robot.spec.base_link}, {"tip_link", robot.spec.tip_link}}},
      {"num_poses", pd.measurements.size()},
      {"num_fit_poses", a.num_fit_poses},
      {"num_test_poses", a.num_test_poses},
      {"num_identified", a.base_fit.identified.size()},
      {"link_density_kg_per_m", o.link_density},
      {"position_noise_m", a.base_fit.position_sigma_m},
      {"orientation_noise_rad", a.base_fit.orientation_sigma_rad},
      {"position_noise_after_m", a.position_sigma_after_m},
      {"effects", jeffects},
      {"rejected_effects", jrejected},
      {"gain", jgain},
      {"selected_on", selected_on},
      {"noise_tests", jnoise},
      {"correlations", jcorr},
      {"selection", jrounds},
      {"alpha", settings.alpha},
      {"skipped", a.skipped}};
  if (rejected.empty()) {
    io::AtomicWriteFile(out / "analysis.json", j.dump(2));
    if (!o.json_path.empty()) io::AtomicWriteFile(o.json_path, j.dump(2));
  } else {
    fs::remove(out / "analysis.json");
  }

  // report.md
  std::ostringstream md;
  md << "# rcal analyze\n\n";
  if (!rejected.empty()) {
    md << "**REJECTED**: no analysis.json was written; the geometric fit describes no arm the "
          "robot file could be:\n\n";
    for (const auto& r : rejected) md << "- " << r << "\n";
    md << "\n";
  }
  md << "- Data: `" << o.data << "`, " << pd.measurements.size() << " poses (" << a.num_fit_poses
     << " fitted, " << a.num_test_poses << " test), "
     << (data.has_orientation ? "position and orientation" : "positions only") << "\n- Robot: `"
     << o.robot << "` (" << model.name() << "), " << a.base_fit.identified.size()
     << " geometric parameters identifiable at these poses\n- Chain: " << ChainText(robot)
     << "; positions of the marker"
     << (model.markers().size() > 1 ? "s (one offset each, tip-link frame)" : "")
     << " in the world frame\n- Noise estimated from the geometric fit: "
     << Fmt(a.base_fit.position_sigma_m * kMm, 4) << " mm"
     << (data.has_orientation ? ", " + Fmt(a.base_fit.orientation_sigma_rad * kDeg, 4) + "°" : "")
     << " per axis\n\n## Finding\n\n";
  if (a.effects.empty() && a.rejected.empty()) {
    md << "**No significant effect beyond geometry.** No candidate extension lowered the "
          "held-out error by more than its uncertainty (paired test, α = "
       << settings.alpha << " per round, Bonferroni over the " << a.candidates.size()
       << " candidates tried).\n\n";
  } else if (a.effects.empty()) {
    md << "**No effect beyond geometry that gains on held-out poses.** The selection chose "
          "effects on the fitted poses, but they lose on poses they did not fit (below).\n\n";
  } else {
    std::vector<std::vector<std::string>> rows;
    for (const auto& f : a.effects)
      for (size_t i = 0; i < f.parameters.size(); ++i)
        rows.push_back(
            {i == 0 ? f.cause : "", i == 0 ? (f.joints.empty() ? "arm" : f.joints[0]) : "",
             f.parameters[i].name, ValueText(f.values(i), f.sigma(i), f.parameters[i].unit),
             i == 0 ? discrepancy::ZText(f.z, 1) : ""});
    md << MdTable({"cause", "joint", "parameter", "value ± σ [SI]", "selection z"}, rows) << "\n";
  }
  if (!a.rejected.empty()) {
    md << "### Selected, then rejected on held-out poses\n\nChosen by the selection on the "
          "fitted poses, but not gaining on poses it did not fit: not reported as effects, not "
          "in `effects` of analysis.json (so `rcal calibrate --effects` does not fit them).\n\n";
    std::vector<std::vector<std::string>> rows;
    for (const auto& r : a.rejected)
      rows.push_back({discrepancy::Describe(model, r.effect), discrepancy::ZText(r.z, 1),
                      Fmt(r.heldout_rms_with_m * kMm, 4), Fmt(r.heldout_rms_without_m * kMm, 4),
                      r.outer_folds_selecting >= 0 ? std::to_string(r.outer_folds_selecting) +
                                                         " of " + std::to_string(settings.folds)
                                                   : "–",
                      r.reason});
    md << MdTable({"effect", "selection z", "held-out RMS with [mm]", "without [mm]",
                   "outer folds selecting", "reason"},
                  rows)
       << "\n";
  }
  md << "## Gain on held-out poses (" << a.gain.scheme << ")\n\n"
     << MdTable({"model", "held-out position RMS [mm]"},
                {{"geometric", Fmt(a.gain.heldout_rms_before_m * kMm, 4)},
                 {"extended", Fmt(a.gain.heldout_rms_after_m * kMm, 4)}})
     << "\nRelative gain " << Fmt(100 * a.gain.relative_gain, 1) << " %"
     << (a.effects.empty() ? "" : " (paired z " + discrepancy::ZText(a.gain.z, 1) + ")") << ".\n\n";
  if (a.gain.nested) {
    md << "Nested: each outer fold redid the selection on its training poses alone and was judged "
          "on its held-out poses. The outer folds chose:\n\n";
    for (size_t f = 0; f < a.gain.outer_selections.size(); ++f) {
      std::string names;
      for (const auto& e : a.gain.outer_selections[f])
        names += (names.empty() ? "" : ", ") + discrepancy::Describe(model, e);
      md << "- fold " << f + 1 << ": " << (names.empty() ? "nothing" : names) << "\n";
    }
    if (!a.effects.empty())
      md << "\nThe reported effects refitted in each outer fold but chosen on all poses (not "
            "nested, flattered by the choice; what `rcal calibrate --effects` measures on the "
            "same folds): "
         << Fmt(a.gain.heldout_rms_after_not_nested_m * kMm, 4) << " mm, gain "
         << Fmt(100 * (1 - a.gain.heldout_rms_after_not_nested_m / a.gain.heldout_rms_before_m), 1)
         << " %.\n";
    md << "\n";
  }
  md << "![held-out errors](heldout_errors.png)\n\n## Residuals against the noise\n\n";
  if (a.noise_tests.empty())
    md << "No stated noise (`--stated-position-sigma-mm`) and no repeated poses: the noise is "
          "estimated from the fit itself, so χ² cannot test it.\n\n";
  else {
    std::vector<std::vector<std::string>> rows;
    for (const auto& t : a.noise_tests)
      rows.push_back({t.against, Fmt(t.position_sigma_m * kMm, 4), Fmt(t.chi2, 1), Fmt(t.dof, 0),
                      discrepancy::PText(t.log_p)});
    md << MdTable({"against", "position σ [mm]", "χ²", "dof", "p"}, rows) << "\n";
  }
  md << "## Structure in the residuals\n\nResidual of the geometric fit along the direction "
        "each candidate moves the marker, correlated with its regressor (strongest first):\n\n";
  {
    std::vector<std::vector<std::string>> rows;
    for (size_t k = 0; k < a.correlations.size() && k < 10; ++k)
      rows.push_back({a.correlations[k].regressor, Fmt(a.correlations[k].correlation, 3),
                      discrepancy::PText(a.correlations[k].log_p)});
    md << MdTable({"regressor", "r", "p (single test)"}, rows) << "\n";
  }
  for (size_t k = 0; k < shown.size(); ++k)
    if (!plot_files[k].empty())
      md << "![residual vs " << shown[k]->regressor << "](" << plot_files[k] << ")\n\n";
  md << "## Selection\n\n";
  {
    std::vector<std::vector<std::string>> rows;
    for (size_t r = 0; r < a.rounds.size(); ++r) {
      const auto& R = a.rounds[r];
      rows.push_back({std::to_string(r + 1), discrepancy::Describe(model, R.tried[R.best]),
                      discrepancy::ZText(R.z[R.best], 2), Fmt(R.z_critical, 2),
                      Fmt(R.heldout_rms_current_m * kMm, 4), Fmt(R.heldout_rms_best_m * kMm, 4),
                      R.accepted ? "added" : "stop"});
    }
    md << MdTable(
        {"round", "best candidate", "z", "z critical", "k-fold RMS now [mm]", "with it [mm]", ""},
        rows);
  }
  md << "\nCandidates not tried:\n\n";
  for (const auto& s : a.skipped) md << "- " << s << "\n";
  md << "\n`time_offset` applies to streamed data only; pose data cannot show it.\n";
  io::AtomicWriteFile(out / "report.md", md.str());

  std::printf("\nrcal analyze — %s, %zu poses\n", o.data.c_str(), pd.measurements.size());
  if (a.effects.empty())
    std::printf(a.rejected.empty() ? "  no significant effect beyond geometry\n"
                                   : "  no effect beyond geometry that gains on held-out poses\n");
  for (const auto& r : a.rejected)
    std::printf("  rejected %s (selection z %s): %s\n",
                discrepancy::Describe(model, r.effect).c_str(), discrepancy::ZText(r.z, 1).c_str(),
                r.reason.c_str());
  for (const auto& f : a.effects) {
    std::printf("  %s:", discrepancy::Describe(model, f.effect).c_str());
    for (size_t i = 0; i < f.parameters.size(); ++i)
      std::printf(" %s", ValueText(f.values(i), f.sigma(i), f.parameters[i].unit).c_str());
    std::printf("\n");
  }
  std::printf("  held-out (%s) position RMS: %.4f mm -> %.4f mm (gain %.1f %%)\n",
              a.gain.scheme.c_str(), a.gain.heldout_rms_before_m * kMm,
              a.gain.heldout_rms_after_m * kMm, 100 * a.gain.relative_gain);
  std::printf("  wrote %s\n", (out / "report.md").c_str());
  if (!rejected.empty()) {
    std::string why;
    for (const auto& r : rejected) why += "\n  - " + r;
    spdlog::error("{}: analysis REJECTED, no analysis.json written:{}", o.data, why);
    return 3;
  }
  return 0;
}

const RegisterCommand kAnalyze(
    "analyze",
    "Find what the geometric model gets wrong in a pose dataset, and the gain of fixing it",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("data", o->data, "pose dataset CSV (rcal or FIGAROH layout) or IMU stream CSV")
          ->required();
      sub.add_option("--robot", o->robot, "robot file (YAML or URDF); not for IMU streams");
      sub.add_flag("--imu", o->imu,
                   "DATA is an LCM log: analyse its IMU channel (the sensor model) instead of "
                   "its POSE_MEASUREMENT events");
      sub.add_flag("--allow-gaps", o->allow_gaps,
                   "DATA is an LCM log that lost data (broken frames, undecodable events): go on "
                   "with what could be read (default: refuse, exit non-zero)");
      sub.add_option("--tip", o->tip_link, "URDF: last link of the chain (the flange)");
      sub.add_option("--base-link", o->base_link, "URDF: first link of the chain");
      sub.add_option("--out", o->out, "output folder")->capture_default_str();
      sub.add_option("--json", o->json_path, "also write analysis.json here");
      sub.add_option("--frames", o->frames,
                     "auto: add world←base, marker and IMU frames the robot file lacks; none")
          ->capture_default_str();
      sub.add_option("--folds", o->folds, "k of the k-fold cross-validation")
          ->capture_default_str();
      sub.add_option("--repeats", o->repeats, "k-fold repetitions (averaged)")
          ->capture_default_str();
      sub.add_option("--seed", o->seed, "fold assignment seed")->capture_default_str();
      sub.add_option("--alpha", o->alpha, "false-positive rate per selection round")
          ->capture_default_str();
      sub.add_option("--position-sigma-mm", o->position_sigma_mm, "starting position noise")
          ->capture_default_str();
      sub.add_option("--orientation-sigma-deg", o->orientation_sigma_deg,
                     "starting orientation noise")
          ->capture_default_str();
      sub.add_option("--stated-position-sigma-mm", o->stated_position_sigma_mm,
                     "the noise the sensor claims, for the χ² test (0: none)");
      sub.add_option("--stated-orientation-sigma-deg", o->stated_orientation_sigma_deg,
                     "the orientation noise the sensor claims (0: none)");
      sub.add_option("--link-density", o->link_density,
                     "gravity model for compliance: kg per metre of link")
          ->capture_default_str();
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
