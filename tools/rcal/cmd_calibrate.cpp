// rcal calibrate DATA.csv --robot ROBOT: identify a robot from a pose dataset, write the
// calibrated robot (YAML, and URDF when it came from URDF), a report and the figures.
// With --effects analysis.json (from `rcal analyze`): also fit the effects the analysis selected
// together with the geometry (identification::FitExtended, weights from the geometric fit's noise,
// the analysis' values as the start), judge geometric and extended models on the same held-out
// poses, and write the calibrated effects (values, σ) to the JSON.
// `rcal calibrate --log LOG` is `rcal calibrate-log LOG` (the same code, calibrate_log.hpp).
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>

#include "calibrate_log.hpp"
#include "command.hpp"
#include "pose_log.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/identification/extended_lm.hpp"
#include "rcal/identification/extended_measurement.hpp"
#include "rcal/identification/sanity.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/calibration_export.hpp"
#include "rcal/io/effects_json.hpp"
#include "rcal/io/plot.hpp"
#include "rcal/io/pose_dataset.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "report.hpp"
#include "robot_setup.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct Options {
  std::string data;
  std::string robot;
  std::string tip_link, base_link;
  std::string out = "out/calibrate";
  std::string json_path;
  std::string method = "lm";
  std::string frames = "auto";
  int folds = 5;
  unsigned seed = 1;
  double position_sigma_mm = 0.1;
  double orientation_sigma_deg = 0.1;
  bool fixed_noise = false;
  std::string effects_path;
  std::vector<std::string> marker_offsets;     ///< ID=x,y,z: known p_FM [m]
  std::vector<std::string> marker_references;  ///< ID=ROW: offset measured at that row's joints
  double link_density = std::numeric_limits<double>::quiet_NaN();  // NaN: the file's, else 10
  CalibrateLogOptions log;  ///< --log LOG: the calibrate-log command
};

json StatsJson(const identification::PoseErrorStats& s, const std::string& prefix) {
  json j;
  j[prefix + "mean_position_error_m"] = s.mean_position_m;
  j[prefix + "max_position_error_m"] = s.max_position_m;
  j[prefix + "rms_position_error_m"] = s.rms_position_m;
  if (!s.orientation_rad.empty()) {
    j[prefix + "mean_orientation_error_rad"] = s.mean_orientation_rad;
    j[prefix + "max_orientation_error_rad"] = s.max_orientation_rad;
  }
  return j;
}

std::vector<std::string> Row(const std::string& name, const identification::PoseErrorStats& s) {
  const bool o = !s.orientation_rad.empty();
  return {name, Fmt(s.mean_position_m * kMm), Fmt(s.max_position_m * kMm),
          o ? Fmt(s.mean_orientation_rad * kDeg) : "n/a",
          o ? Fmt(s.max_orientation_rad * kDeg) : "n/a"};
}

// The extended fit of --effects and its figures.
struct ExtendedResult {
  kinematics::ExtendedModel model;
  identification::ExtendedFit fit;
  identification::PoseErrorStats fit_stats;
  identification::ExtendedHeldOutErrors held;
  // Whether the analysis that selected the effects saw the held-out poses (analysis.json
  // "selected_on"): if it did, the held-out gain of the fixed effect list is not nested (the
  // choice was made on those poses) and flatters; analyze's own gain is the nested figure.
  int heldout_poses = 0;
  int heldout_seen = -1;  ///< held-out poses the selection fitted; −1: the file does not say
  double analysis_gain = std::numeric_limits<double>::quiet_NaN();
  std::string analysis_scheme;
  bool Independent() const { return heldout_seen == 0; }
  std::string Label(const std::string& effects_path) const {
    const std::string own =
        std::isfinite(analysis_gain)
            ? "; the analysis' own gain, selection redone where it is judged: " +
                  Fmt(100 * analysis_gain, 1) + " % (" + analysis_scheme + ")"
            : "";
    if (heldout_seen < 0)
      return "not known to be nested: " + effects_path +
             " does not record the rows it was selected on" + own;
    if (heldout_seen == 0)
      return "independent of the selection: none of the " + std::to_string(heldout_poses) +
             " held-out poses was seen by the analysis that selected the effects";
    return "NOT NESTED: the effects were selected on " + std::to_string(heldout_seen) +
           " of these " + std::to_string(heldout_poses) +
           " held-out poses, so the gain of this fixed list is flattered by the choice" + own;
  }
};

