#include "rcal/cell/cell_sim_yaml.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <numbers>
#include <random>
#include <set>
#include <stdexcept>

#include "rcal/io/atomic_file.hpp"
#include "rcal/io/yaml_reader.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::cell {
namespace {

using io::detail::Reader;

constexpr const char* kSchema = "rcal.cell_sim/1";

using io::detail::Bounded;

Eigen::Vector3d Rpy(const Reader& r, const YAML::Node& n, const std::string& path) {
  const Eigen::Vector3d v = r.Vec3(n, path, true);
  for (int i = 0; i < 3; ++i)
    if (std::abs(v(i)) > 2.0 * std::numbers::pi + 1e-12)
      r.FailAt(path + "[" + std::to_string(i) + "]", "beyond 2π: degrees? (write radians)", n[i]);
  return v;
}

TrueFrame ReadTrueFrame(const Reader& r, const YAML::Node& n, const std::string& path, bool xyz,
                        bool rpy) {
  std::set<std::string> keys;
  if (xyz) keys.insert("xyz");
  if (rpy) keys.insert("rpy");
  r.CheckMap(n, path, keys);
  TrueFrame f;
  if (xyz) f.xyz = r.Vec3(r.Require(n, path, "xyz"), path + ".xyz", false);
  if (rpy) f.rpy = Rpy(r, r.Require(n, path, "rpy"), path + ".rpy");
  return f;
}

/// An angle error wrapped to (−π, π]: each rotation ET is periodic in its own angle.
double Wrap(double a) {
  const double w = std::remainder(a, 2.0 * std::numbers::pi);
  return w == -std::numbers::pi ? std::numbers::pi : w;
}

}  // namespace

