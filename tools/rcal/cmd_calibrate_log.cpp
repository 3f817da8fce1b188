// rcal calibrate-log LOG --cell FILE: the online identification run offline on a recorded LCM
// event log (lcm-logger or the logger service). Reads the pose measurements in log order with
// io::LcmLogReader and runs them through the same checks and the same EKF, on the same base set
// and set-up guess, as `ekf_identifier --cell FILE` (both run cell::OnlineIdentification): a log
// replayed through the pipeline with lcm-logplayer and this command give the same parameters (a
// tested property). A run in which no pose was accepted exits non-zero, saying why.
// Events that fail to decode or to validate, and poses not after the last accepted one, are
// skipped and counted, as the process rejects them. `rcal calibrate --log LOG` runs this same code.
// Every event is checked against its schema before it is decoded; a log that lost data (broken
// frames, bytes unreadable, undecodable events) is refused after its summary unless --allow-gaps.
// Where users trip (issue 13, item 4), as `rcal calibrate DATA` refuses them: the logged poses
// are checked against the robot (joints in degrees, positions in millimetres, another arm's joint
// limits: io::CheckPosesPlausible, exit 1 naming the likely cause), and the outcome is judged
// (identification::CalibrationImplausible on the noise left in the accepted poses' residuals and
// the poses the EKF rejected): no pose accepted or a fit no arm gives is REJECTED, exit 3, the
// reasons on stderr and in the JSON (rejected, rejected_because).
// --effects analysis.json: the effects identified with the geometry, each pose under its logged
// context (cell::MakeOnlineIdentification, as ekf_identifier --effects); the JSON's `effects` are
// the calibrated ones (values, σ), in analysis.json's form.
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>

#include "calibrate_log.hpp"
#include "command.hpp"
#include "pose_log.hpp"
#include "rcal/cell/online_identification.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/identification/sanity.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/calibration_export.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/effects_json.hpp"
#include "rcal/io/lcm_log.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_schema.hpp"
#include "robot_setup.hpp"