// Every pose must carry what the effects depend on: temperature or time for thermal, the approach
// direction for backlash.
void CheckContexts(const kinematics::ExtendedModel& ext,
                   const std::vector<kinematics::EffectContext>& contexts,
                   const std::string& data) {
  for (const kinematics::Effect& f : ext.effects()) {
    const bool thermal = f.cause == kinematics::EffectCause::kThermal;
    for (size_t i = 0; i < contexts.size(); ++i) {
      const auto& c = contexts[i];
      if (thermal && !std::isfinite(kinematics::ThermalRegressor(f, c)))
        throw std::runtime_error(
            "--effects: thermal needs a " +
            std::string(f.thermal_source == kinematics::Effect::ThermalSource::kTime
                            ? "time"
                            : "temperature") +
            " column in " + data + " (row " + std::to_string(i + 1) + " has none)");
      if (f.cause == kinematics::EffectCause::kBacklash && c.dq_sign.size() == 0)
        throw std::runtime_error("--effects: backlash needs the dq1..dqN columns in " + data +
                                 " (row " + std::to_string(i + 1) + " has none)");
      const std::string why = identification::ValidateContext(ext, c);
      if (!why.empty())
        throw std::runtime_error(data + ": row " + std::to_string(i + 1) + ": " + why);
    }
  }
}

ExtendedResult FitEffects(const Options& o, const kinematics::KinematicModel& model,
                          const io::PoseDataset& data,
                          const std::vector<kinematics::PoseMeasurement>& ms,
                          const std::vector<bool>& is_test,
                          const identification::CalibrationFit& fit,
                          const identification::CalibrationSettings& settings) {
  const io::AnalysisEffects ae = io::ReadAnalysisEffects(ResolvePath(o.effects_path), model);
  kinematics::GravityModel gravity;  // --link-density, else the analysis', else 10 kg/m
  gravity.link_density_kg_per_m = std::isfinite(o.link_density) ? o.link_density
                                  : std::isfinite(ae.link_density_kg_per_m)
                                      ? ae.link_density_kg_per_m
                                      : 10.0;
  kinematics::ExtendedModel ext(model, ae.effects, gravity);
  const std::vector<kinematics::EffectContext> contexts = io::ToContexts(data);
  CheckContexts(ext, contexts, o.data);
  std::vector<kinematics::PoseMeasurement> fit_ms;
  std::vector<kinematics::EffectContext> fit_ctx;
  for (size_t i = 0; i < ms.size(); ++i)
    if (!is_test[i]) {
      fit_ms.push_back(ms[i]);
      fit_ctx.push_back(contexts[i]);
    }
  identification::SetNoise(fit_ms, fit.position_sigma_m, fit.orientation_sigma_rad);
  spdlog::info("fitting geometry and {} effect(s) ({} parameters) from {}", ae.effects.size(),
               ext.num_effect_params(), o.effects_path);
  identification::ExtendedFit ef = identification::FitExtended(ext, fit.identified, fit_ms, fit_ctx,
                                                               fit.x, ae.values, !o.fixed_noise);
  std::vector<double> p, r_o;
  Eigen::VectorXd r;
  for (size_t i = 0; i < fit_ms.size(); ++i) {
    identification::ExtendedResidualAndJacobian(ext, fit_ms[i], fit_ctx[i], ef.x, ef.e, {}, r,
                                                nullptr);
    p.push_back(r.head<3>().norm());
    if (r.size() == 6) r_o.push_back(r.tail<3>().norm());
  }
  spdlog::info("judging geometric and extended models on poses not fitted...");
  identification::ExtendedHeldOutErrors held =
      identification::HeldOutExtended(ext, ms, contexts, is_test, fit, ae.values, settings);
  ExtendedResult out{std::move(ext),
                     std::move(ef),
                     identification::Summarize(p, r_o),
                     std::move(held),
                     0,
                     -1,
                     ae.analysis_relative_gain,
                     ae.analysis_gain_scheme};
  // Held-out poses: the test rows with a split, every row with k-fold.
  const bool split = std::find(is_test.begin(), is_test.end(), true) != is_test.end();
  out.heldout_seen = ae.has_selection_rows ? 0 : -1;
  for (size_t i = 0; i < ms.size(); ++i)
    if (!split || is_test[i]) {
      ++out.heldout_poses;
      if (ae.has_selection_rows && ae.selection_rows.count(io::PoseFingerprint(ms[i])))
        ++out.heldout_seen;
    }
  return out;
}