CellSimSpec ParseCellSimYaml(const std::string& text, const std::string& source) {
  const Reader r(source, "cell sim files");
  const YAML::Node root = io::detail::LoadYaml(text, source);
  r.CheckMap(root, "", {"schema", "cell", "seed", "arm_errors", "truth", "run"});
  const YAML::Node schema = r.Require(root, "", "schema");
  if (r.String(schema, "schema") != kSchema)
    r.Fail("schema", std::string("expected ") + kSchema + ", got '" + schema.Scalar() + "'",
           &schema);
  CellSimSpec s;
  s.source = source;
  s.cell = r.String(r.Require(root, "", "cell"), "cell");
  s.seed = static_cast<unsigned>(r.Integer(r.Require(root, "", "seed"), "seed", 0, 4294967295LL));
  {
    const YAML::Node e = r.Require(root, "", "arm_errors");
    if (e.IsScalar() && e.Scalar() == "none") {
      s.arm_errors = ArmErrorsKind::kNone;
    } else if (e.IsScalar() && e.Scalar() == "table3") {
      s.arm_errors = ArmErrorsKind::kTable3;
    } else if (e.IsMap()) {
      r.CheckMap(e, "arm_errors", {"sigma_length", "sigma_angle"});
      s.arm_errors = ArmErrorsKind::kRandom;
      s.sigma_length =
          Bounded(r, r.Require(e, "arm_errors", "sigma_length"), "arm_errors.sigma_length", "m",
                  0.0, 0.01, "millimetres? (write metres)");
      s.sigma_angle =
          Bounded(r, r.Require(e, "arm_errors", "sigma_angle"), "arm_errors.sigma_angle", "rad",
                  0.0, 0.1, "degrees? (write radians)");
    } else {
      r.Fail("arm_errors",
             "expected none, table3 or {sigma_length: [m], sigma_angle: [rad]}, got " +
                 Reader::Kind(e),
             &e);
    }
  }
  {
    const YAML::Node t = r.Require(root, "", "truth");
    r.CheckMap(
        t, "truth",
        {"world_from_base", "earth_from_world", "flange_to_imu", "markers", "imu_to_marker"});
    if (const YAML::Node lever = t["imu_to_marker"]) {
      s.imu_to_marker_I = r.Vec3(lever, "truth.imu_to_marker", false);
      if (s.imu_to_marker_I.norm() > 1.0)
        r.Fail("truth.imu_to_marker", "beyond 1 m from the IMU: millimetres? (write metres)",
               &lever);
    }
    if (t["world_from_base"])
      s.world_from_base =
          ReadTrueFrame(r, t["world_from_base"], "truth.world_from_base", true, true);
    if (t["earth_from_world"])
      s.earth_from_world =
          ReadTrueFrame(r, t["earth_from_world"], "truth.earth_from_world", false, true);
    if (t["flange_to_imu"])
      s.flange_to_imu = ReadTrueFrame(r, t["flange_to_imu"], "truth.flange_to_imu", false, true);
    if (t["markers"]) {
      const YAML::Node list = t["markers"];
      if (!list.IsSequence())
        r.Fail("truth.markers", "expected a list of markers, got " + Reader::Kind(list), &list);
      for (size_t i = 0; i < list.size(); ++i) {
        const std::string path = "truth.markers[" + std::to_string(i) + "]";
        const YAML::Node n = list[i];
        r.CheckMap(n, path, {"id", "xyz"});
        const int id =
            static_cast<int>(r.Integer(r.Require(n, path, "id"), path + ".id", 0, 1000000));
        const YAML::Node xyz = r.Require(n, path, "xyz");
        const Eigen::Vector3d p = r.Vec3(xyz, path + ".xyz", false);
        if (p.norm() > 2.0)
          r.Fail(path + ".xyz", "beyond 2 m from the flange: millimetres? (write metres)", &xyz);
        for (const auto& [other, unused] : s.markers)
          if (other == id)
            r.FailAt(path + ".id", "marker id " + std::to_string(id) + " twice", n["id"]);
        s.markers.emplace_back(id, p);
      }
    }
  }
  if (const YAML::Node n = root["run"]) {
    const std::string p = "run";
    r.CheckMap(n, p,
               {"calibration_poses", "test_poses", "extra_poses", "still_time", "noise_scale",
                "gyro_bias", "mag_disturbance", "dropout"});
    auto count = [&](const char* key, int lo, int* out) {
      if (n[key]) *out = static_cast<int>(r.Integer(n[key], p + "." + key, lo, 100000));
    };
    count("calibration_poses", 1, &s.num_cal);
    count("test_poses", 0, &s.num_test);
    count("extra_poses", 0, &s.num_extra);
    if (n["still_time"])
      s.still_time = Bounded(r, n["still_time"], "run.still_time", "s", 0.0, 600.0,
                             "milliseconds? (write seconds)", "", true);
    if (n["noise_scale"])
      s.noise_scale = Bounded(r, n["noise_scale"], "run.noise_scale", "-", 0.0, 100.0);
    if (n["dropout"]) {
      s.dropout = Bounded(r, n["dropout"], "run.dropout", "-", 0.0, 1.0,
                          "a percentage? (write a probability)");
      if (s.dropout == 1.0) r.Fail("run.dropout", "1: every position sample lost", &n);
    }
    if (n["gyro_bias"]) s.gyro_bias = r.Bool(n["gyro_bias"], "run.gyro_bias");
    if (n["mag_disturbance"])
      s.mag_disturbance = r.Bool(n["mag_disturbance"], "run.mag_disturbance");
  }
  return s;
}

CellSimSpec LoadCellSimSpec(const std::filesystem::path& path) {
  CellSimSpec s = ParseCellSimYaml(io::ReadFile(path), path.string());
  if (s.cell.is_relative())
    s.cell =
        (path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path()) / s.cell;
  s.cell = s.cell.lexically_normal();
  return s;
}

