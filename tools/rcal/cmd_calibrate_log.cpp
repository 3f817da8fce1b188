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
#include <memory>
#include <nlohmann/json.hpp>

#include "calibrate_log.hpp"
#include "command.hpp"
#include "pose_log.hpp"
#include "rcal/cell/online_identification.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/lcm_log.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_schema.hpp"
#include "robot_setup.hpp"

namespace rcal::tool {

void AddCalibrateLogOptions(CLI::App& sub, CalibrateLogOptions& o, const std::string& suffix) {
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
  cell::OnlineIdentification id(io::LoadCell(ResolvePath(o.cell)));
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
  while (const auto e = log->Next()) {
    if (e->channel != o.channel) continue;
    ++events;
    pose_measurement_t msg;
    // Checked against the schema before the generated decoder allocates (num_joints = 2^28 + 6).
    if (const std::string why = transport::DecodeLcm(e->data.data(), e->data.size(), &msg);
        !why.empty()) {
      log->Skip(*e, "does not decode as pose_measurement_t: " + why);
      ++skipped;
      continue;
    }
    std::string error;
    auto z = transport::FromMessage(msg, &error, &id.model());
    if (!z || !id.Add({std::move(*z), msg.utime, msg.pose_index}).rejected.empty()) ++skipped;
  }
  const io::LcmLogStats stats = log->stats();
  CheckLogGaps(o.log, stats, o.allow_gaps);
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
  for (int i = 0; i < x.size(); ++i) {
    const auto& P = model.parameters()[i];
    const std::string unit = P.is_angle ? "rad" : "m";
    names.push_back(P.name);
    parameters.push_back({{"name", P.name},
                          {"frame", ParameterFrame(cell_robot, i)},
                          {"value_" + unit, x(i)},
                          {"sigma_" + unit, sigma(i)}});
  }
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
        {"parameters", parameters}};
    io::AtomicWriteFile(o.json_path, j.dump(2));
  }
  if (ekf.accepted() == 0) {
    // Never a silent nominal: say what happened and what to check.
    std::fprintf(stderr,
                 "rcal calibrate-log: no pose accepted (%lld %s events, %d held for the set-up "
                 "guess of %d, %d rejected by the EKF%s); is %s the cell that was recorded, and "
                 "%s its pose channel?\n",
                 static_cast<long long>(events), o.channel.c_str(),
                 static_cast<int>(id.held().size()), id.cell().spec.identifier.guess_poses,
                 ekf.rejected(),
                 ekf.last_rejection().empty() ? "" : (": " + ekf.last_rejection()).c_str(),
                 o.cell.c_str(), o.channel.c_str());
    return 3;
  }
  return 0;
}

namespace {

const RegisterCommand kCalibrateLog(
    "calibrate-log",
    "Identify the robot offline from the POSE_MEASUREMENT events of an LCM log (as ekf_identifier)",
    [](CLI::App& sub) -> std::function<int()> {
      auto o = std::make_shared<CalibrateLogOptions>();
      sub.add_option("log", o->log, "LCM event log (lcm-logger, logger service)")->required();
      sub.add_option("--cell", o->cell, "cell file (schema rcal.cell/1), as ekf_identifier's")
          ->capture_default_str();
      AddCalibrateLogOptions(sub, *o, "");
      sub.add_option("--json", o->json_path, "write the parameters here (SI units)");
      return [o]() { return RunCalibrateLog(*o); };
    });

}  // namespace
}  // namespace rcal::tool
