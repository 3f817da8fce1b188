#include "rcal/io/cell_yaml.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <map>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>

#include "rcal/estimation/position_kf.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/yaml_reader.hpp"

namespace rcal::io {
namespace {

using detail::Reader;

constexpr const char* kSchema = "rcal.cell/1";
constexpr double kTwoPi = 2.0 * std::numbers::pi;

using detail::Bounded;
using detail::ShortNumber;

/// A σ: one number for all three axes, or a list of three.
Eigen::Vector3d Sigma3(const Reader& r, const YAML::Node& n, const std::string& path,
                       const std::string& unit, double hi, const std::string& above) {
  Eigen::Vector3d s;
  if (n.IsSequence()) {
    if (n.size() != 3) r.Fail(path, "expected one σ or a list of 3, got " + Reader::Kind(n), &n);
    for (int i = 0; i < 3; ++i)
      s(i) = Bounded(r, n[i], path + "[" + std::to_string(i) + "]", unit, 0.0, hi, above, "", true);
    return s;
  }
  s.setConstant(Bounded(r, n, path, unit, 0.0, hi, above, "", true));
  return s;
}

/// Angles of a frame: readable multiples of π, within 2π (beyond: degrees, checked before the
/// reader's own 100 rad bound so that 180 gets the hint).
Eigen::Vector3d Rpy(const Reader& r, const YAML::Node& n, const std::string& path) {
  if (n.IsSequence() && n.size() == 3)
    for (int i = 0; i < 3; ++i) {
      const YAML::Node a = n[i];
      const std::optional<double> v = a.IsScalar() ? ParseAngle(a.Scalar()) : std::nullopt;
      if (v && std::isfinite(*v) && std::abs(*v) > kTwoPi + 1e-12)
        r.FailAt(path + "[" + std::to_string(i) + "]",
                 ShortNumber(*v) + " rad is beyond 2π: degrees? (write radians, e.g. pi/2)", a);
    }
  return r.Vec3(n, path, true);
}

enum FrameKind { kTranslationAndRotation, kTranslationOnly, kRotationOnly };

SetupFrameSpec ReadSetupFrame(const Reader& r, const YAML::Node& n, const std::string& path,
                              FrameKind kind, double max_offset) {
  SetupFrameSpec f;
  if (n.IsScalar()) {
    if (n.Scalar() == "guess") return f;
    r.Fail(path,
           "expected `guess` or a map {mode: fixed | prior | guess, ...}, got '" + n.Scalar() + "'",
           &n);
  }
  const bool has_xyz = kind != kRotationOnly, has_rpy = kind != kTranslationOnly;
  std::set<std::string> keys{"mode"};
  if (has_xyz) keys.insert({"xyz", "sigma_xyz"});
  if (has_rpy) keys.insert({"rpy", "sigma_rpy"});
  if (kind == kTranslationOnly) keys.insert("id");
  r.CheckMap(n, path, keys);
  const YAML::Node mode = r.Require(n, path, "mode");
  const std::string m = r.String(mode, path + ".mode");
  if (m == "fixed") {
    f.mode = SetupMode::kFixed;
  } else if (m == "prior") {
    f.mode = SetupMode::kPrior;
  } else if (m == "guess") {
    f.mode = SetupMode::kGuess;
  } else {
    r.Fail(path + ".mode", "expected fixed, prior or guess, got '" + m + "'", &mode);
  }
  const bool value_required = f.mode != SetupMode::kGuess;
  if (has_xyz) {
    if (value_required || n["xyz"]) {
      const YAML::Node xyz = r.Require(n, path, "xyz");
      f.xyz = r.Vec3(xyz, path + ".xyz", false);
      if (f.xyz.norm() > max_offset)
        r.Fail(path + ".xyz",
               ShortNumber(f.xyz.norm()) + " m from its origin is beyond " +
                   ShortNumber(max_offset) + " m: millimetres? (write metres)",
               &xyz);
    }
  }
  if (has_rpy && (value_required || n["rpy"]))
    f.rpy = Rpy(r, r.Require(n, path, "rpy"), path + ".rpy");
  const char* mode_name = f.mode == SetupMode::kFixed ? "fixed" : "prior";
  auto sigma = [&](bool has, const char* key, const char* unit, double hi, const char* above,
                   std::optional<Eigen::Vector3d>* out) {
    if (!has) return;
    const std::string sub = path + "." + key;
    if (f.mode == SetupMode::kFixed && n[key])
      r.Fail(sub, "a fixed frame has no σ (mode: prior for value ± σ)", &n);
    if (f.mode == SetupMode::kPrior && !n[key])
      r.Fail(sub, std::string("missing key (mode: ") + mode_name + " needs the value's σ)", &n);
    if (n[key]) *out = Sigma3(r, n[key], sub, unit, hi, above);
  };
  sigma(has_xyz, "sigma_xyz", "m", 1.0, "millimetres? (write metres)", &f.sigma_xyz);
  sigma(has_rpy, "sigma_rpy", "rad", 1.0, "degrees? (write radians)", &f.sigma_rpy);
  return f;
}

/// A safe identifier: [A-Za-z][A-Za-z0-9_-]*, at most `max` characters.
bool SafeName(const std::string& s, size_t max) {
  if (s.empty() || s.size() > max || !std::isalpha(static_cast<unsigned char>(s[0]))) return false;
  for (char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) return false;
  return true;
}

/// Informational text (ids, serials): printable, at most 128 characters.
std::string Label(const Reader& r, const YAML::Node& n, const std::string& path) {
  const std::string s = r.String(n, path);
  if (s.size() > 128) r.Fail(path, "longer than 128 characters", &n);
  for (char c : s)
    if (std::iscntrl(static_cast<unsigned char>(c)))
      r.Fail(path, "control characters are not allowed in a label", &n);
  return s;
}

int MarkerId(const Reader& r, const YAML::Node& n, const std::string& path) {
  return static_cast<int>(r.Integer(n, path, 0, 1000000));
}

/// The mounting frame ← sensor axes of `axes: [-y, x, z]` (row i: the signed sensor axis of the
/// mounting frame's axis i).
Eigen::Matrix3d ReadAxes(const Reader& r, const YAML::Node& n, const std::string& path) {
  if (!n.IsSequence() || n.size() != 3)
    r.Fail(path, "expected a list of 3 signed axes such as [-y, x, z], got " + Reader::Kind(n), &n);
  Eigen::Matrix3d R = Eigen::Matrix3d::Zero();
  std::set<int> used;
  for (int i = 0; i < 3; ++i) {
    const std::string sub = path + "[" + std::to_string(i) + "]";
    const YAML::Node a = n[i];
    const std::string s = a.IsScalar() ? a.Scalar() : std::string();
    double sign = 1.0;
    std::string axis = s;
    if (!axis.empty() && (axis[0] == '-' || axis[0] == '+')) {
      sign = axis[0] == '-' ? -1.0 : 1.0;
      axis.erase(0, 1);
    }
    const int k = axis == "x" ? 0 : axis == "y" ? 1 : axis == "z" ? 2 : -1;
    if (k < 0) r.Fail(sub, "expected x, y or z with an optional sign, got " + Reader::Kind(a), &a);
    if (!used.insert(k).second)
      r.Fail(sub, "axis " + axis + " used twice: the axes must be a signed permutation", &a);
    R(i, k) = sign;
  }
  if (R.determinant() < 0)
    r.Fail(path, "a mirror (left-handed) mapping: flip the sign of one axis", &n);
  return R;
}

ImuSensorSpec ReadImu(const Reader& r, const YAML::Node& n, const std::string& path) {
  r.CheckMap(n, path,
             {"id", "rate", "axes", "noise_density", "range", "earth", "gravity", "to_marker",
              "accel_bias", "accel_delay"});
  ImuSensorSpec s;
  if (n["id"]) s.id = Label(r, n["id"], path + ".id");
  s.rate = Bounded(r, r.Require(n, path, "rate"), path + ".rate", "Hz", 1.0, 10000.0,
                   "not an IMU's sample rate");
  if (n["axes"]) s.R_IS = ReadAxes(r, n["axes"], path + ".axes");
  {
    const std::string p = path + ".noise_density";
    const YAML::Node nd = r.Require(n, path, "noise_density");
    r.CheckMap(nd, p, {"gyro", "accel", "mag"});
    s.gyro_noise_density =
        Bounded(r, r.Require(nd, p, "gyro"), p + ".gyro", "rad/s/√Hz", 1e-9, 5e-3,
                "°/s/√Hz? (write rad/s/√Hz: 0.01 °/s/√Hz = 1.745e-4)", "", true);
    s.accel_noise_density =
        Bounded(r, r.Require(nd, p, "accel"), p + ".accel", "m/s²/√Hz", 1e-7, 0.05,
                "µg/√Hz or mg/√Hz? (write m/s²/√Hz: 60 µg/√Hz = 5.886e-4)", "", true);
    s.mag_noise_density = Bounded(r, r.Require(nd, p, "mag"), p + ".mag", "T/√Hz", 1e-13, 1e-5,
                                  "µT/√Hz or mG/√Hz? (write T/√Hz: 0.02 µT/√Hz = 2e-8)", "", true);
  }
  {
    const YAML::Node e = r.Require(n, path, "earth");
    const std::string t = r.String(e, path + ".earth");
    if (t == "ned") {
      s.earth = estimation::EarthFrame::kNed;
    } else if (t == "enu") {
      s.earth = estimation::EarthFrame::kEnu;
    } else {
      r.Fail(path + ".earth", "expected ned or enu, got '" + t + "'", &e);
    }
  }
  if (n["gravity"])
    s.gravity =
        Bounded(r, n["gravity"], path + ".gravity", "m/s²", 9.7, 9.9,
                "not the earth's gravity (write m/s²)", "not the earth's gravity (write m/s²)");
  if (const YAML::Node t = n["to_marker"]) {
    if (t.IsScalar() && t.Scalar() == "estimate") {
      s.estimate_to_marker = true;
    } else {
      s.to_marker_I = r.Vec3(t, path + ".to_marker", false);
      if (s.to_marker_I.norm() > 1.0)
        r.Fail(path + ".to_marker",
               "beyond 1 m from the IMU: millimetres? (write metres, or `estimate`)", &t);
    }
  }
  if (n["accel_delay"])
    s.accel_delay = Bounded(r, n["accel_delay"], path + ".accel_delay", "s", 0.0,
                            estimation::kMaxAccelDelay, "ms? (write seconds: 2.25 ms = 0.00225)");
  if (const YAML::Node b = n["accel_bias"]) {
    const std::string p = path + ".accel_bias";
    r.CheckMap(b, p, {"sigma", "random_walk"});
    if (b["sigma"])
      s.accel_bias_sigma = Bounded(r, b["sigma"], p + ".sigma", "m/s²", 0.0, 1.0,
                                   "mg or µg? (write m/s²: 15 µg = 1.47e-4)", "", true);
    if (b["random_walk"])
      s.accel_bias_random_walk = Bounded(r, b["random_walk"], p + ".random_walk", "m/s²/√s", 0.0,
                                         0.01, "µg/√s or mg/√h? (write m/s²/√s)", "", true);
  }
  if (n["range"]) {
    const std::string p = path + ".range";
    const YAML::Node rg = n["range"];
    r.CheckMap(rg, p, {"gyro", "accel", "mag"});
    if (rg["gyro"])
      s.gyro_range =
          Bounded(r, rg["gyro"], p + ".gyro", "rad/s", 0.5, 100.0,
                  "°/s? (write rad/s: 2000 °/s = 34.9)", "too small for an arm's motion");
    if (rg["accel"])
      s.accel_range = Bounded(r, rg["accel"], p + ".accel", "m/s²", 1.5 * s.gravity, 2000.0,
                              "not an accelerometer's range (write m/s²)",
                              "it would not read gravity: in g? (write m/s²: 16 g = 157)");
    if (rg["mag"])
      s.mag_range = Bounded(r, rg["mag"], p + ".mag", "T", 6.5e-5, 0.1,
                            "µT or gauss? (write T: 4900 µT = 4.9e-3)",
                            "it would not read the earth's field (up to 65 µT)");
  }
  return s;
}

PositionSensorSpec ReadPosition(const Reader& r, const YAML::Node& n, const std::string& path) {
  r.CheckMap(n, path, {"id", "markers", "sigma", "rate", "orientation", "orientation_sigma"});
  PositionSensorSpec s;
  if (n["id"]) s.id = Label(r, n["id"], path + ".id");
  const YAML::Node ms = r.Require(n, path, "markers");
  if (!ms.IsSequence() || ms.size() == 0)
    r.Fail(path + ".markers", "expected a list of marker ids, got " + Reader::Kind(ms), &ms);
  for (size_t i = 0; i < ms.size(); ++i) {
    const std::string sub = path + ".markers[" + std::to_string(i) + "]";
    const int id = MarkerId(r, ms[i], sub);
    if (std::find(s.markers.begin(), s.markers.end(), id) != s.markers.end())
      r.FailAt(sub, "marker id " + std::to_string(id) + " twice", ms[i]);
    s.markers.push_back(id);
  }
  const YAML::Node sigma = r.Require(n, path, "sigma");
  if (!sigma.IsSequence() || sigma.size() != 3)
    r.Fail(path + ".sigma", "expected a list of 3 σ [m] (one per axis), got " + Reader::Kind(sigma),
           &sigma);
  for (int i = 0; i < 3; ++i)
    s.sigma(i) = Bounded(r, sigma[i], path + ".sigma[" + std::to_string(i) + "]", "m", 1e-7, 0.01,
                         "millimetres? (write metres: 0.05 mm = 5e-5)", "", false);
  s.rate = Bounded(r, r.Require(n, path, "rate"), path + ".rate", "Hz", 1.0, 10000.0,
                   "not a position sensor's rate");
  if (n["orientation"]) s.orientation = r.Bool(n["orientation"], path + ".orientation");
  if (s.orientation) {
    s.orientation_sigma =
        Bounded(r, r.Require(n, path, "orientation_sigma"), path + ".orientation_sigma", "rad",
                1e-7, 0.1, "degrees? (write radians: 0.01° = 1.745e-4)");
  } else if (n["orientation_sigma"]) {
    r.Fail(path + ".orientation_sigma", "only with orientation: true", &n);
  }
  return s;
}

void ReadStillWindow(const Reader& r, const YAML::Node& n, const std::string& p,
                     StillWindowSpec* s) {
  r.CheckMap(
      n, p,
      {"joint_rate_threshold", "gyro_threshold", "accel_threshold", "min_duration", "settle_time",
       "min_window_samples", "min_raw_samples", "max_gap", "rest_from_joints", "warmup"});
  auto num = [&](const char* key, double* v, const char* unit, double lo, double hi,
                 const char* above, bool lo_open) {
    if (n[key]) *v = Bounded(r, n[key], p + "." + key, unit, lo, hi, above, "", lo_open);
  };
  num("joint_rate_threshold", &s->joint_rate_threshold, "rad/s", 0.0, 0.1,
      "°/s? (write rad/s) or not still", true);
  num("gyro_threshold", &s->gyro_threshold, "rad/s", 0.0, 1.0, "°/s? (write rad/s) or not still",
      true);
  num("accel_threshold", &s->accel_threshold, "m/s²", 0.0, 5.0, "not still", true);
  num("min_duration", &s->min_duration, "s", 0.0, 60.0, "milliseconds? (write seconds)", true);
  num("settle_time", &s->settle_time, "s", 0.0, 60.0, "milliseconds? (write seconds)", false);
  num("max_gap", &s->max_gap, "s", 0.0, 10.0, "milliseconds? (write seconds)", true);
  num("warmup", &s->warmup, "s", 0.0, 3600.0, "", false);
  if (n["min_window_samples"])
    s->min_window_samples =
        static_cast<int>(r.Integer(n["min_window_samples"], p + ".min_window_samples", 1, 1000000));
  if (n["min_raw_samples"])
    s->min_raw_samples =
        static_cast<int>(r.Integer(n["min_raw_samples"], p + ".min_raw_samples", 2, 1000000));
  if (n["rest_from_joints"])
    s->rest_from_joints = r.Bool(n["rest_from_joints"], p + ".rest_from_joints");
}

void ReadIdentifier(const Reader& r, const YAML::Node& n, const std::string& p, IdentifierSpec* s) {
  r.CheckMap(n, p,
             {"prior_sigma_length", "prior_sigma_angle", "drift_sigma_length", "drift_sigma_angle",
              "gate_probability", "gate_after", "guess_poses", "base_set_seed", "joint_margin"});
  auto num = [&](const char* key, double* v, const char* unit, double lo, double hi,
                 const char* above, bool lo_open) {
    if (n[key]) *v = Bounded(r, n[key], p + "." + key, unit, lo, hi, above, "", lo_open);
  };
  num("prior_sigma_length", &s->prior_sigma_length, "m", 0.0, 1.0, "millimetres? (write metres)",
      true);
  num("prior_sigma_angle", &s->prior_sigma_angle, "rad", 0.0, 1.0, "degrees? (write radians)",
      true);
  num("drift_sigma_length", &s->drift_sigma_length, "m", 0.0, 0.01,
      "millimetres? (write metres per pose)", false);
  num("drift_sigma_angle", &s->drift_sigma_angle, "rad", 0.0, 0.01,
      "degrees? (write radians per pose)", false);
  num("gate_probability", &s->gate_probability, "-", 0.5, 1.0,
      "a percentage? (write a probability: 99.999 % = 0.99999)", false);
  num("joint_margin", &s->joint_margin, "rad | m", 0.0, 1.0, "degrees or millimetres?", false);
  if (n["gate_after"])
    s->gate_after = static_cast<int>(r.Integer(n["gate_after"], p + ".gate_after", 0, 1000000));
  if (n["guess_poses"])
    s->guess_poses = static_cast<int>(r.Integer(n["guess_poses"], p + ".guess_poses", 1, 10000));
  if (n["base_set_seed"])
    s->base_set_seed =
        static_cast<unsigned>(r.Integer(n["base_set_seed"], p + ".base_set_seed", 0, 4294967295LL));
}

void ReadChannels(const Reader& r, const YAML::Node& n, const std::string& p, CellChannels* c) {
  const std::vector<std::pair<const char*, std::string*>> fields = {
      {"imu", &c->imu},
      {"position", &c->position},
      {"joints", &c->joints},
      {"orientation", &c->orientation},
      {"tool_position", &c->tool_position},
      {"ins_orientation", &c->ins_orientation},
      {"ins_tool_position", &c->ins_tool_position},
      {"pose_measurement", &c->pose_measurement},
      {"kinematic_params", &c->kinematic_params},
      {"calibration_status", &c->calibration_status},
      {"ik_request", &c->ik_request},
      {"ik_command", &c->ik_command},
      {"health", &c->health},
      {"supervisor_state", &c->supervisor_state},
      {"clock_offset", &c->clock_offset},
      {"next_poses", &c->next_poses},
      {"model_discrepancy", &c->model_discrepancy},
      {"arm_conditions", &c->arm_conditions}};
  std::set<std::string> keys;
  for (const auto& f : fields) keys.insert(f.first);
  r.CheckMap(n, p, keys);
  for (const auto& [key, out] : fields) {
    if (!n[key]) continue;
    const std::string sub = p + "." + key;
    const std::string s = r.String(n[key], sub);
    bool ok = s.size() <= 63;
    for (char ch : s)
      if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '.' || ch == '/' ||
            ch == '-'))
        ok = false;
    if (!ok)
      r.FailAt(sub, "'" + s + "' is not a channel name ([A-Za-z0-9_./-], at most 63 characters)",
               n[key]);
    *out = s;
  }
  // Two streams on one channel would each fail to decode the other's messages.
  std::map<std::string, const char*> seen;
  for (const auto& [key, out] : fields) {
    const auto [it, fresh] = seen.emplace(*out, key);
    if (!fresh)
      r.FailAt(p + "." + key, "channel '" + *out + "' is also " + p + "." + it->second,
               n[key] ? n[key] : n);
  }
}

