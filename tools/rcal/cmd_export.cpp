// rcal export: an identified model as a calibrated URDF, a YAML of every parameter with its σ and
// a parity report that proves the URDF (reloaded through liburdfdom) is the model
// (io/calibration_export.hpp). The model comes from one of
//   --calibration FILE|DIR   results.json (or the --out folder) of `rcal calibrate`, DATA or --log,
//                            or the calibration.json of an earlier export;
//   --checkpoint FILE        ekf_identifier's checkpoint (schema rcal.ekf_checkpoint/3), on the
//                            cell of --cell;
//   --log LOG                the last KINEMATIC_PARAMS event of an LCM log, on the cell of --cell.
// Exit 0 when parity holds, 4 when it fails (the files are written, the report says what
// differed), 1 with a message naming the file and the field on bad input.
#include <spdlog/spdlog.h>

#include <cctype>
#include <cmath>
#include <filesystem>
#include <optional>

#include "command.hpp"
#include "rcal/cell/online_identification.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/calibration_export.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/lcm_log.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/checkpoint_json.hpp"
#include "rcal/transport/lcm_schema.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;

struct Options {
  std::string calibration, checkpoint, log;
  std::string cell, robot, channel, data;
  std::string out = "out/export";
  int samples = 1000;
  unsigned seed = 1;
};

/// The URDF text of a robot file when it is one (its meshes and frames are kept), else "".
std::string UrdfTextOf(const std::string& robot_file) {
  std::string ext = fs::path(robot_file).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext == ".urdf" ? io::ReadFile(robot_file) : std::string();
}

/// The cell's model as the identifier builds it.
io::BuiltCell CellOf(const Options& o, const std::string& what) {
  if (o.cell.empty())
    throw std::runtime_error(what +
                             " needs --cell: the cell file names the robot and the set-up "
                             "frames the parameters belong to");
  return io::LoadCell(ResolvePath(o.cell));
}

io::ExportInput FromCell(const io::BuiltCell& cell) {
  io::ExportInput in;
  in.spec = cell.robot_spec;
  in.model = cell.model;
  in.robot_file = cell.spec.robot.file.string();
  in.source_urdf_xml = cell.robot.from_urdf ? io::ReadFile(cell.robot.source) : std::string();
  return in;
}

io::ExportInput FromCalibration(const Options& o) {
  fs::path file = ResolvePath(o.calibration);
  if (fs::is_directory(file)) file /= "results.json";
  const std::string text = io::ReadFile(file);
  // A fit `rcal calibrate` refused is no calibration to export.
  if (const auto j = nlohmann::json::parse(text, nullptr, false);
      j.is_object() && j.contains("rejected") && j["rejected"] == true)
    throw std::runtime_error(file.string() +
                             ": rejected: true: rcal calibrate refused this fit (see "
                             "rejected_because); it is no calibration to export");
  const io::CalibrationRecord r = io::ParseCalibrationRecord(text, file.string());
  io::ExportInput in;
  in.spec = r.spec;
  in.model = io::BuildModel(r.spec);
  in.parameters = io::ParametersByName(in.model, r.names, r.values, r.sigmas,
                                       file.string() + ": calibration.parameters", r.identified);
  // The rebuilt model must be the one that was fitted: the hash covers its structure and x.
  const std::string hash = io::CalibrationHash(in.model, in.parameters.x);
  if (hash != r.calibration_hash)
    throw std::runtime_error(file.string() + ": calibration_hash: " + r.calibration_hash +
                             ", the model rebuilt from robot_yaml and parameters gives " + hash);
  in.robot_file = o.robot.empty() ? r.robot_file : ResolvePath(o.robot);
  if (!o.cell.empty()) {
    // The cell must be the robot the calibration is of (same parameters, same set-up frames).
    const io::BuiltCell cell = io::LoadCell(ResolvePath(o.cell));
    if (transport::ModelId(cell.model) != transport::ModelId(in.model))
      throw std::runtime_error("--cell " + o.cell + ": its model is " +
                               transport::ModelId(cell.model) + ", the calibration's is " +
                               transport::ModelId(in.model) + " (another robot or set-up)");
  }
  if (fs::exists(in.robot_file)) {
    in.source_urdf_xml = UrdfTextOf(in.robot_file);
  } else if (!o.robot.empty() || fs::path(in.robot_file).extension() == ".urdf") {
    spdlog::warn("{}: robot file {} not found: the URDF is written from the robot description",
                 file.string(), in.robot_file);
  }
  in.data = r.data;
  in.date = r.date;
  in.from = file.string();
  return in;
}

io::ExportInput FromCheckpoint(const Options& o) {
  const io::BuiltCell cell = CellOf(o, "--checkpoint");
  const transport::CheckpointFile f = transport::LoadCheckpoint(ResolvePath(o.checkpoint));
  if (f.model_id != transport::ModelId(cell.model))
    throw std::runtime_error(o.checkpoint + ": model_id: " + f.model_id + ", the cell " + o.cell +
                             " has " + transport::ModelId(cell.model) +
                             " (another robot or set-up)");
  io::ExportInput in = FromCell(cell);
  cell::OnlineIdentification id(cell);
  id.Restore(f.checkpoint, f.held, f.utime, f.last_pose_index);
  if (!id.started())
    throw std::runtime_error(o.checkpoint + ": the identifier has not started (" +
                             std::to_string(f.held.size()) +
                             " poses held for the set-up guess): nothing identified yet");
  const auto& ekf = id.ekf();
  in.parameters.x = ekf.x();
  const Eigen::VectorXd sigma = ekf.sigma();
  in.parameters.sigma = Eigen::VectorXd::Constant(in.model.num_params(), std::nan(""));
  in.parameters.identified.assign(in.model.num_params(), false);
  for (int i : ekf.identified()) {
    in.parameters.sigma(i) = sigma(i);
    in.parameters.identified[i] = true;
  }
  if (!in.parameters.x.allFinite()) throw std::runtime_error(o.checkpoint + ": x: not finite");
  in.data = "ekf_identifier poses up to utime " + std::to_string(f.utime) + " µs (" +
            std::to_string(ekf.accepted()) + " accepted)";
  in.from = o.checkpoint;
  return in;
}