Eigen::VectorXd TrueErrors(const io::BuiltCell& cell, const CellSimSpec& sim) {
  const auto& model = cell.model;
  const auto& frames = cell.spec.frames;
  const std::string& src = sim.source;
  auto fail = [&](const std::string& key, const std::string& what) {
    throw std::runtime_error(src + ": " + key + ": " + what);
  };
  // Which frames the cell identifies, and the truth the sim file gives for each.
  auto check = [&](const char* name, const io::SetupFrameSpec* frame,
                   const std::optional<TrueFrame>& truth) {
    const bool identified = frame != nullptr && frame->mode != io::SetupMode::kFixed;
    const std::string key = std::string("truth.") + name;
    if (identified && !truth)
      fail(key,
           std::string("missing: the cell (") + cell.spec.source + ") identifies frames." + name);
    if (!identified && truth)
      fail(key, std::string("the cell (") + cell.spec.source + ") " +
                    (frame ? "fixes frames." + std::string(name) + " at its nominal"
                           : "has no frames." + std::string(name)));
  };
  check("world_from_base", &frames.world_from_base, sim.world_from_base);
  check("earth_from_world", frames.earth_from_world ? &*frames.earth_from_world : nullptr,
        sim.earth_from_world);
  check("flange_to_imu", frames.flange_to_imu ? &*frames.flange_to_imu : nullptr,
        sim.flange_to_imu);
  std::set<int> identified_markers, true_markers;
  for (const auto& m : frames.markers)
    if (m.frame.mode != io::SetupMode::kFixed) identified_markers.insert(m.id);
  for (const auto& [id, p] : sim.markers) true_markers.insert(id);
  for (int id : identified_markers)
    if (!true_markers.count(id))
      fail("truth.markers", "marker " + std::to_string(id) + " is identified by the cell (" +
                                cell.spec.source + ") but has no truth");
  for (int id : true_markers)
    if (!identified_markers.count(id))
      fail("truth.markers", "marker " + std::to_string(id) + " is not identified by the cell (" +
                                cell.spec.source + "): fixed or absent");

  Eigen::VectorXd x = model.Nominal();
  switch (sim.arm_errors) {
    case ArmErrorsKind::kNone:
      break;
    case ArmErrorsKind::kTable3:
      for (const char* p : {"a1", "alpha1", "d1", "theta1", "a6", "alpha6", "theta6"})
        if (model.FindParameter(p) < 0)
          fail("arm_errors",
               std::string("table3 is the GRB3016's D–H table, and the cell's arm has no "
                           "parameter ") +
                   p);
      x = sim::Table3Errors(model);
      break;
    case ArmErrorsKind::kRandom: {
      sim::Rng rng(static_cast<std::uint64_t>(sim.seed) * 1000 + 4);
      x = sim::RandomErrors(model, rng, sim.sigma_length, sim.sigma_angle);
      break;
    }
  }
  // Set-up parameters: truth − nominal (the parameters' nominal values are the cell's).
  const auto& params = model.parameters();
  auto axis_of = [](const std::string& name) {
    const std::string s = name.substr(name.rfind('_') + 1);
    if (s == "x" || s == "rx") return 0;
    if (s == "y" || s == "ry") return 1;
    return 2;
  };
  for (int i = 0; i < model.num_params(); ++i) {
    const auto& p = params[i];
    if (!kinematics::IsSetupGroup(p.group)) continue;
    const TrueFrame* t = nullptr;
    if (p.group == "base") t = &*sim.world_from_base;
    if (p.group == "earth") t = &*sim.earth_from_world;
    if (p.group == "imu") t = &*sim.flange_to_imu;
    Eigen::Vector3d marker_truth;
    if (p.group == "marker") {
      for (const auto& mk : model.markers())
        for (int a = 0; a < 3; ++a)
          if (mk.param[a] == i)
            for (const auto& [id, pt] : sim.markers)
              if (id == mk.id) x(i) = pt(a) - p.nominal;
      continue;
    }
    if (t == nullptr) fail("truth", "no truth for parameter '" + p.name + "'");
    const int a = axis_of(p.name);
    x(i) = p.is_angle ? Wrap(t->rpy(a) - p.nominal) : t->xyz(a) - p.nominal;
  }
  return x;
}

Cell MakeSimCell(const io::BuiltCell& cell, const CellSimSpec& sim) {
  return MakeCell(cell.model, TrueErrors(cell, sim), sim.seed,
                  cell.spec.measures_orientation() ? kinematics::MeasurementKind::kFullPose
                                                   : kinematics::MeasurementKind::kPositionOnly);
}