/// A ROS 2 topic name: '/' then [A-Za-z0-9_/], no empty segment, no trailing '/', ≤ 200.
void CheckRosTopic(const Reader& r, const YAML::Node& n, const std::string& path,
                   const std::string& s) {
  bool ok = s.size() >= 2 && s.size() <= 200 && s[0] == '/' && s.back() != '/' &&
            s.find("//") == std::string::npos;
  for (char ch : s)
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '/')) ok = false;
  if (ok && std::isdigit(static_cast<unsigned char>(s[1]))) ok = false;
  if (!ok)
    r.FailAt(path,
             "'" + s + "' is not a ROS 2 topic name (absolute: /name/of/topic, [A-Za-z0-9_/])", n);
}

void ReadRos2(const Reader& r, const YAML::Node& n, const std::string& p, const CellSpec& spec,
              Ros2Spec* o) {
  r.CheckMap(
      n, p,
      {"domain", "joint_states", "joint_names", "imu", "magnetic_field", "imu_frame", "temperature",
       "payload", "positions", "clock_offsets", "max_clock_offset", "frame_prefix"});
  if (n["domain"]) o->domain = static_cast<int>(r.Integer(n["domain"], p + ".domain", 0, 232));
  auto topic = [&](const char* key, std::string* out) {
    if (!n[key]) return;
    *out = r.String(n[key], p + "." + key);
    CheckRosTopic(r, n[key], p + "." + key, *out);
  };
  topic("joint_states", &o->joint_states);
  topic("imu", &o->imu);
  topic("magnetic_field", &o->magnetic_field);
  topic("temperature", &o->temperature);
  topic("payload", &o->payload);
  if (n["imu_frame"]) o->imu_frame = r.String(n["imu_frame"], p + ".imu_frame");
  if (n["joint_names"]) {
    const YAML::Node list = n["joint_names"];
    if (!list.IsSequence() || list.size() == 0)
      r.Fail(p + ".joint_names", "expected a list of joint names, got " + Reader::Kind(list),
             &list);
    std::set<std::string> seen;
    for (size_t i = 0; i < list.size(); ++i) {
      const std::string sub = p + ".joint_names[" + std::to_string(i) + "]";
      const std::string name = r.String(list[i], sub);
      if (name.empty()) r.FailAt(sub, "empty", list[i]);
      if (!seen.insert(name).second) r.FailAt(sub, "'" + name + "' twice", list[i]);
      o->joint_names.push_back(name);
    }
  }
  if (spec.imu && o->imu.empty())
    r.Fail(p + ".imu", "missing key (the cell has an IMU: its sensor_msgs/Imu topic)", &n);
  if (!spec.imu && !o->imu.empty())
    r.FailAt(p + ".imu", "the cell has no IMU (sensors.imu)", n["imu"]);
  if (!o->magnetic_field.empty() && o->imu.empty())
    r.FailAt(p + ".magnetic_field", "a magnetometer needs the IMU's topic (ros2.imu)",
             n["magnetic_field"]);
  const YAML::Node list = r.Require(n, p, "positions");
  if (!list.IsSequence() || list.size() == 0)
    r.Fail(p + ".positions", "expected a list, one per marker, got " + Reader::Kind(list), &list);
  std::set<int> topics_for;
  for (size_t i = 0; i < list.size(); ++i) {
    const std::string sub = p + ".positions[" + std::to_string(i) + "]";
    const YAML::Node e = list[i];
    r.CheckMap(e, sub, {"marker", "topic", "type", "frame"});
    Ros2PositionTopic t;
    t.marker =
        static_cast<int>(r.Integer(r.Require(e, sub, "marker"), sub + ".marker", 0, 1000000));
    t.topic = r.String(r.Require(e, sub, "topic"), sub + ".topic");
    CheckRosTopic(r, e["topic"], sub + ".topic", t.topic);
    const std::string type = e["type"] ? r.String(e["type"], sub + ".type") : "PointStamped";
    if (type == "PoseStamped" || type == "geometry_msgs/msg/PoseStamped")
      t.pose = true;
    else if (type != "PointStamped" && type != "geometry_msgs/msg/PointStamped")
      r.FailAt(sub + ".type", "expected PointStamped or PoseStamped, got '" + type + "'",
               e["type"]);
    if (e["frame"]) t.frame_id = r.String(e["frame"], sub + ".frame");
    if (std::find(spec.position.markers.begin(), spec.position.markers.end(), t.marker) ==
        spec.position.markers.end())
      r.FailAt(sub + ".marker",
               "marker " + std::to_string(t.marker) + " is not in sensors.position.markers",
               e["marker"]);
    if (!topics_for.insert(t.marker).second)
      r.FailAt(sub + ".marker", "marker " + std::to_string(t.marker) + " twice", e["marker"]);
    o->positions.push_back(t);
  }
  for (int id : spec.position.markers)
    if (!topics_for.count(id))
      r.Fail(p + ".positions", "marker " + std::to_string(id) + " has no topic", &list);
  if (n["clock_offsets"]) {
    const std::string mode = r.String(n["clock_offsets"], p + ".clock_offsets");
    if (mode != "estimate" && mode != "none")
      r.FailAt(p + ".clock_offsets", "expected estimate or none, got '" + mode + "'",
               n["clock_offsets"]);
    o->estimate_clock_offsets = mode == "estimate";
  }
  if (n["max_clock_offset"])
    o->max_clock_offset = Bounded(r, n["max_clock_offset"], p + ".max_clock_offset", "s", 0.01,
                                  10.0, "milliseconds? (write seconds)", "", false);
  if (n["frame_prefix"]) {
    o->frame_prefix = r.String(n["frame_prefix"], p + ".frame_prefix");
    if (!o->frame_prefix.empty() && !SafeName(o->frame_prefix, 32))
      r.FailAt(p + ".frame_prefix", "'" + o->frame_prefix + "' is not [A-Za-z][A-Za-z0-9_-]*",
               n["frame_prefix"]);
  }
}