// Every marker's offset comes from somewhere: fitted from its calibration rows, given
// (--marker-offset), or measured at a stated configuration (--marker-reference ID=ROW, a marker
// seen only in test rows). Returns the measured ones; throws naming the marker otherwise.
std::vector<identification::MarkerReference> MarkerReferences(
    const Options& o, const io::PoseDataset& data, const kinematics::KinematicModel& model,
    const std::vector<kinematics::PoseMeasurement>& ms, const std::vector<bool>& is_test) {
  const std::map<int, int> rows = ParseMarkerRows(o.marker_references, "--marker-reference");
  const std::map<int, Eigen::Vector3d> known =
      ParseMarkerOffsets(o.marker_offsets, "--marker-offset");
  std::set<int> ids, fitted;
  for (size_t i = 0; i < data.samples.size(); ++i) {
    ids.insert(data.samples[i].marker);
    if (!is_test[i]) fitted.insert(data.samples[i].marker);
  }
  std::vector<identification::MarkerReference> out;
  for (const auto& [id, row] : rows) {
    if (!ids.count(id))
      throw std::runtime_error("--marker-reference " + std::to_string(id) + "=" +
                               std::to_string(row) + ": no row of " + o.data + " measures marker " +
                               std::to_string(id));
    if (fitted.count(id))
      throw std::runtime_error(
          "--marker-reference " + std::to_string(id) + "=" + std::to_string(row) + ": marker " +
          std::to_string(id) +
          " has calibration rows, so its offset is fitted; a reference is for a marker measured "
          "only in test rows (set = test)");
    if (known.count(id))
      throw std::runtime_error("marker " + std::to_string(id) +
                               ": --marker-offset and --marker-reference both given");
    int index = -1;
    for (size_t i = 0; i < data.samples.size(); ++i)
      if (data.samples[i].row == row) index = static_cast<int>(i);
    if (index < 0 || data.samples[index].marker != id)
      throw std::runtime_error("--marker-reference " + std::to_string(id) + "=" +
                               std::to_string(row) + ": data row " + std::to_string(row) + " of " +
                               o.data + " does not measure marker " + std::to_string(id));
    out.push_back({ms[index].marker, index});
  }
  for (int id : ids)
    if (!fitted.count(id) && !known.count(id) && !rows.count(id))
      throw std::runtime_error(
          "marker " + std::to_string(id) +
          " appears only in test rows, so nothing fits its offset: give it with --marker-offset " +
          std::to_string(id) + "=x,y,z [m, " + model.name() +
          " flange frame] or name a row measuring it at a stated configuration with "
          "--marker-reference " +
          std::to_string(id) + "=ROW");
  if (!out.empty() && !o.effects_path.empty())
    throw std::runtime_error(
        "--marker-reference with --effects is not supported: give the "
        "marker's offset with --marker-offset");
  return out;
}