RunSettings SimRunSettings(const io::BuiltCell& cell, const CellSimSpec& sim) {
  RunSettings s;
  s.seed = sim.seed;
  s.num_cal = sim.num_cal;
  s.num_test = sim.num_test;
  s.num_extra = sim.num_extra;
  s.noise_scale = sim.noise_scale;
  s.still_time = sim.still_time;
  s.gyro_bias = sim.gyro_bias;
  s.mag_disturbance = sim.mag_disturbance;
  s.dropout = sim.dropout;
  s.orientation = cell.spec.imu.has_value();
  return s;
}

sim::SensorSimSettings SimSensorSettings(const io::BuiltCell& cell, const CellSimSpec& sim) {
  sim::SensorSimSettings ss;
  const auto& spec = cell.spec;
  const double k = sim.noise_scale;
  ss.rate_hz = spec.imu ? spec.imu->rate : spec.position.rate;
  if (spec.imu) {
    const io::ImuSensorSpec& imu = *spec.imu;
    ss.imu.rate_hz = imu.rate;
    ss.imu.gyro_noise_density = imu.gyro_noise_density;
    ss.imu.accel_noise_density = imu.accel_noise_density;
    ss.imu.mag_noise_density = imu.mag_noise_density * 1e6;  // [T/√Hz] → the simulator's µT
    const bool ned = imu.earth == estimation::EarthFrame::kNed;
    ss.imu.g_W = Eigen::Vector3d(0, 0, ned ? imu.gravity : -imu.gravity);
    // The default field (20 µT north, 44 µT down) in the cell's earth frame.
    ss.imu.m_W = ned ? Eigen::Vector3d(20.0, 0.0, 44.0) : Eigen::Vector3d(0.0, 20.0, -44.0);
    if (!imu.R_IS.isIdentity()) {
      ss.imu.mounting = true;
      ss.imu.R_SI = imu.R_IS.transpose();
    }
  }
  ss.imu.gyro_noise_density *= k;
  ss.imu.accel_noise_density *= k;
  ss.imu.mag_noise_density *= k;
  ss.position.rate_hz = spec.position.rate;
  if (ss.position.rate_hz > ss.rate_hz)
    throw std::runtime_error(sim.source + ": the simulator samples the position sensor on the " +
                             "IMU's clock: sensors.position.rate " +
                             std::to_string(ss.position.rate_hz) + " Hz above sensors.imu.rate " +
                             std::to_string(ss.rate_hz) + " Hz (" + spec.source + ")");
  ss.position.sigma = spec.position.sigma.maxCoeff() * k;
  // The run's switches, with SimulateWindows' values.
  if (sim.gyro_bias) {
    ss.imu.constant_bias = true;
    ss.imu.gyro_bias = Eigen::Vector3d(0.004, -0.003, 0.005);  // [rad/s]
    ss.imu.bias_random_walk = true;
  }
  ss.mag_disturbance = sim.mag_disturbance;
  ss.position.dropouts = sim.dropout > 0;
  ss.position.dropout_probability = sim.dropout;
  return ss;
}

SimArmConditions::SimArmConditions(double warmup_s, int64_t start_utime, unsigned seed)
    : t0_s_(static_cast<double>(start_utime) * 1e-6), seed_(seed) {
  if (!(warmup_s > 0) || !std::isfinite(warmup_s))
    throw std::invalid_argument("warm-up time constant " + std::to_string(warmup_s) +
                                " s: not a positive figure");
  session_.warmup_time_constant_s = warmup_s;
  session_.payloads_kg = {0.0};
}

