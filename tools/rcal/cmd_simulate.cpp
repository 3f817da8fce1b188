// rcal simulate --robot ROBOT --effect CAUSE:JOINT=VALUE ... --poses N --seed S --out DATA.csv:
// a pose dataset (rcal layout) measured on a truth robot with geometric errors, set-up frames and
// hidden non-geometric effects (sim/effects.hpp), with the context columns the effects need.
#include <spdlog/spdlog.h>

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "command.hpp"
#include "plan_poses.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/pose_dataset.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "rcal/sim/effects.hpp"
#include "report.hpp"
#include "robot_setup.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct Options {
  std::string robot;
  std::vector<std::string> effects;
  int poses = 60;
  unsigned seed = 1;
  std::string out = "out/simulate/data.csv";
  std::string truth_json;
  std::string joints;  ///< a stops file (rcal plan-poses): measure there instead of at random
  std::string frames = "auto";
  std::string tip_link, base_link;
  double base_sigma_m = 0.05;
  double base_sigma_rad = 0.05;
  std::vector<double> marker_xyz{0.05, 0.0, 0.1};
  std::vector<std::string> markers;  ///< ID=x,y,z: several markers, each measured at every pose
  double geometry_sigma_mm = 0.5;
  double geometry_sigma_deg = 0.05;
  double position_sigma_mm = 0.05;
  double orientation_sigma_deg = 0.0;
  double test_fraction = 0.0;
  double session_s = 7200.0;
  double temperature_rise_c = 12.0;
  std::vector<double> payloads_kg{0.0, 5.0, 10.0};
  bool all_context = false;
  double link_density = 10.0;
};