int Run(const Options& o) {
  if (!o.log.log.empty()) {
    if (!o.data.empty()) throw std::runtime_error("rcal calibrate: give DATA or --log, not both");
    CalibrateLogOptions lo = o.log;
    lo.effects_path = o.effects_path;  // identified with the geometry, as ekf_identifier --effects
    if (!o.robot.empty())
      throw std::runtime_error(
          "rcal calibrate --log: the robot comes from --cell (a cell file "
          "names its robot file), not --robot");
    lo.json_path = o.json_path;
    return RunCalibrateLog(lo);
  }
  if (o.data.empty()) throw std::runtime_error("rcal calibrate: DATA is required (or --log LOG)");
  if (o.robot.empty()) throw std::runtime_error("rcal calibrate: --robot is required");
  // The robot with the set-up frames a real cell has (URDF chains get them; YAML files get what
  // they lack), and the IMU/marker rotation when the data measures orientation.
  io::LoadedRobot robot = LoadRobotForCell(o.robot, o.tip_link, o.base_link, o.frames);
  const io::PoseDataset data = LoadPoseDataFor(robot, o.data, o.log.allow_gaps);
  SetUpMarkers(robot, data, ParseMarkerOffsets(o.marker_offsets, "--marker-offset"),
               o.frames == "auto");
  if (o.frames == "auto" && data.has_orientation)
    AddOrientationFrame(robot, IsLcmLog(ResolvePath(o.data)));
  const auto& model = robot.model;
  spdlog::info("chain {}", ChainText(robot));

  std::vector<kinematics::PoseMeasurement> ms = ToMeasurements(data, model);
  std::vector<bool> is_test;
  for (const auto& s : data.samples) is_test.push_back(s.set == io::PoseSample::kTest);
  const std::vector<identification::MarkerReference> references =
      MarkerReferences(o, data, model, ms, is_test);
  identification::SetNoise(ms, o.position_sigma_mm / kMm, o.orientation_sigma_deg / kDeg);
  identification::CalibrationSettings settings;
  settings.method = o.method == "ekf" ? identification::CalibrationSettings::Method::kEkf
                                      : identification::CalibrationSettings::Method::kLm;
  if (o.method != "ekf" && o.method != "lm") throw std::runtime_error("--method: lm or ekf");
  settings.estimate_noise = !o.fixed_noise;
  settings.folds = o.folds;
  settings.seed = o.seed;

  // Fit on the calibration poses only when there is a split; judge on the rest.
  std::vector<kinematics::PoseMeasurement> fit_set;
  for (size_t i = 0; i < ms.size(); ++i)
    if (!is_test[i]) fit_set.push_back(ms[i]);
  spdlog::info("{}: {} poses ({} for fitting), {}, robot {} with {} parameters", o.data, ms.size(),
               fit_set.size(), data.has_orientation ? "position and orientation" : "positions only",
               model.name(), model.num_params());
  identification::CalibrationFit fit = identification::Calibrate(model, fit_set, settings);
  // Markers measured at a stated configuration (test rows only): their offsets from that row.
  for (const auto& ref : references) {
    const auto& marker = model.markers()[ref.slot];
    for (Eigen::VectorXd* x : {&fit.x_nominal, &fit.x}) {
      const Eigen::Vector3d p_FM = identification::MarkerOffsetFromPoint(
          model, ref.slot, *x, ms[ref.measurement].q, ms[ref.measurement].p_WM_W);
      for (int a = 0; a < 3; ++a)
        if (marker.param[a] >= 0) (*x)(marker.param[a]) = p_FM(a) - marker.nominal(a);
    }
    spdlog::info("marker {}: offset from row {}, not fitted", marker.id,
                 data.samples[ref.measurement].row);
  }
  spdlog::info("fitted {} parameters ({} set-up); noise σ {:.3f} mm{}", fit.identified.size(),
               fit.setup.size(), fit.position_sigma_m * kMm,
               data.has_orientation ? ", " + Fmt(fit.orientation_sigma_rad * kDeg, 3) + "°"
                                    : std::string(" (positions only)"));
  std::optional<ExtendedResult> ext;
  identification::HeldOutErrors held;
  if (!o.effects_path.empty()) {
    ext = FitEffects(o, model, data, ms, is_test, fit, settings);
    held = {ext->held.scheme, ext->held.nominal, ext->held.geometric};
  } else {
    spdlog::info("judging on poses not fitted...");
    held = identification::HeldOut(model, ms, is_test, fit, settings, references);
  }

  // A fit that describes no arm this robot file could be (identification/sanity.hpp) is refused:
  // no calibrated robot is written (an earlier run's is removed from --out, so none is left to be
  // deployed by mistake); the report and results.json say why, and the exit code is 3.
  identification::CalibrationFigures figures;
  figures.robot = o.robot;
  figures.arm_reach_m = io::ArmReach(model, false);
  figures.nominal_rms_position_m = fit.nominal_fit.rms_position_m;
  figures.heldout_nominal_rms_position_m = held.nominal.rms_position_m;
  figures.heldout_rms_position_m = held.calibrated.rms_position_m;
  if (!o.fixed_noise) {
    figures.position_sigma_m = fit.position_sigma_m;
    if (data.has_orientation) figures.orientation_sigma_rad = fit.orientation_sigma_rad;
  }
  const std::vector<std::string> rejected = identification::CalibrationImplausible(figures);

  const fs::path out(o.out);
  fs::create_directories(out);
  const std::vector<std::string> header = {" calibrated by rcal calibrate from " + o.data,
                                           " held-out (" + held.scheme + ") mean position error " +
                                               Fmt(held.calibrated.mean_position_m * kMm, 4) +
                                               " mm (nominal " +
                                               Fmt(held.nominal.mean_position_m * kMm, 4) + " mm)"};
  if (!rejected.empty()) {
    for (const char* f :
         {"robot_calibrated.yaml", "robot_calibrated.urdf", "robot_calibrated_extended.yaml"})
      fs::remove(out / f);
  } else {
    io::SaveCalibratedRobotYaml(out / "robot_calibrated.yaml", robot.spec, model, fit.x, header);
  }
  if (rejected.empty() && robot.from_urdf)
    io::SaveCalibratedUrdf(robot.source, out / "robot_calibrated.urdf", robot.spec, model, fit.x);
  if (rejected.empty() && ext)  // the geometry that goes with the calibrated effects
    io::SaveCalibratedRobotYaml(
        out / "robot_calibrated_extended.yaml", robot.spec, model, ext->fit.x,
        {" calibrated by rcal calibrate --effects " + o.effects_path + " from " + o.data,
         " geometric part of the extended model; its effects are in results.json"});

  std::vector<double> idx, before, after;
  for (size_t i = 0; i < fit.nominal_fit.position_m.size(); ++i) {
    idx.push_back(i + 1);
    before.push_back(fit.nominal_fit.position_m[i] * kMm);
    after.push_back(fit.calibrated_fit.position_m[i] * kMm);
  }
  io::PlotPng({"Position error per fitted pose",
               "pose",
               "position error [mm]",
               {{"nominal (set-up frames fitted)", idx, before, "impulses"},
                {"calibrated", idx, after, "points"}}},
              out / "errors.png");

  std::vector<std::vector<std::string>> prows;
  json jparams = json::array();
  for (int i : fit.identified) {
    const auto& P = model.parameters()[i];
    const double u = P.is_angle ? kDeg : kMm;
    prows.push_back({P.name, ParameterFrame(robot, i), P.is_angle ? "deg" : "mm",
                     Fmt(fit.x(i) * u, 4), Fmt(fit.sigma(i) * u, 4)});
    jparams.push_back({{"name", P.name},
                       {"frame", ParameterFrame(robot, i)},
                       {"unit", P.is_angle ? "rad" : "m"},
                       {"value", fit.x(i)},
                       {"sigma", fit.sigma(i)}});
  }
  // The calibrated set-up frames, whole (identified or not), each in its frame.
  const io::RobotSpec calibrated = io::CalibratedSpec(robot.spec, model, fit.x);
  const std::string& base_link = robot.spec.base_link;
  const std::string& tip_link = robot.spec.tip_link;
  std::vector<std::vector<std::string>> frows;
  json jframes = json::object();
  const auto mm3 = [](const Eigen::Vector3d& v) {
    return Fmt(v.x() * kMm, 3) + ", " + Fmt(v.y() * kMm, 3) + ", " + Fmt(v.z() * kMm, 3);
  };
  const auto deg3 = [](const Eigen::Vector3d& v) {
    return Fmt(v.x() * kDeg, 4) + ", " + Fmt(v.y() * kDeg, 4) + ", " + Fmt(v.z() * kDeg, 4);
  };
  const auto vec = [](const Eigen::Vector3d& v) {
    return std::vector<double>{v.x(), v.y(), v.z()};
  };
  if (calibrated.base) {
    frows.push_back(
        {"world ← " + base_link, "T_WB",
         "xyz " + mm3(calibrated.base->xyz) + " mm; rpy " + deg3(calibrated.base->rpy) + "°"});
    jframes["world_from_base"] = {{"parent", "world"},
                                  {"child", base_link},
                                  {"xyz_m", vec(calibrated.base->xyz)},
                                  {"rpy_rad", vec(calibrated.base->rpy)}};
  }
  json jmarkers = json::array();
  for (const io::MarkerSpec& m : calibrated.markers) {
    std::string source = m.identify ? "fitted" : "given (--marker-offset)";
    for (const auto& ref : references)
      if (model.markers()[ref.slot].id == m.id)
        source = "measured at row " + std::to_string(data.samples[ref.measurement].row);
    frows.push_back({tip_link + " → marker " + std::to_string(m.id), "p_FM, " + tip_link + " frame",
                     "xyz " + mm3(m.xyz) + " mm (" + source + ")"});
    jmarkers.push_back(
        {{"id", m.id}, {"parent", tip_link}, {"xyz_m", vec(m.xyz)}, {"source", source}});
  }
  if (!jmarkers.empty()) jframes["tip_to_markers"] = jmarkers;
  if (calibrated.imu) {
    frows.push_back({tip_link + " → imu", "R_FI", "rpy " + deg3(calibrated.imu->rpy) + "°"});
    jframes["tip_to_imu"] = {{"parent", tip_link}, {"rpy_rad", vec(calibrated.imu->rpy)}};
  }
  if (calibrated.earth) {
    frows.push_back({"earth ← world", "R_EW", "rpy " + deg3(calibrated.earth->rpy) + "°"});
    jframes["earth_from_world"] = {
        {"parent", "earth"}, {"child", "world"}, {"rpy_rad", vec(calibrated.earth->rpy)}};
  }
  std::ostringstream md;
  md << "# rcal calibrate\n\n";
  if (!rejected.empty()) {  // said first: the figures below are a fit, not a calibration
    md << "**REJECTED**: no calibrated robot was written; the fit describes no arm the robot file "
          "could be:\n\n";
    for (const auto& r : rejected) md << "- " << r << "\n";
    md << "\n";
  }
  md << "- Data: `" << o.data << "`, " << ms.size() << " poses, "
     << (data.has_orientation ? "position and orientation" : "positions only") << "\n- Robot: `"
     << o.robot << "` (" << model.name() << "), " << model.num_params() << " parameters, "
     << fit.identified.size() << " identifiable at these poses, " << fit.setup.size()
     << " of them set-up frames\n- Chain: " << ChainText(robot) << "; positions are of the "
     << (model.markers().size() > 1 ? std::to_string(model.markers().size()) + " markers"
                                    : std::string("marker"))
     << " in the world (position sensor) frame\n- Method: " << o.method << "; noise "
     << (o.fixed_noise ? "given" : "estimated from the residuals") << ": "
     << Fmt(fit.position_sigma_m * kMm, 4) << " mm"
     << (data.has_orientation ? ", " + Fmt(fit.orientation_sigma_rad * kDeg, 4) + "°"
                              : std::string(" (positions only: no orientation measured)"))
     << "\n\n'Nominal' is the drawing kinematics with only the set-up frames (world ← base, "
        "marker, IMU) fitted: the honest before-calibration figure.\n\n## Errors\n\n"
     << MdTable({"", "position mean [mm]", "position max [mm]", "orientation mean [deg]",
                 "orientation max [deg]"},
                {Row("fitted poses, nominal", fit.nominal_fit),
                 Row("fitted poses, calibrated", fit.calibrated_fit),
                 Row("held-out (" + held.scheme + "), nominal", held.nominal),
                 Row("held-out (" + held.scheme + "), calibrated", held.calibrated)})
     << "\n![errors](errors.png)\n\n## Set-up frames (calibrated)\n\n"
     << MdTable({"frame", "what", "value"}, frows)
     << "\nroll-pitch-yaw: R = Rz(yaw)·Ry(pitch)·Rx(roll).\n\n## Identified parameters\n\n"
     << MdTable({"parameter", "frame", "unit", "error", "σ"}, prows)
     << (rejected.empty()
             ? "\nCalibrated robot: `robot_calibrated.yaml`" +
                   std::string(robot.from_urdf ? " and `robot_calibrated.urdf`" : "") + ".\n"
             : std::string("\nCalibrated robot: none (rejected, above).\n"));
  if (ext) {
    const auto params = ext->model.EffectParameters();
    std::vector<std::vector<std::string>> erows;
    for (size_t i = 0; i < params.size(); ++i)
      erows.push_back(
          {params[i].name, params[i].unit, Fmt(ext->fit.e(i), 4), Fmt(ext->fit.sigma_e(i), 2)});
    md << "\n## Extended model (effects from `" << o.effects_path << "`)\n\n"
       << MdTable({"", "position mean [mm]", "position max [mm]", "orientation mean [deg]",
                   "orientation max [deg]"},
                  {Row("fitted poses, extended", ext->fit_stats),
                   Row("held-out (" + held.scheme + "), geometric", ext->held.geometric),
                   Row("held-out (" + held.scheme + "), extended", ext->held.extended)})
       << "\nHeld-out gain of the extended model (RMS): "
       << Fmt(100 * (1 - ext->held.extended.rms_position_m / ext->held.geometric.rms_position_m), 1)
       << " %, " << ext->Label(o.effects_path) << ".\n\n"
       << MdTable({"effect parameter", "unit", "value", "σ"}, erows)
       << "\nGeometry of the extended model: `robot_calibrated_extended.yaml`.\n";
  }
  io::AtomicWriteFile(out / "report.md", md.str());

  json j = {{"data", o.data},
            {"robot", model.name()},
            {"chain",
             {{"base_link", base_link},
              {"tip_link", tip_link},
              {"joints",
               [&] {
                 std::vector<std::string> v;
                 for (const auto& jt : model.joints()) v.push_back(jt.name);
                 return v;
               }()}}},
            {"setup_frames", jframes},
            {"num_poses", ms.size()},
            {"num_identified", fit.identified.size()},
            {"method", o.method},
            {"validation", held.scheme},
            {"position_noise_m", fit.position_sigma_m},
            {"parameters", jparams},
            {"rejected", !rejected.empty()},
            {"rejected_because", rejected}};
  // What `rcal export` reads: the robot as fitted and every parameter with its σ (null: not
  // identified), under a hash of both (io/calibration_export.hpp).
  if (rejected.empty()) {
    io::ModelParameters mp{fit.x, Eigen::VectorXd::Constant(model.num_params(), std::nan("")), {}};
    mp.identified.assign(model.num_params(), false);
    for (int i : fit.identified) {
      mp.sigma(i) = fit.sigma(i);
      mp.identified[i] = true;
    }
    j["calibration"] = io::CalibrationRecordJson(
        robot.spec, model, mp, fs::absolute(robot.source).string(), o.data, io::UtcNow());
  }
  // Positions only: no orientation noise (nor orientation errors, StatsJson) to report.
  if (data.has_orientation) j["orientation_noise_rad"] = fit.orientation_sigma_rad;
  j.update(StatsJson(fit.nominal_fit, "fit_nominal_"));
  j.update(StatsJson(fit.calibrated_fit, "fit_"));
  j.update(StatsJson(held.nominal, "test_nominal_"));
  j.update(StatsJson(held.calibrated, "test_"));
  if (ext) {
    json jx = json::array();
    for (int i : fit.identified)
      jx.push_back({{"name", model.parameters()[i].name},
                    {"unit", model.parameters()[i].is_angle ? "rad" : "m"},
                    {"value", ext->fit.x(i)}});
    j["effects_file"] = o.effects_path;
    j["link_density_kg_per_m"] = ext->model.gravity().link_density_kg_per_m;
    j["effects"] = io::EffectsJson(ext->model, ext->fit.e, ext->fit.sigma_e);
    j["extended_parameters"] = jx;
    j["extended_position_noise_m"] = ext->fit.position_sigma_m;
    j.update(StatsJson(ext->fit_stats, "fit_extended_"));
    j.update(StatsJson(ext->held.geometric, "test_geometric_"));
    j.update(StatsJson(ext->held.extended, "test_extended_"));
    const double before = ext->held.geometric.rms_position_m;
    j["test_extended_relative_gain"] =
        before > 0 ? 1.0 - ext->held.extended.rms_position_m / before : 0.0;
    j["test_extended_gain_independent_of_selection"] = ext->Independent();
    j["test_extended_heldout_poses_seen_by_selection"] = ext->heldout_seen;
    j["test_extended_gain_note"] = ext->Label(o.effects_path);
    if (std::isfinite(ext->analysis_gain)) {
      j["analysis_relative_gain"] = ext->analysis_gain;
      j["analysis_gain_scheme"] = ext->analysis_scheme;
    }
  }
  io::AtomicWriteFile(out / "results.json", j.dump(2));
  if (!o.json_path.empty()) io::AtomicWriteFile(o.json_path, j.dump(2));

  std::printf("\nrcal calibrate — %s, %zu poses, %zu parameters identified\n", o.data.c_str(),
              ms.size(), fit.identified.size());
  // Positions only: no orientation was measured, so there is no orientation error to print (it
  // used to read 0.000).
  if (data.has_orientation)
    std::printf("                         position mean/max [mm]   orientation mean/max [deg]\n");
  else
    std::printf(
        "                         position mean/max [mm]   (positions only: no orientation)\n");
  const auto line = [](const char* name, const identification::PoseErrorStats& s) {
    if (s.orientation_rad.empty())
      std::printf("  %-22s %8.3f / %-8.3f\n", name, s.mean_position_m * kMm,
                  s.max_position_m * kMm);
    else
      std::printf("  %-22s %8.3f / %-8.3f       %8.3f / %-8.3f\n", name, s.mean_position_m * kMm,
                  s.max_position_m * kMm, s.mean_orientation_rad * kDeg,
                  s.max_orientation_rad * kDeg);
  };
  line("fit, nominal", fit.nominal_fit);
  line("fit, calibrated", fit.calibrated_fit);
  std::printf("  held-out: %s\n", held.scheme.c_str());
  line("held-out, nominal", held.nominal);
  line("held-out, calibrated", held.calibrated);
  if (ext) {
    line("fit, extended", ext->fit_stats);
    line("held-out, extended", ext->held.extended);
    std::printf("  held-out gain of the extended model %.1f %%: %s\n",
                100 * (1 - ext->held.extended.rms_position_m / ext->held.geometric.rms_position_m),
                ext->Label(o.effects_path).c_str());
    const auto params = ext->model.EffectParameters();
    for (size_t i = 0; i < params.size(); ++i)
      std::printf("  effect %-34s %+.4e ± %.2e %s\n", params[i].name.c_str(), ext->fit.e(i),
                  ext->fit.sigma_e(i), params[i].unit.c_str());
  }
  std::printf("  wrote %s\n", (out / "report.md").c_str());
  if (!rejected.empty()) {
    std::string why;
    for (const auto& r : rejected) why += "\n  - " + r;
    spdlog::error("{}: calibration REJECTED, no calibrated robot written:{}", o.data, why);
    return 3;
  }
  return 0;
}