void SimArmConditions::SetPayloads(const sim::JointTrajectory& trajectory,
                                   const std::vector<double>& payloads_kg, PayloadChangeAt at) {
  if (payloads_kg.empty())
    throw std::invalid_argument("payloads: the list of payloads [kg] is empty");
  for (double m : payloads_kg)
    if (!(m >= 0.0 && m <= 1000.0))
      throw std::invalid_argument("payloads: " + std::to_string(m) +
                                  " kg is not a payload (finite, 0 to 1000 kg)");
  sim::Rng rng(static_cast<uint64_t>(seed_) * 1000 + 13);
  std::uniform_int_distribution<size_t> pick(0, payloads_kg.size() - 1);
  waypoint_payloads_kg_.clear();
  payload_changes_.clear();
  for (int k = 0; k < trajectory.num_waypoints(); ++k) {
    waypoint_payloads_kg_.push_back(payloads_kg[pick(rng)]);
    if (k == 0) continue;
    // Taken on halfway through the move from waypoint k − 1, or halfway through stop k's still
    // interval (header comment).
    const auto [a, b] =
        at == PayloadChangeAt::kMidMove
            ? std::pair(trajectory.StillInterval(k - 1).second, trajectory.StillInterval(k).first)
            : trajectory.StillInterval(k);
    const double mid = 0.5 * (a + b);
    const double from = waypoint_payloads_kg_[static_cast<size_t>(k - 1)];
    const double to = waypoint_payloads_kg_.back();
    if (from != to)
      payload_changes_.push_back({mid, mid + std::min(0.5, 0.25 * (b - a)), from, to});
  }
}

double SimArmConditions::PayloadAt(int waypoint) const {
  if (waypoint < 0 || static_cast<size_t>(waypoint) >= waypoint_payloads_kg_.size()) return 0.0;
  return waypoint_payloads_kg_[static_cast<size_t>(waypoint)];
}

kinematics::EffectContext SimArmConditions::At(double t_sim) const {
  kinematics::EffectContext c;
  c.time_s = t0_s_ + t_sim;  // the clock still_window stamps its poses with
  c.temperature_c = sim::WarmedTo(session_, t_sim);
  c.payload_kg = waypoint_payloads_kg_.empty() ? 0.0 : waypoint_payloads_kg_.front();
  for (const PayloadChange& ch : payload_changes_) {
    if (t_sim <= ch.t_start) break;
    // Quintic smoothstep: value, slope and curvature continuous at both ends.
    const double u = std::min(1.0, (t_sim - ch.t_start) / (ch.t_end - ch.t_start));
    c.payload_kg = ch.from + (ch.to - ch.from) * u * u * u * (10.0 - 15.0 * u + 6.0 * u * u);
  }
  return c;
}

double SimArmConditions::ReportedPayload(double t_sim) const {
  double m = waypoint_payloads_kg_.empty() ? 0.0 : waypoint_payloads_kg_.front();
  for (const PayloadChange& ch : payload_changes_)
    if (t_sim >= ch.t_start) m = ch.to;
  return m;
}

std::vector<double> SimArmConditions::PayloadReportTimes() const {
  std::vector<double> t;
  for (const PayloadChange& ch : payload_changes_) t.push_back(ch.t_start);  // each a real change
  return t;
}

double SimArmConditions::Reported(double t_sim, int64_t tick) const {
  sim::Rng rng(static_cast<uint64_t>(seed_) * 1000 + 11 + static_cast<uint64_t>(tick));
  std::normal_distribution<double> n(0.0, 1.0);
  return At(t_sim).temperature_c + session_.temperature_noise_c * n(rng);
}

std::vector<std::string> SimArmConditions::ApplyEffects(const std::vector<std::string>& texts,
                                                        SimProgramme& programme) const {
  return ApplyEffects(texts, std::vector<sim::ToolMotionTruth*>{&programme.truth});
}