namespace rcal::tool {

void AddCalibrateLogOptions(Args& sub, CalibrateLogOptions& o, const std::string& suffix) {
  sub.add_option(
      "--channel", o.channel,
      "channel of the pose measurements (default: the cell's channels.pose_measurement)" + suffix);
  sub.add_flag("--allow-gaps", o.allow_gaps,
               "an LCM log that lost data (broken frames, undecodable events): go on with what "
               "could be read (default: refuse, exit non-zero)");
}

int RunCalibrateLog(const CalibrateLogOptions& o_in) {
  CalibrateLogOptions o = o_in;
  // The identification exactly as ekf_identifier runs it (same base set, set-up guess, checks).
  cell::OnlineIdentification id = cell::MakeOnlineIdentification(
      io::LoadCell(ResolvePath(o.cell)),
      o.effects_path.empty() ? std::string() : ResolvePath(o.effects_path));
  if (o.channel.empty()) o.channel = id.cell().spec.channels.pose_measurement;
  const auto& model = id.model();
  const auto& base = id.base();

  std::unique_ptr<io::LcmLogReader> log;
  try {
    log = std::make_unique<io::LcmLogReader>(o.log);
  } catch (const std::exception&) {
    throw std::runtime_error("calibrate-log: cannot read " + o.log);
  }
  int64_t events = 0, skipped = 0;
  PoseLog valid;  // the poses that decode and fit the model, for the plausibility check
  std::map<int64_t, kinematics::PoseMeasurement> by_utime;  // ... and the residuals of the fit
  std::map<int64_t, kinematics::EffectContext> context_by_utime;  // (under their contexts)
  std::vector<int64_t> accepted_utimes;
  std::string first_skip;  // why the first pose skipped was
  while (const auto e = log->Next()) {
    if (e->channel != o.channel) continue;
    ++events;
    pose_measurement_t msg;
    // Checked against the schema before the generated decoder allocates (num_joints = 2^28 + 6).
    if (const std::string why =
            transport::DecodePoseMeasurement(e->data.data(), e->data.size(), &msg);
        !why.empty()) {
      log->Skip(*e, "does not decode as pose_measurement_t: " + why);
      ++skipped;
      continue;
    }
    std::string error;
    auto z = transport::FromMessage(msg, &error, &id.model());
    std::optional<kinematics::EffectContext> context;
    if (z) context = transport::ContextFromMessage(msg, &error);
    if (!z || !context) {
      if (first_skip.empty()) first_skip = error;
      ++skipped;
      continue;
    }
    const kinematics::PoseMeasurement m = *z;
    const auto outcome = id.Add({std::move(*z), msg.utime, msg.pose_index, *context});
    if (!outcome.rejected.empty()) {
      if (first_skip.empty()) first_skip = outcome.rejected;
      ++skipped;
      continue;
    }
    valid.poses.push_back({m, msg.utime, msg.pose_index, *context});
    by_utime.emplace(msg.utime, m);
    context_by_utime.emplace(msg.utime, *context);
    for (const auto& u : outcome.updates)
      if (u.result.accepted) accepted_utimes.push_back(u.utime);
  }
  const io::LcmLogStats stats = log->stats();
  CheckLogGaps(o.log, stats, o.allow_gaps);
  // Poses this robot cannot have produced (joints in degrees, positions in millimetres, joints
  // beyond another arm's limits): refused naming the likely cause, as `rcal calibrate DATA`. The
  // positions are judged by their spread (the world ← base frame unknown, as --frames auto has
  // it): set-up frames the EKF cannot find are judged by what it rejects, below.
  if (!valid.poses.empty()) {
    io::RobotSpec spread = id.cell().robot.spec;
    if (!spread.base) spread.base = io::FrameSpec{};
    io::CheckPosesPlausible(ToPoseDataset(valid, model.num_joints()), io::BuildModel(spread),
                            o.log);
  }
  const auto& ekf = id.ekf();
  const int64_t last_utime = id.last_utime(), last_pose_index = id.last_pose_index();
  const Eigen::VectorXd x = ekf.x(), sigma = ekf.sigma();
  std::printf(
      "rcal calibrate-log %s: %lld %s events, %d poses accepted, %d rejected by the EKF, "
      "%lld skipped (undecodable, invalid or out of order)\n",
      o.log.c_str(), static_cast<long long>(events), o.channel.c_str(), ekf.accepted(),
      ekf.rejected(), static_cast<long long>(skipped));
  // Every parameter in model order, its unit in the key: value_m and sigma_m, or value_rad and
  // sigma_rad.
  io::LoadedRobot cell_robot = id.cell().robot;  // the arm with the cell's set-up frames
  cell_robot.spec = id.cell().robot_spec;
  cell_robot.model = model;
  std::printf("  chain %s\n", ChainText(cell_robot).c_str());
  nlohmann::json names = nlohmann::json::array(), parameters = nlohmann::json::array();
  for (int i : base) {
    std::printf("  %-16s %+.6e ± %.2e  [%s]\n", model.parameters()[i].name.c_str(), x(i), sigma(i),
                ParameterFrame(cell_robot, i).c_str());
  }
  const auto effect_params = ekf.extended_model().EffectParameters();
  for (size_t k = 0; k < effect_params.size(); ++k)
    std::printf("  %-16s %+.6e ± %.2e  [%s]\n", effect_params[k].name.c_str(),
                ekf.e()(static_cast<Eigen::Index>(k)), ekf.sigma_e()(static_cast<Eigen::Index>(k)),
                effect_params[k].unit.c_str());
  for (int i = 0; i < x.size(); ++i) {
    const auto& P = model.parameters()[i];
    const std::string unit = P.is_angle ? "rad" : "m";
    names.push_back(P.name);
    parameters.push_back({{"name", P.name},
                          {"frame", ParameterFrame(cell_robot, i)},
                          {"value_" + unit, x(i)},
                          {"sigma_" + unit, sigma(i)}});
  }
  // The noise left in the accepted poses' residuals at the estimate, and the poses rejected.
  identification::CalibrationFigures figures;
  figures.robot = id.cell().spec.robot.file.string();
  figures.poses = ekf.accepted() + ekf.rejected();
  figures.poses_rejected = ekf.rejected();
  double p2 = 0, o2 = 0;
  int np = 0, no = 0;
  // With effects: the extended model's residual, each pose under its context.
  const bool extended = ekf.num_effect_params() > 0;
  for (const int64_t t : accepted_utimes) {
    const auto& m = by_utime.at(t);
    const auto stats = extended
                           ? identification::ErrorsAgainstMeasurements(
                                 ekf.extended_model(), x, ekf.e(), {m}, {context_by_utime.at(t)})
                           : identification::ErrorsAgainstMeasurements(model, x, {m});
    p2 += stats.rms_position_m * stats.rms_position_m;
    ++np;
    if (m.has_orientation) {
      o2 += stats.rms_orientation_rad * stats.rms_orientation_rad;
      ++no;
    }
  }
  if (np > 0) figures.position_sigma_m = std::sqrt(p2 / (3.0 * np));
  if (no > 0) figures.orientation_sigma_rad = std::sqrt(o2 / (3.0 * no));
  const std::vector<std::string> rejected = identification::CalibrationImplausible(figures);
  if (!o.json_path.empty()) {
    nlohmann::json j = {
        {"log", o.log},
        {"robot", model.name()},
        {"cell", id.cell().spec.name},
        {"chain",
         {{"base_link", cell_robot.spec.base_link}, {"tip_link", cell_robot.spec.tip_link}}},
        {"model_id", transport::ModelId(model)},
        {"events", events},
        {"skipped", skipped},
        {"log_events_read", stats.events_read},
        {"log_events_skipped", stats.events_skipped},
        {"log_broken_frames", stats.broken_frames},
        {"log_bytes_unreadable", stats.bytes_unreadable},
        {"poses_accepted", ekf.accepted()},
        {"poses_rejected", ekf.rejected()},
        {"last_utime_us", ekf.accepted() > 0 ? last_utime : 0},
        {"last_pose_index", last_pose_index},
        {"identified", base},
        {"names", names},
        {"parameters", parameters},
        {"residual_position_sigma_m", figures.position_sigma_m},
        {"residual_orientation_sigma_rad", figures.orientation_sigma_rad},
        {"rejected", !rejected.empty()},
        {"rejected_because", rejected}};
    // The effects identified with the geometry (--effects), as analysis.json entries with the
    // calibrated values and σ: what ik_corrector --effects and rcal calibrate --effects read.
    if (extended) {
      j["effects"] = io::EffectsJson(ekf.extended_model(), ekf.e(), ekf.sigma_e());
      j["link_density_kg_per_m"] = ekf.extended_model().gravity().link_density_kg_per_m;
    }
    // What `rcal export` reads (io/calibration_export.hpp): the cell's robot with its set-up
    // frames and every parameter with its σ (null: not identified).
    if (rejected.empty() && ekf.accepted() > 0) {
      io::ModelParameters mp{x, Eigen::VectorXd::Constant(model.num_params(), std::nan("")), {}};
      mp.identified.assign(model.num_params(), false);
      for (int i : ekf.identified()) {
        mp.sigma(i) = sigma(i);
        mp.identified[i] = true;
      }
      j["calibration"] =
          io::CalibrationRecordJson(cell_robot.spec, model, mp, id.cell().spec.robot.file.string(),
                                    "LCM log " + o.log, io::UtcNow());
    }
    io::AtomicWriteFile(o.json_path, j.dump(2));
  }
  if (!rejected.empty() || ekf.accepted() == 0) {
    std::string why;
    for (const auto& r : rejected) why += "\n  - " + r;
    if (ekf.accepted() == 0) {
      // Never a silent nominal: say what happened and what to check.
      why += "\n  - no pose accepted (" + std::to_string(events) + " " + o.channel + " events, " +
             std::to_string(id.held().size()) + " held for the set-up guess of " +
             std::to_string(id.cell().spec.identifier.guess_poses) + ", " +
             std::to_string(ekf.rejected()) + " rejected by the EKF" +
             (ekf.last_rejection().empty() ? "" : ": " + ekf.last_rejection()) +
             (first_skip.empty() ? "" : "; the first skipped because: " + first_skip) + "); is " +
             o.cell + " the cell that was recorded, and " + o.channel + " its pose channel?";
    }
    std::fprintf(stderr,
                 "rcal calibrate-log: %s: calibration REJECTED, these parameters are no "
                 "calibration:%s\n",
                 o.log.c_str(), why.c_str());
    return 3;
  }
  return 0;
}

namespace {

const RegisterCommand kCalibrateLog(
    "calibrate-log",
    "Identify the robot offline from the POSE_MEASUREMENT events of an LCM log (as ekf_identifier)",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<CalibrateLogOptions>();
      sub.add_option("log", o->log, "LCM event log (lcm-logger, logger service)")->required();
      sub.add_option("--cell", o->cell, "cell file (schema rcal.cell/1), as ekf_identifier's")
          ->capture_default_str();
      AddCalibrateLogOptions(sub, *o, "");
      sub.add_option("--effects", o->effects_path,
                     "analysis.json of `rcal analyze`: identify its effects with the geometry, "
                     "each pose under its logged context, as ekf_identifier --effects");
      sub.add_option("--json", o->json_path, "write the parameters here (SI units)");
      return [o]() { return RunCalibrateLog(*o); };
    });

}  // namespace
}  // namespace rcal::tool