int Run(const Options& o) {
  io::LoadedRobot robot = LoadRobotForCell(o.robot, o.tip_link, o.base_link, o.frames);
  const std::map<int, Eigen::Vector3d> marker_truth = ParseMarkerOffsets(o.markers, "--marker");
  if (!marker_truth.empty()) {
    // The truth robot measures these markers; their offsets are truth, not drawing (identified).
    io::PoseDataset ids;
    for (const auto& [id, p_FM] : marker_truth) {
      ids.samples.emplace_back();
      ids.samples.back().marker = id;
    }
    SetUpMarkers(robot, ids, {}, o.frames == "auto");
  }
  const kinematics::KinematicModel& model = robot.model;

  sim::Rng rng(o.seed);
  // Truth: geometric errors on the arm, the set-up frames where the cell put them.
  Eigen::VectorXd x =
      sim::RandomErrors(model, rng, o.geometry_sigma_mm * 1e-3, o.geometry_sigma_deg / kDeg);
  std::normal_distribution<double> n(0.0, 1.0);
  const char* marker_names[3] = {"marker_x", "marker_y", "marker_z"};
  for (int i : identification::SetupParameters(model)) {
    const auto& P = model.parameters()[i];
    x(i) = 0.0;
    if (P.group == "base") x(i) = (P.is_angle ? o.base_sigma_rad : o.base_sigma_m) * n(rng);
    for (int k = 0; k < 3; ++k)
      if (P.name == marker_names[k] && o.marker_xyz.size() == 3) x(i) = o.marker_xyz[k];
  }
  for (const kinematics::Marker& m : model.markers())
    if (const auto t = marker_truth.find(m.id); t != marker_truth.end())
      for (int a = 0; a < 3; ++a)
        if (m.param[a] >= 0) x(m.param[a]) = t->second(a) - m.nominal(a);
  std::vector<sim::TruthEffect> effects;
  for (const auto& spec : o.effects) effects.push_back(sim::ParseEffectSpec(spec, model));
  kinematics::GravityModel gravity;
  gravity.link_density_kg_per_m = o.link_density;
  const sim::EffectTruth truth = sim::MakeEffectTruth(model, effects, gravity);

  // --joints: the stops of a plan (rcal plan-poses) instead of random ones.
  const auto qs =
      o.joints.empty() ? sim::SampleJoints(model, o.poses, rng) : ReadJointsCsv(o.joints, model);
  const int poses = static_cast<int>(qs.size());
  sim::SessionSettings ss;
  ss.session_s = o.session_s;
  ss.temperature_rise_c = o.temperature_rise_c;
  ss.payloads_kg = o.payloads_kg;
  const auto ctx = sim::SampleSession(model.num_joints(), poses, ss, rng);
  sim::PoseNoise noise;
  noise.position_sigma = o.position_sigma_mm * 1e-3;
  noise.orientation = o.orientation_sigma_deg > 0;
  noise.orientation_sigma = o.orientation_sigma_deg / kDeg;
  const auto ms = sim::MeasurePosesWithEffects(truth, x, qs, ctx, noise, rng);

  // Which context columns the data carries.
  bool need_temperature = o.all_context, need_time = o.all_context, need_payload = o.all_context,
       need_dq = o.all_context;
  for (const auto& t : effects) {
    switch (t.effect.cause) {
      case kinematics::EffectCause::kThermal:
        (t.effect.thermal_source == kinematics::Effect::ThermalSource::kTime ? need_time
                                                                             : need_temperature) =
            true;
        break;
      case kinematics::EffectCause::kJointCompliance:
        need_payload = true;
        break;
      case kinematics::EffectCause::kBacklash:
        need_dq = true;
        break;
      default:
        break;
    }
  }
  std::uniform_real_distribution<double> u(0.0, 1.0);
  io::PoseDataset data;
  data.num_joints = model.num_joints();
  data.has_orientation = noise.orientation;
  // One row per marker and pose (MeasurePosesWithEffects measures every marker at each pose);
  // the rows of one pose share its context and its set.
  const size_t per_pose = ms.size() / qs.size();
  io::PoseSample::Set set = io::PoseSample::kUnspecified;
  for (size_t r = 0; r < ms.size(); ++r) {
    const size_t i = r / per_pose;
    io::PoseSample s;
    s.q = ms[r].q;
    s.p_WM_W = ms[r].p_WM_W;
    s.marker = model.markers().empty() ? 0 : model.markers()[ms[r].marker].id;
    s.has_orientation = noise.orientation;
    if (s.has_orientation) s.q_EI_wxyz = geometry::MatrixToQuat(ms[r].R_EI);
    if (need_temperature) s.temperature = ctx[i].temperature_c;
    if (need_payload) s.payload = ctx[i].payload_kg;
    if (need_time) s.time = ctx[i].time_s;
    if (need_dq) s.dq_sign = ctx[i].dq_sign;
    if (o.test_fraction > 0 && r % per_pose == 0)
      set = u(rng) < o.test_fraction ? io::PoseSample::kTest : io::PoseSample::kCal;
    s.set = set;
    data.samples.push_back(s);
  }
  std::ostringstream effects_text;
  for (const auto& e : o.effects) effects_text << " " << e;
  data.comments = {
      " simulated by rcal simulate, robot " + o.robot + ", seed " + std::to_string(o.seed),
      " chain " + ChainText(robot) + "; positions of the marker(s) in the world frame [m]",
      " hidden effects:" + (o.effects.empty() ? std::string(" none") : effects_text.str()),
      " noise: position " + Fmt(o.position_sigma_mm, 4) + " mm per axis" +
          (noise.orientation ? ", orientation " + Fmt(o.orientation_sigma_deg, 4) + " deg" : ""),
      " gravity model: " + Fmt(o.link_density, 2) + " kg/m of link, g = 9.81 m/s^2 along -z base"};
  io::SavePoseDataset(o.out, data);

  if (!o.truth_json.empty()) {
    json jx = json::object();
    for (int i = 0; i < model.num_params(); ++i) jx[model.parameters()[i].name] = x(i);
    json je = json::array();
    const auto params = truth.model.EffectParameters();
    for (size_t k = 0; k < effects.size(); ++k) {
      json v = json::array();
      for (int i = 0; i < effects[k].values.size(); ++i)
        v.push_back({{"name", params[truth.model.effect_offset(k) + i].name},
                     {"unit", params[truth.model.effect_offset(k) + i].unit},
                     {"value", effects[k].values(i)}});
      json joints = json::array();
      if (effects[k].effect.joint >= 0)
        joints.push_back(model.joints()[effects[k].effect.joint].name);
      je.push_back({{"cause", kinematics::ToString(effects[k].effect.cause)},
                    {"joints", joints},
                    {"values", v}});
    }
    json jm = json::array();
    for (const kinematics::Marker& m : model.markers()) {
      Eigen::Vector3d p_FM = m.nominal;
      for (int a = 0; a < 3; ++a)
        if (m.param[a] >= 0) p_FM(a) += x(m.param[a]);
      jm.push_back({{"id", m.id},
                    {"frame", robot.spec.tip_link + " → marker " + std::to_string(m.id)},
                    {"xyz_m", {p_FM.x(), p_FM.y(), p_FM.z()}}});
    }
    io::AtomicWriteFile(
        o.truth_json,
        json({{"seed", o.seed},
              {"robot", model.name()},
              {"chain", {{"base_link", robot.spec.base_link}, {"tip_link", robot.spec.tip_link}}},
              {"markers", jm},
              {"geometric_errors", jx},
              {"effects", je},
              {"position_noise_m", noise.position_sigma}})
            .dump(2));
  }
  std::printf("rcal simulate: %d poses of %s (%zu rows) with %zu hidden effect(s) -> %s\n", poses,
              model.name().c_str(), data.samples.size(), effects.size(), o.out.c_str());
  return 0;
}