// `constraints:` (issue 16): boxes and distances [m] in the base frame, a home [rad | m].
identification::Box ReadBox(const Reader& r, const YAML::Node& n, const std::string& p) {
  r.CheckMap(n, p, {"min", "max"});
  identification::Box b;
  b.min = r.Vec3(r.Require(n, p, "min"), p + ".min", false);
  b.max = r.Vec3(r.Require(n, p, "max"), p + ".max", false);
  for (int i = 0; i < 3; ++i)
    if (!(b.min(i) < b.max(i)))
      r.Fail(p,
             "min[" + std::to_string(i) + "] " + ShortNumber(b.min(i)) + " m is not below max[" +
                 std::to_string(i) + "] " + ShortNumber(b.max(i)) + " m",
             &n);
  return b;
}

void ReadConstraints(const Reader& r, const YAML::Node& n, const std::string& p,
                     identification::PoseConstraints* c) {
  r.CheckMap(n, p, {"tool_box", "min_base_distance", "home", "task_region"});
  if (n["tool_box"]) c->tool_box = ReadBox(r, n["tool_box"], p + ".tool_box");
  if (n["task_region"]) c->task_region = ReadBox(r, n["task_region"], p + ".task_region");
  if (n["min_base_distance"])
    c->min_base_distance = Bounded(r, n["min_base_distance"], p + ".min_base_distance", "m", 0.0,
                                   10.0, "millimetres? (write metres)");
  if (const YAML::Node h = n["home"]) {
    const std::string hp = p + ".home";
    r.CheckMap(h, hp, {"joints", "tolerance"});
    const YAML::Node j = r.Require(h, hp, "joints");
    if (!j.IsSequence() || j.size() == 0)
      r.Fail(hp + ".joints", "expected a list of joint values, got " + Reader::Kind(j), &j);
    c->home.resize(static_cast<Eigen::Index>(j.size()));
    for (size_t i = 0; i < j.size(); ++i)
      c->home(static_cast<Eigen::Index>(i)) =
          r.Number(j[i], hp + ".joints[" + std::to_string(i) + "]", true);
    const YAML::Node t = r.Require(h, hp, "tolerance");
    c->home_tolerance.resize(c->home.size());
    if (t.IsSequence()) {
      if (t.size() != j.size())
        r.Fail(hp + ".tolerance",
               std::to_string(t.size()) + " tolerances for " + std::to_string(j.size()) + " joints",
               &t);
      for (size_t i = 0; i < t.size(); ++i)
        c->home_tolerance(static_cast<Eigen::Index>(i)) =
            Bounded(r, t[i], hp + ".tolerance[" + std::to_string(i) + "]", "rad | m", 0.0, 100.0,
                    "degrees? (write radians)", "", true);
    } else {
      c->home_tolerance.setConstant(Bounded(r, t, hp + ".tolerance", "rad | m", 0.0, 100.0,
                                            "degrees? (write radians)", "", true));
    }
  }
}

}  // namespace

