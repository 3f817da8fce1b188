// rcal identifiability: which parameter errors of a robot a pose set can identify, and why not
// the others.
//
// The robot is loaded exactly as `rcal calibrate` loads it (--tip, --base-link, --frames: the
// world ← base frame and marker offsets a cell adds, the flange → IMU rotation with full poses,
// and with --earth-frame the earth ← world rotation of an IMU's own reference), so the count is
// the one calibrate identifies. With DATA the poses (and markers) are the data's own; without,
// --poses random joint vectors inside the limits, each measuring every one of --markers markers.
//
// Rank is judged with the arm at its drawing but the set-up frames at a generic placement: a
// set-up frame at its nominal can sit where part of the model is invisible (a marker at the
// flange origin lies on the last joint's axis, whose tilt then moves no measured point), yet in
// any real cell those directions are seen, and calibrate counts them at its estimate. The
// generic placement is the nominal (or, with DATA, the set-up guess from the data) plus seeded
// offsets: 5 cm on each marker coordinate, 1 mm / 1 mrad on the other set-up parameters. The
// arm's own parameters stay at the drawing, so a degenerate drawing (a zero D–H tool) shows.
#include <spdlog/spdlog.h>

#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "command.hpp"
#include "pose_log.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/identification/setup_guess.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "robot_setup.hpp"