const RegisterCommand kSimulate(
    "simulate", "Write a pose dataset measured on a truth robot with hidden effects",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--robot", o->robot, "robot file (YAML or URDF)")->required();
      sub.add_option("--effect", o->effects,
                     "hidden effect CAUSE[:JOINT][:h2]=V[,V] [SI], e.g. joint_compliance:j2=2e-6, "
                     "joint_periodic:j3=1e-4,0, joint_scale:j4=2e-4, backlash:j5=5e-5, "
                     "thermal=1.2e-5, thermal:time=3e-9 (repeatable)");
      sub.add_option("--poses", o->poses, "number of poses")->capture_default_str();
      sub.add_option("--joints", o->joints,
                     "measure at these stops (q1..qN, as rcal plan-poses writes) instead of "
                     "--poses random ones");
      sub.add_option("--seed", o->seed, "random seed")->capture_default_str();
      sub.add_option("--out", o->out, "pose dataset CSV to write")->capture_default_str();
      sub.add_option("--truth-json", o->truth_json, "also write the truth (SI) here");
      sub.add_option("--frames", o->frames,
                     "auto: world←base and marker frames as rcal calibrate adds them; none")
          ->capture_default_str();
      sub.add_option("--tip", o->tip_link, "URDF: last link of the chain");
      sub.add_option("--base-link", o->base_link, "URDF: first link of the chain");
      sub.add_option("--base-sigma-m", o->base_sigma_m, "truth world←base offset σ [m]")
          ->capture_default_str();
      sub.add_option("--base-sigma-rad", o->base_sigma_rad, "truth world←base rotation σ [rad]")
          ->capture_default_str();
      sub.add_option("--marker-xyz", o->marker_xyz, "truth flange→marker offset [m]")
          ->delimiter(',')
          ->expected(3);
      sub.add_option("--marker", o->markers,
                     "ID=x,y,z: a marker with its truth offset [m, tip-link frame]; several: "
                     "each measured at every pose, one row per marker (the marker column) "
                     "(repeatable; replaces --marker-xyz)");
      sub.add_option("--geometry-sigma-mm", o->geometry_sigma_mm, "geometric length errors σ")
          ->capture_default_str();
      sub.add_option("--geometry-sigma-deg", o->geometry_sigma_deg, "geometric angle errors σ")
          ->capture_default_str();
      sub.add_option("--position-sigma-mm", o->position_sigma_mm, "position noise σ per axis")
          ->capture_default_str();
      sub.add_option("--orientation-sigma-deg", o->orientation_sigma_deg,
                     "orientation noise σ per axis; 0: positions only")
          ->capture_default_str();
      sub.add_option("--test-fraction", o->test_fraction,
                     "fraction of poses marked set=test (0: no set column)")
          ->capture_default_str();
      sub.add_option("--session-s", o->session_s, "session duration [s]")->capture_default_str();
      sub.add_option("--temperature-rise", o->temperature_rise_c, "warm-up rise [K]")
          ->capture_default_str();
      sub.add_option("--payloads", o->payloads_kg, "payloads drawn per pose [kg]")->delimiter(',');
      sub.add_option("--link-density", o->link_density, "gravity model: kg per metre of link")
          ->capture_default_str();
      sub.add_flag("--all-context", o->all_context,
                   "write temperature, payload, dq and time even when no effect needs them");
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