const RegisterCommand kCalibrate(
    "calibrate",
    "Identify a robot from a pose dataset (CSV), optionally with the effects an analysis found "
    "(--effects), or from an LCM log (--log: the same as calibrate-log)",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("data", o->data, "pose dataset CSV (rcal or FIGAROH layout)");
      sub.add_option("--robot", o->robot,
                     "robot file (YAML or URDF); required with DATA, with --log default "
                     "config/robots/grb3016.yaml");
      sub.add_option("--tip", o->tip_link, "URDF: last link of the chain (the flange)");
      sub.add_option("--base-link", o->base_link, "URDF: first link of the chain");
      sub.add_option("--out", o->out, "output folder")->capture_default_str();
      sub.add_option("--json", o->json_path, "also write the figures here (SI units)");
      sub.add_option("--method", o->method, "lm or ekf")->capture_default_str();
      sub.add_option("--frames", o->frames,
                     "auto: add world←base, marker and IMU frames the robot file lacks; none")
          ->capture_default_str();
      sub.add_option("--folds", o->folds, "k of k-fold when the data has no set column")
          ->capture_default_str();
      sub.add_option("--seed", o->seed, "fold assignment seed")->capture_default_str();
      sub.add_option("--position-sigma-mm", o->position_sigma_mm, "starting position noise [mm]")
          ->capture_default_str();
      sub.add_option("--orientation-sigma-deg", o->orientation_sigma_deg,
                     "starting orientation noise [deg]")
          ->capture_default_str();
      sub.add_flag("--fixed-noise", o->fixed_noise, "use the given noise, do not estimate it");
      sub.add_option("--effects", o->effects_path,
                     "analysis.json of `rcal analyze`: fit its effects with the geometry, write "
                     "the calibrated effects (values, sigma) to the JSON (with --log: identified "
                     "as ekf_identifier --effects does, each pose under its logged context)");
      sub.add_option("--marker-offset", o->marker_offsets,
                     "ID=x,y,z: marker ID's known offset p_FM [m, tip-link frame], not fitted "
                     "(repeatable)");
      sub.add_option("--marker-reference", o->marker_references,
                     "ID=ROW: marker ID, measured only in test rows, has its offset measured at "
                     "the configuration of data row ROW (solved with the calibrated model; that "
                     "row is not judged) (repeatable)");
      sub.add_option("--link-density", o->link_density,
                     "[kg/m] gravity model of joint_compliance (default: the analysis.json's "
                     "link_density_kg_per_m, else 10)");
      sub.add_option("--log", o->log.log,
                     "LCM event log: identify from its pose measurements instead of DATA, exactly "
                     "as `rcal calibrate-log LOG` and ekf_identifier (alias; --cell, --json and "
                     "the options marked [--log] apply)");
      sub.add_option("--cell", o->log.cell,
                     "[--log] cell file (schema rcal.cell/1), as ekf_identifier's")
          ->capture_default_str();
      AddCalibrateLogOptions(sub, o->log, " [--log]");
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