namespace rcal::tool {
namespace {

struct Options {
  std::string robot = "config/robots/grb3016.yaml";
  std::string data;
  std::string tip_link, base_link;
  std::string frames = "auto";
  bool position_only = false;
  bool earth_frame = false;
  int markers = 1;
  std::vector<double> tool;  // a [m], alpha [rad], d [m], theta [rad]
  int poses = 100;
  unsigned seed = 1;
  bool allow_gaps = false;
  std::string json_path;
};

int Run(const Options& o) {
  io::LoadedRobot robot = LoadRobotForCell(o.robot, o.tip_link, o.base_link, o.frames);
  if (!o.tool.empty()) {
    if (o.tool.size() != 4) throw std::runtime_error("--tool: expected a,alpha,d,theta");
    robot.spec.tool = io::ToolSpec{o.tool[0], o.tool[1], o.tool[2], o.tool[3], true};
    robot.spec.markers.clear();  // the D–H tool ends at the measured point
    robot.model = io::BuildModel(robot.spec);
  }
  std::vector<kinematics::PoseMeasurement> ms;
  Eigen::VectorXd x0;
  std::string where;
  if (!o.data.empty()) {
    if (o.markers != 1 || o.position_only)
      throw std::runtime_error("--markers and --position-only come from DATA when it is given");
    const io::PoseDataset data = LoadPoseDataFor(robot, o.data, o.allow_gaps);
    SetUpMarkers(robot, data, {}, o.frames == "auto");
    if (o.frames == "auto" && data.has_orientation)
      AddOrientationFrame(robot, o.earth_frame || IsLcmLog(ResolvePath(o.data)));
    ms = ToMeasurements(data, robot.model);
    for (auto& m : ms) m.covariance = Eigen::MatrixXd::Identity(m.dimension(), m.dimension());
    x0 = identification::InitialSetupGuess(robot.model, ms);
    where = "the " + std::to_string(ms.size()) + " poses of " + o.data;
  } else {
    if (o.markers < 1 || o.markers > 100) throw std::runtime_error("--markers: 1 to 100");
    if (o.markers > 1) {
      if (robot.spec.tool) throw std::runtime_error("--markers: the robot ends in a D–H tool");
      io::PoseDataset ids;  // one sample per marker id 0 … N − 1: the markers the cell measures
      for (int id = 0; id < o.markers; ++id) ids.samples.push_back(io::PoseSample{});
      for (int id = 0; id < o.markers; ++id) ids.samples[id].marker = id;
      SetUpMarkers(robot, ids, {}, true);
    }
    if (o.frames == "auto" && !o.position_only) AddOrientationFrame(robot, o.earth_frame);
    sim::Rng rng(o.seed);
    const int slots = std::max<int>(1, static_cast<int>(robot.model.markers().size()));
    for (const Eigen::VectorXd& q : sim::SampleJoints(robot.model, o.poses, rng))
      for (int k = 0; k < slots; ++k) {
        kinematics::PoseMeasurement m;
        m.q = q;
        m.marker = k;
        m.has_orientation = !o.position_only;
        ms.push_back(m);
      }
    x0 = robot.model.Nominal();
    where = std::to_string(o.poses) + " random poses inside the limits";
  }
  const kinematics::KinematicModel& model = robot.model;
  const Eigen::VectorXd x = identification::GenericSetupPlacement(model, x0, o.seed);
  const bool full = !ms.empty() && ms.front().has_orientation;
  const auto r = kinematics::AnalyzeIdentifiability(model, ms, x);
  std::printf("%s: %d parameters, %s, %zu marker(s), %s\n", model.name().c_str(),
              model.num_params(), full ? "full poses" : "positions only",
              std::max<size_t>(1, model.markers().size()), where.c_str());
  std::printf("chain %s\n", ChainText(robot).c_str());
  std::printf("rank %d of %d; condition number of the base set %.1f\n", r.rank, r.num_params,
              r.condition_number);
  std::printf("not identifiable (%zu):\n", r.unidentifiable.size());
  for (const auto& c : r.unidentifiable)
    std::printf("  - %s  [%s fixed at nominal]\n", c.explanation.c_str(),
                model.parameters()[c.dropped].name.c_str());
  std::printf("base parameter set (%zu):", r.identifiable.size());
  for (int i : r.identifiable) std::printf(" %s", model.parameters()[i].name.c_str());
  std::printf("\n");
  if (!o.json_path.empty()) {
    nlohmann::json j;
    j["robot"] = model.name();
    j["chain"] = {{"base_link", robot.spec.base_link}, {"tip_link", robot.spec.tip_link}};
    j["num_params"] = r.num_params;
    j["rank"] = r.rank;
    j["position_only"] = !full;
    j["markers"] = std::max<size_t>(1, model.markers().size());
    j["poses"] = where;
    j["condition_number"] = r.condition_number;
    j["singular_values"] = std::vector<double>(r.singular_values.data(),
                                               r.singular_values.data() + r.singular_values.size());
    for (int i : r.identifiable) {
      j["identifiable"].push_back(model.parameters()[i].name);
      j["identifiable_frames"][model.parameters()[i].name] = ParameterFrame(robot, i);
    }
    j["unidentifiable"] = nlohmann::json::array();
    for (const auto& c : r.unidentifiable) {
      nlohmann::json u;
      u["dropped"] = model.parameters()[c.dropped].name;
      u["explanation"] = c.explanation;
      for (size_t k = 0; k < c.params.size(); ++k)
        u["direction"][model.parameters()[c.params[k]].name] = c.direction[k];
      j["unidentifiable"].push_back(u);
    }
    io::AtomicWriteFile(o.json_path, j.dump(2));
  }
  return 0;
}

const RegisterCommand kIdentifiability(
    "identifiability",
    "Rank, unidentifiable combinations and base parameters of a robot in its cell (the count "
    "rcal calibrate identifies)",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("data", o->data,
                     "pose dataset CSV or LCM log: judge at its own poses and markers (as rcal "
                     "calibrate DATA)");
      sub.add_option("--robot", o->robot, "robot file (YAML or URDF)")->capture_default_str();
      sub.add_option("--tip", o->tip_link, "URDF: last link of the chain (the flange)");
      sub.add_option("--base-link", o->base_link, "URDF: first link of the chain");
      sub.add_option("--frames", o->frames,
                     "auto: add the world←base, marker and (full poses) IMU frames a cell adds, "
                     "as rcal calibrate; none: the file as it is")
          ->capture_default_str();
      sub.add_flag("--position-only", o->position_only, "positions only (laser tracker)");
      sub.add_flag("--earth-frame", o->earth_frame,
                   "full poses from an IMU in its own earth frame (as the pipeline's logs): add "
                   "the earth ← world rotation");
      sub.add_option("--markers", o->markers,
                     "points measured on the tool at each pose (ids 0 … N-1), each with its own "
                     "offset")
          ->capture_default_str();
      sub.add_option("--tool", o->tool, "D–H tool a,alpha,d,theta [m, rad] (replaces the file's)")
          ->delimiter(',')
          ->expected(4);
      sub.add_option("--poses", o->poses, "random poses (without DATA)")->capture_default_str();
      sub.add_option("--seed", o->seed, "random seed (poses and the generic point)")
          ->capture_default_str();
      sub.add_flag("--allow-gaps", o->allow_gaps, "DATA is a log that lost events: use the rest");
      sub.add_option("--json", o->json_path, "also write the figures here");
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