CellSpec ParseCellYaml(const std::string& text, const std::string& source) {
  const Reader r(source, "cell files");
  const YAML::Node root = detail::LoadYaml(text, source);
  r.CheckMap(root, "",
             {"schema", "name", "robot", "frames", "sensors", "still_window", "identifier",
              "channels", "ros2", "constraints"});
  const YAML::Node schema = r.Require(root, "", "schema");
  if (r.String(schema, "schema") != kSchema)
    r.Fail("schema", std::string("expected ") + kSchema + ", got '" + schema.Scalar() + "'",
           &schema);
  CellSpec spec;
  spec.source = source;
  {
    const YAML::Node name = r.Require(root, "", "name");
    spec.name = r.String(name, "name");
    if (!SafeName(spec.name, 64))
      r.Fail("name",
             "'" + spec.name +
                 "' is not a safe identifier ([A-Za-z][A-Za-z0-9_-]*, at most 64 characters)",
             &name);
  }
  // robot
  {
    const YAML::Node n = r.Require(root, "", "robot");
    r.CheckMap(n, "robot", {"file", "base_link", "tip_link", "id"});
    const YAML::Node file = r.Require(n, "robot", "file");
    spec.robot.file = r.String(file, "robot.file");
    std::string ext = spec.robot.file.extension().string();
    for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (ext != ".yaml" && ext != ".yml" && ext != ".urdf")
      r.Fail("robot.file",
             "'" + spec.robot.file.string() + "': expected a .yaml (rcal.robot/1) or .urdf file",
             &file);
    for (const char* key : {"base_link", "tip_link"}) {
      if (!n[key]) continue;
      const std::string sub = std::string("robot.") + key;
      if (ext != ".urdf")
        r.FailAt(sub, "only for a URDF robot (a YAML robot's chain is its links list)", n[key]);
      (key[0] == 'b' ? spec.robot.base_link : spec.robot.tip_link) = r.String(n[key], sub);
    }
    if (n["id"]) spec.robot.id = Label(r, n["id"], "robot.id");
  }
  // sensors (before frames: which frames a cell needs depends on its sensors)
  const YAML::Node sensors = r.Require(root, "", "sensors");
  r.CheckMap(sensors, "sensors", {"imu", "position"});
  if (sensors["imu"]) spec.imu = ReadImu(r, sensors["imu"], "sensors.imu");
  spec.position = ReadPosition(r, r.Require(sensors, "sensors", "position"), "sensors.position");
  if (spec.imu && spec.position.orientation)
    r.FailAt(
        "sensors.position.orientation",
        "a cell has one orientation source: the IMU (sensors.imu) or a 6-DoF tracker, not both",
        sensors["position"]);
  // frames
  const YAML::Node frames = r.Require(root, "", "frames");
  r.CheckMap(frames, "frames", {"world_from_base", "earth_from_world", "flange_to_imu", "markers"});
  spec.frames.world_from_base =
      ReadSetupFrame(r, r.Require(frames, "frames", "world_from_base"), "frames.world_from_base",
                     kTranslationAndRotation, detail::kMaxLength);
  if (spec.imu) {
    spec.frames.earth_from_world =
        ReadSetupFrame(r, r.Require(frames, "frames", "earth_from_world"),
                       "frames.earth_from_world", kRotationOnly, 0.0);
  } else if (frames["earth_from_world"]) {
    r.FailAt("frames.earth_from_world",
             spec.position.orientation
                 ? "the tracker measures orientation in the world frame: no earth frame"
                 : "there is no IMU (sensors.imu): no earth frame",
             frames["earth_from_world"]);
  }
  if (spec.measures_orientation()) {
    spec.frames.flange_to_imu = ReadSetupFrame(r, r.Require(frames, "frames", "flange_to_imu"),
                                               "frames.flange_to_imu", kRotationOnly, 0.0);
  } else if (frames["flange_to_imu"]) {
    r.FailAt("frames.flange_to_imu",
             "nothing measures orientation (no sensors.imu, sensors.position.orientation false)",
             frames["flange_to_imu"]);
  }
  {
    const YAML::Node list = r.Require(frames, "frames", "markers");
    if (!list.IsSequence() || list.size() == 0)
      r.Fail("frames.markers", "expected a list of markers, got " + Reader::Kind(list), &list);
    if (list.size() > 100) r.Fail("frames.markers", "more than 100 markers", &list);
    for (size_t i = 0; i < list.size(); ++i) {
      const std::string path = "frames.markers[" + std::to_string(i) + "]";
      const YAML::Node n = list[i];
      if (!n.IsMap())
        r.Fail(path, "expected a map {id: N, mode: ..., xyz: [...]}, got " + Reader::Kind(n), &n);
      CellMarkerSpec m;
      m.frame = ReadSetupFrame(r, n, path, kTranslationOnly, 2.0);
      m.id = MarkerId(r, r.Require(n, path, "id"), path + ".id");
      for (const CellMarkerSpec& o : spec.frames.markers)
        if (o.id == m.id)
          r.FailAt(path + ".id", "marker id " + std::to_string(m.id) + " twice", n["id"]);
      spec.frames.markers.push_back(m);
    }
    // The position sensor measures exactly the markers the cell places.
    std::set<int> placed, measured(spec.position.markers.begin(), spec.position.markers.end());
    for (const CellMarkerSpec& m : spec.frames.markers) placed.insert(m.id);
    for (int id : measured)
      if (!placed.count(id))
        r.FailAt("sensors.position.markers",
                 "marker " + std::to_string(id) + " has no frames.markers entry (its offset)",
                 sensors["position"]["markers"]);
    for (int id : placed)
      if (!measured.count(id))
        r.Fail("frames.markers",
               "marker " + std::to_string(id) +
                   " is not measured by the position sensor (sensors.position.markers)",
               &list);
  }
  if (root["still_window"])
    ReadStillWindow(r, root["still_window"], "still_window", &spec.still_window);
  if (root["identifier"]) ReadIdentifier(r, root["identifier"], "identifier", &spec.identifier);
  if (root["channels"]) ReadChannels(r, root["channels"], "channels", &spec.channels);
  if (root["ros2"]) {
    spec.ros2.emplace();
    ReadRos2(r, root["ros2"], "ros2", spec, &*spec.ros2);
  }
  if (root["constraints"])
    ReadConstraints(r, root["constraints"], "constraints", &spec.constraints);
  // A set-up guess needs poses enough to fit a rigid frame (GuessSetup: at least 3).
  bool guessed = spec.frames.world_from_base.mode == SetupMode::kGuess;
  for (const auto* f : {&spec.frames.earth_from_world, &spec.frames.flange_to_imu})
    guessed |= f->has_value() && (*f)->mode == SetupMode::kGuess;
  for (const CellMarkerSpec& m : spec.frames.markers) guessed |= m.frame.mode == SetupMode::kGuess;
  if (guessed && spec.identifier.guess_poses < 3)
    r.FailAt(
        "identifier.guess_poses",
        std::to_string(spec.identifier.guess_poses) + ": a guessed frame needs at least 3 poses",
        root["identifier"] ? root["identifier"] : root);
  return spec;
}