std::vector<std::string> SimArmConditions::ApplyEffects(
    const std::vector<std::string>& texts, const std::vector<sim::ToolMotionTruth*>& truths) const {
  if (truths.empty()) throw std::invalid_argument("SimArmConditions::ApplyEffects: no truth");
  const kinematics::KinematicModel& arm = truths.front()->model();
  std::vector<sim::TruthEffect> effects;
  std::vector<std::string> lines;
  Eigen::VectorXd backlash = Eigen::VectorXd::Zero(arm.num_joints());
  for (const std::string& text : texts) {
    sim::TruthEffect te = sim::ParseEffectSpec(text, arm);
    const kinematics::Effect e = te.effect;  // a copy: te moves into effects below
    if (e.cause == kinematics::EffectCause::kBacklash) {
      // The joints stand off their readings by the approach direction; blended through the dead
      // band as a move reverses (sim::ToolMotionTruth::set_backlash).
      backlash(e.joint) += te.values(0);
      lines.push_back(
          "the simulated arm's joint stands off its reading by its backlash in the "
          "direction it came in, crossing the dead band as a move reverses (" +
          text + ")");
      continue;
    }
    effects.push_back(std::move(te));
    if (e.cause == kinematics::EffectCause::kJointCompliance) {
      lines.push_back("the simulated arm's joints give way under gravity and its payload (" + text +
                      (payload_changes_.empty() && PayloadAt(0) == 0.0
                           ? "; no payload: its own links' weight only)"
                           : ")"));
      continue;
    }
    if (e.cause == kinematics::EffectCause::kJointPeriodic ||
        e.cause == kinematics::EffectCause::kJointScale) {
      // A function of the joint angle alone: smooth along the motion, so the IMU feels it as the
      // tool moves, as the extended model says.
      lines.push_back(std::string(e.cause == kinematics::EffectCause::kJointPeriodic
                                      ? "the simulated arm's gear errs periodically with the "
                                        "joint angle ("
                                      : "the simulated arm's joint turns by a scale off its "
                                        "reading (") +
                      text + ")");
      continue;
    }
    lines.push_back("the simulated arm grows with its " +
                    std::string(e.thermal_source == kinematics::Effect::ThermalSource::kTime
                                    ? "time"
                                    : "temperature") +
                    " (" + text + "), warming with τ " +
                    std::to_string(session_.warmup_time_constant_s) + " s");
  }
  for (sim::ToolMotionTruth* truth : truths) {
    if (!backlash.isZero()) truth->set_backlash(backlash);
    if (effects.empty()) continue;
    // Each marker's own chain with the arm's effects (their parameters are the arm's, not the
    // marker's).
    sim::EffectTruth et = sim::MakeEffectTruth(truth->model(), effects);
    truth->set_effects(std::move(et.model), std::move(et.e),
                       [c = *this](double t) { return c.At(t); });
  }
  return lines;
}

}  // namespace rcal::cell

namespace rcal::cell {

SimProgramme MakeSimProgramme(const io::BuiltCell& cell, const CellSimSpec& sim, unsigned seed,
                              int num_cal, int num_test) {
  Cell c = MakeSimCell(cell, sim);
  sim::Rng rng(seed * 1000 + 3);
  std::vector<Eigen::VectorXd> waypoints;
  waypoints.push_back(sim::SampleJoints(c.model, 1, rng).front());
  std::vector<Eigen::VectorXd> stops = sim::SampleJoints(c.model, num_cal + num_test, rng);
  for (int k = 0; k < num_cal + std::min(num_test, 1); ++k) waypoints.push_back(stops[k]);
  sim::TrajectorySettings ts;
  ts.still_time = SimRunSettings(cell, sim).still_time;
  sim::ToolMotionTruth truth(c.model, c.x_true, sim::JointTrajectory(waypoints, ts));
  truth.set_imu_to_marker_I(sim.imu_to_marker_I);
  return SimProgramme{std::move(c), std::move(stops), std::move(truth)};
}

sim::JointOffsetStep OffsetStepInProgramme(const SimProgramme& programme,
                                           const sim::JointOffsetStepSpec& spec) {
  // Waypoint 0 is the home pose, waypoint k calibration stop k.
  const int stops = std::min(programme.truth.trajectory().num_waypoints() - 1,
                             static_cast<int>(programme.stops.size()));
  if (spec.stop < 1 || spec.stop > stops)
    throw std::invalid_argument("offset step at stop " + std::to_string(spec.stop) +
                                ": the programme has calibration stops 1.." +
                                std::to_string(stops));
  return {programme.truth.trajectory().StillInterval(spec.stop - 1).second, spec.joint, spec.delta};
}

}  // namespace rcal::cell