io::ExportInput FromLog(const Options& o) {
  const io::BuiltCell cell = CellOf(o, "--log");
  const std::string channel = o.channel.empty() ? cell.spec.channels.kinematic_params : o.channel;
  io::LcmLogReader reader(ResolvePath(o.log));
  std::optional<kinematic_params_t> last;
  int64_t events = 0;
  std::string first_bad;
  while (const auto e = reader.Next()) {
    if (e->channel != channel) continue;
    ++events;
    kinematic_params_t msg;
    if (const std::string why =
            transport::DecodeKinematicParams(e->data.data(), e->data.size(), &msg);
        !why.empty()) {
      reader.Skip(*e, why);
      if (first_bad.empty()) first_bad = why;
      continue;
    }
    last = std::move(msg);
  }
  if (!last)
    throw std::runtime_error(o.log + ": no decodable " + channel + " event (" +
                             std::to_string(events) + " on the channel" +
                             (first_bad.empty() ? "" : "; first refused: " + first_bad) + ")");
  std::string error;
  const auto x = transport::ParamsFromMessage(*last, cell.model, &error);
  if (!x) throw std::runtime_error(o.log + ": last " + channel + ": " + error);
  io::ExportInput in = FromCell(cell);
  const size_t n = static_cast<size_t>(cell.model.num_params());
  if (last->sigmas.size() != n || last->identified.size() != n)
    throw std::runtime_error(o.log + ": last " + channel + ": sigmas/identified: not " +
                             std::to_string(n) + " values");
  std::vector<double> sigmas(n);
  for (size_t i = 0; i < n; ++i) sigmas[i] = last->identified[i] ? last->sigmas[i] : std::nan("");
  std::vector<double> values(x->data(), x->data() + x->size());
  const std::vector<bool> identified(last->identified.begin(), last->identified.end());
  in.parameters = io::ParametersByName(cell.model, last->names, values, sigmas,
                                       o.log + ": " + channel, identified);
  in.data = "LCM log " + o.log + ", last " + channel + " (utime " + std::to_string(last->utime) +
            " µs, " + std::to_string(last->poses_used) + " poses used)";
  in.from = o.log;
  return in;
}

int Run(const Options& o) {
  const int given = !o.calibration.empty() + !o.checkpoint.empty() + !o.log.empty();
  if (given != 1)
    throw std::runtime_error("rcal export: give one of --calibration, --checkpoint, --log");
  if (o.samples < 1 || o.samples > 10'000'000)
    throw std::runtime_error("--samples: " + std::to_string(o.samples) +
                             ": from 1 to 10000000 joint vectors");
  io::ExportInput in = !o.calibration.empty()  ? FromCalibration(o)
                       : !o.checkpoint.empty() ? FromCheckpoint(o)
                                               : FromLog(o);
  if (!o.data.empty()) in.data = o.data;
  io::ParityOptions po;
  po.samples = o.samples;
  po.seed = o.seed;
  const io::ExportResult r = io::ExportCalibration(in, o.out, po);
  std::printf("rcal export %s: robot %s, calibration hash %s\n", in.from.c_str(),
              in.model.name().c_str(), r.hash.c_str());
  std::printf(
      "  parity over %d joint vectors (urdfdom): position max %.3g nm, median %.3g nm; "
      "orientation max %.3g nrad: %s\n",
      r.parity.samples, r.parity.max_position_m * 1e9, r.parity.median_position_m * 1e9,
      r.parity.max_orientation_rad * 1e9, r.parity.passed ? "PASSED" : "FAILED");
  for (const auto& f : r.files) std::printf("  wrote %s\n", f.c_str());
  if (!r.parity.passed) {
    spdlog::error("parity FAILED: the exported URDF is not the identified model (see {})",
                  (fs::path(o.out) / "parity.md").string());
    return 4;
  }
  return 0;
}

const RegisterCommand kExport(
    "export",
    "Export an identified model: calibrated URDF (set-up frames as fixed joints), every parameter "
    "with its sigma (YAML), and a parity report proving the URDF is the model",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--calibration", o->calibration,
                     "results.json of rcal calibrate (or its --out folder), or an export's "
                     "calibration.json");
      sub.add_option("--checkpoint", o->checkpoint,
                     "ekf_identifier checkpoint (rcal.ekf_checkpoint/3); needs --cell");
      sub.add_option("--log", o->log, "LCM log: its last KINEMATIC_PARAMS event; needs --cell");
      sub.add_option("--cell", o->cell,
                     "cell file (rcal.cell/1): the robot and set-up frames; with --calibration "
                     "checked to be the calibration's");
      sub.add_option("--robot", o->robot,
                     "--calibration: the robot file, where the record's has moved (a URDF is "
                     "kept with its meshes)");
      sub.add_option("--channel", o->channel,
                     "--log: channel (default: the cell's kinematic_params)");
      sub.add_option("--data", o->data, "describe the data the calibration came from");
      sub.add_option("--out", o->out, "output folder")->capture_default_str();
      sub.add_option("--samples", o->samples, "joint vectors of the parity check")
          ->capture_default_str();
      sub.add_option("--seed", o->seed, "seed of the joint vectors")->capture_default_str();
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