CellSpec LoadCellSpec(const std::filesystem::path& path) {
  CellSpec spec = ParseCellYaml(ReadFile(path), path.string());
  if (spec.robot.file.is_relative())
    spec.robot.file =
        (path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path()) /
        spec.robot.file;
  spec.robot.file = spec.robot.file.lexically_normal();
  return spec;
}

Eigen::VectorXd BuiltCell::PriorSigma() const {
  Eigen::VectorXd s(static_cast<Eigen::Index>(prior.size()));
  for (size_t i = 0; i < prior.size(); ++i) s(static_cast<Eigen::Index>(i)) = prior[i].sigma;
  return s;
}

std::vector<int> BuiltCell::Guessed() const {
  std::vector<int> g;
  for (size_t i = 0; i < prior.size(); ++i)
    if (prior[i].kind == PriorKind::kGuess) g.push_back(static_cast<int>(i));
  return g;
}

BuiltCell BuildCell(const CellSpec& spec) {
  const std::string& src = spec.source;
  BuiltCell c;
  c.spec = spec;
  UrdfOptions urdf;
  urdf.base_link = spec.robot.base_link;
  urdf.tip_link = spec.robot.tip_link;
  if (!std::filesystem::exists(spec.robot.file))
    throw std::runtime_error(src + ": robot.file: '" + spec.robot.file.string() +
                             "' does not exist");
  try {
    c.robot = LoadRobot(spec.robot.file, urdf);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(src + ": robot.file: " + e.what());
  }
  // The arm of the robot file, the set-up of the cell.
  RobotSpec& rs = c.robot_spec;
  rs = c.robot.spec;
  const CellFramesSpec& f = spec.frames;
  rs.base = FrameSpec{f.world_from_base.xyz, f.world_from_base.rpy,
                      f.world_from_base.mode != SetupMode::kFixed};
  rs.markers.clear();
  for (const CellMarkerSpec& m : f.markers)
    rs.markers.push_back({m.id, m.frame.xyz, m.frame.mode != SetupMode::kFixed});
  rs.imu.reset();
  rs.earth.reset();
  if (f.flange_to_imu)
    rs.imu = FrameSpec{Eigen::Vector3d::Zero(), f.flange_to_imu->rpy,
                       f.flange_to_imu->mode != SetupMode::kFixed};
  if (f.earth_from_world)
    rs.earth = FrameSpec{Eigen::Vector3d::Zero(), f.earth_from_world->rpy,
                         f.earth_from_world->mode != SetupMode::kFixed};
  try {
    c.model = BuildModel(rs);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(src + ": robot.file: " + e.what());
  }
  if (const auto& h = spec.constraints.home; h.size() > 0 && h.size() != c.model.num_joints())
    throw std::runtime_error(src + ": constraints.home.joints: " + std::to_string(h.size()) +
                             " values, the arm has " + std::to_string(c.model.num_joints()) +
                             " joints");

  // The prior of every parameter: the arm's from identifier, the set-up's from its frame.
  const IdentifierSpec& id = spec.identifier;
  const auto& params = c.model.parameters();
  c.prior.resize(params.size());
  auto frame_prior = [&](const SetupFrameSpec& fr, const std::string& key, bool angle, int axis,
                         ParameterPrior* p) {
    p->kind = fr.mode == SetupMode::kGuess ? PriorKind::kGuess : PriorKind::kSetup;
    const auto& sigma = angle ? fr.sigma_rpy : fr.sigma_xyz;
    if (sigma) {
      p->sigma = (*sigma)(axis);
      p->key = key + (angle ? ".sigma_rpy" : ".sigma_xyz");
    } else {
      p->sigma = angle ? id.prior_sigma_angle : id.prior_sigma_length;
      p->key = angle ? "identifier.prior_sigma_angle" : "identifier.prior_sigma_length";
    }
  };
  // Parameter name suffix → axis: x, y, z of a translation; roll (rx), pitch (ry), yaw (rz).
  auto axis_of = [](const std::string& name) {
    const std::string s = name.substr(name.rfind('_') + 1);
    if (s == "x" || s == "rx") return 0;
    if (s == "y" || s == "ry") return 1;
    return 2;
  };
  for (size_t i = 0; i < params.size(); ++i) {
    const kinematics::Parameter& p = params[i];
    ParameterPrior& out = c.prior[i];
    if (p.group == "base") {
      frame_prior(f.world_from_base, "frames.world_from_base", p.is_angle, axis_of(p.name), &out);
    } else if (p.group == "imu" && f.flange_to_imu) {
      frame_prior(*f.flange_to_imu, "frames.flange_to_imu", true, axis_of(p.name), &out);
    } else if (p.group == "earth" && f.earth_from_world) {
      frame_prior(*f.earth_from_world, "frames.earth_from_world", true, axis_of(p.name), &out);
    } else if (p.group == "marker") {
      bool found = false;
      for (size_t slot = 0; slot < c.model.markers().size() && !found; ++slot)
        for (int a = 0; a < 3 && !found; ++a)
          if (c.model.markers()[slot].param[a] == static_cast<int>(i)) {
            for (size_t k = 0; k < f.markers.size(); ++k)
              if (f.markers[k].id == c.model.markers()[slot].id)
                frame_prior(f.markers[k].frame, "frames.markers[" + std::to_string(k) + "]", false,
                            a, &out);
            found = true;
          }
      if (!found)
        throw std::runtime_error(src + ": parameter '" + p.name + "' belongs to no marker");
    } else {
      out.kind = PriorKind::kArm;
      out.sigma = p.is_angle ? id.prior_sigma_angle : id.prior_sigma_length;
      out.key = p.is_angle ? "identifier.prior_sigma_angle" : "identifier.prior_sigma_length";
    }
  }

  // The pose pipeline: today's settings with the cell's values.
  estimation::PosePipelineSettings& ps = c.pipeline;
  const StillWindowSpec& sw = spec.still_window;
  ps.still.joint_rate_threshold = sw.joint_rate_threshold;
  ps.still.gyro_threshold = sw.gyro_threshold;
  ps.still.accel_threshold = sw.accel_threshold;
  ps.still.min_duration = sw.min_duration;
  ps.settle_time = sw.settle_time;
  ps.min_window_samples = sw.min_window_samples;
  ps.min_raw_samples = sw.min_raw_samples;
  ps.max_gap = sw.max_gap;
  ps.rest_from_joints = sw.rest_from_joints;
  // One σ for the position KF: the largest axis (conservative for the others).
  ps.position.position_sigma = spec.position.sigma.maxCoeff();
  ps.use_orientation = spec.imu.has_value();
  if (spec.imu) {
    ps.orientation.gyro_noise_density = spec.imu->gyro_noise_density;
    ps.orientation.earth = ps.position.earth = spec.imu->earth;
    ps.orientation.gravity = ps.position.gravity = ps.still.gravity = spec.imu->gravity;
    ps.orientation.gyro_range = spec.imu->gyro_range;
    ps.orientation.accel_range = spec.imu->accel_range;
    ps.orientation.max_step = estimation::MaxStepForRate(spec.imu->rate);  // a slow IMU: no silence
    ps.accel_bias_sigma = spec.imu->accel_bias_sigma;
    ps.accel_bias_random_walk = spec.imu->accel_bias_random_walk;
    ps.position.accel_delay = spec.imu->accel_delay;
  }

  identification::EkfSettings& es = c.ekf;
  es.prior_sigma_length = id.prior_sigma_length;
  es.prior_sigma_angle = id.prior_sigma_angle;
  es.drift_sigma_length = id.drift_sigma_length;
  es.drift_sigma_angle = id.drift_sigma_angle;
  es.gate_probability = id.gate_probability;
  es.gate_after = id.gate_after;

  // The joints as the ROS 2 driver names them: one per model joint.
  for (const kinematics::Joint& j : c.model.joints()) c.ros2_joint_names.push_back(j.name);
  if (spec.ros2 && !spec.ros2->joint_names.empty()) {
    if (spec.ros2->joint_names.size() != c.ros2_joint_names.size())
      throw std::runtime_error(
          src + ": ros2.joint_names: " + std::to_string(spec.ros2->joint_names.size()) +
          " names, the arm has " + std::to_string(c.ros2_joint_names.size()) + " joints");
    c.ros2_joint_names = spec.ros2->joint_names;
  }
  return c;
}

BuiltCell LoadCell(const std::filesystem::path& path) {
  return BuildCell(LoadCellSpec(path));
}

}  // namespace rcal::io
