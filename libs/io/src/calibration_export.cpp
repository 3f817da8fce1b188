#include "rcal/io/calibration_export.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <map>
#include <random>
#include <stdexcept>

#include "rcal/io/atomic_file.hpp"
#include "rcal/io/plot.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/numeric/median.hpp"

namespace rcal::io {
namespace {

using nlohmann::json;
constexpr const char* kRecordSchema = "rcal.calibration/1";

struct Fnv {
  uint64_t h = 1469598103934665603ull;
  void Bytes(const void* p, size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  }
  void Str(const std::string& s) {
    Bytes(s.data(), s.size());
    Int(-1);  // separator: "ab","c" differs from "a","bc"
  }
  void Int(int64_t v) { Bytes(&v, sizeof v); }
  void Num(double v) {
    if (v == 0.0) v = 0.0;  // −0 hashes as 0
    Bytes(&v, sizeof v);
  }
  void Vec(const Eigen::Vector3d& v) {
    for (int i = 0; i < 3; ++i) Num(v(i));
  }
};

double Angle(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B) {
  return Eigen::AngleAxisd(A.transpose() * B).angle();
}

/// A JSON scalar as YAML (JSON is YAML 1.2): numbers shortest-exact, NaN as null.
std::string Y(double v) {
  return std::isfinite(v) ? json(v).dump() : "null";
}
std::string Y(const std::string& s) {
  return json(s).dump();
}
std::string Y3(const Eigen::Vector3d& v) {
  // Appended piece by piece: GCC 12 warns (-Wrestrict, falsely) on "[" + std::string.
  std::string s("[");
  s.append(Y(v(0))).append(", ").append(Y(v(1))).append(", ").append(Y(v(2))).append("]");
  return s;
}

const json& Key(const json& j, const std::string& key, const std::string& where) {
  if (!j.is_object() || !j.contains(key)) throw std::runtime_error(where + key + ": missing");
  return j.at(key);
}

std::string StrKey(const json& j, const std::string& key, const std::string& where) {
  const json& v = Key(j, key, where);
  if (!v.is_string()) throw std::runtime_error(where + key + ": not a string");
  return v.get<std::string>();
}

}  // namespace

std::string CalibrationHash(const kinematics::KinematicModel& model, const Eigen::VectorXd& x) {
  Fnv f;
  f.Str(model.name());
  for (const kinematics::Joint& j : model.joints()) {
    f.Str(j.name);
    f.Int(static_cast<int>(j.type));
    f.Num(j.lower);
    f.Num(j.upper);
  }
  for (auto s :
       {kinematics::Segment::kEarth, kinematics::Segment::kChain, kinematics::Segment::kImu}) {
    f.Int(static_cast<int>(s));
    for (const kinematics::ElementaryTransform& et : model.ets(s)) {
      f.Int(static_cast<int>(et.kind));
      f.Vec(et.axis);
      f.Num(et.nominal);
      f.Int(et.param);
      f.Int(et.joint);
    }
  }
  for (const kinematics::Parameter& p : model.parameters()) {
    f.Str(p.name);
    f.Int(p.is_angle ? 1 : 0);
  }
  for (const kinematics::Marker& m : model.markers()) {
    f.Int(m.id);
    for (int a = 0; a < 3; ++a) f.Int(m.param[a]);
    f.Vec(m.nominal);
  }
  f.Int(x.size());
  for (int i = 0; i < x.size(); ++i) f.Num(x(i));
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(f.h));
  return std::string("fnv1a64:") + hex;
}

std::string ParameterFrameText(const RobotSpec& spec, const kinematics::KinematicModel& model,
                               int index) {
  const kinematics::Parameter& p = model.parameters().at(index);
  const std::string& base = spec.base_link;
  const std::string& tip = spec.tip_link;
  if (p.group == "base")
    return "world ← " + base + " (T_WB: translation in world, roll-pitch-yaw of R_WB)";
  if (p.group == "earth") return "earth ← world (R_EW, roll-pitch-yaw)";
  if (p.group == "imu") return tip + " → imu (R_FI, roll-pitch-yaw)";
  if (p.group == "tool") return "D–H tool after the last joint (" + tip + ")";
  if (p.group == "marker") {
    for (const kinematics::Marker& m : model.markers())
      for (int a = 0; a < 3; ++a)
        if (m.param[a] == index)
          return tip + " → marker " + std::to_string(m.id) + " (p_FM, " + tip + " frame)";
    return tip + " → marker (p_FM, " + tip + " frame)";
  }
  for (const auto& j : model.joints())
    if (p.group == j.name) return "origin of joint " + j.name + " (parent link frame)";
  return p.group + " (D–H, previous link frame)";
}

ModelParameters ParametersByName(const kinematics::KinematicModel& model,
                                 const std::vector<std::string>& names,
                                 const std::vector<double>& values,
                                 const std::vector<double>& sigmas, const std::string& field,
                                 const std::vector<bool>& identified) {
  if (values.size() != names.size() || (!sigmas.empty() && sigmas.size() != names.size()) ||
      (!identified.empty() && identified.size() != names.size()))
    throw std::runtime_error(field + ": " + std::to_string(names.size()) + " names, " +
                             std::to_string(values.size()) + " values, " +
                             std::to_string(sigmas.size()) + " sigmas");
  ModelParameters p;
  p.x = Eigen::VectorXd::Zero(model.num_params());
  p.sigma = Eigen::VectorXd::Constant(model.num_params(), std::nan(""));
  p.identified.assign(model.num_params(), false);
  std::vector<bool> seen(model.num_params(), false);
  for (size_t i = 0; i < names.size(); ++i) {
    const std::string where = field + "[" + std::to_string(i) + "] '" + names[i] + "'";
    const int k = model.FindParameter(names[i]);
    if (k < 0)
      throw std::runtime_error(where + ": not a parameter of robot '" + model.name() +
                               "' (parameters of another robot or set-up?)");
    if (seen[k]) throw std::runtime_error(where + ": given twice");
    seen[k] = true;
    if (!std::isfinite(values[i])) throw std::runtime_error(where + ": value is not finite");
    p.x(k) = values[i];
    if (!sigmas.empty()) {
      const double s = sigmas[i];
      if (!std::isnan(s) && !(std::isfinite(s) && s >= 0.0))
        throw std::runtime_error(where + ": sigma must be finite and ≥ 0 (or null)");
      p.sigma(k) = s;
    }
    p.identified[k] =
        identified.empty() ? !std::isnan(p.sigma(k)) : static_cast<bool>(identified[i]);
  }
  for (int k = 0; k < model.num_params(); ++k)
    if (!seen[k])
      throw std::runtime_error(field + ": parameter '" + model.parameters()[k].name +
                               "' of robot '" + model.name() + "' is missing");
  return p;
}

nlohmann::json CalibrationRecordJson(const RobotSpec& spec, const kinematics::KinematicModel& model,
                                     const ModelParameters& p, const std::string& robot_file,
                                     const std::string& data, const std::string& date) {
  json params = json::array();
  for (int i = 0; i < model.num_params(); ++i) {
    const double s = i < p.sigma.size() ? p.sigma(i) : std::nan("");
    params.push_back({{"name", model.parameters()[i].name},
                      {"value", p.x(i)},
                      {"sigma", std::isfinite(s) ? json(s) : json(nullptr)},
                      {"identified", p.Identified(i)}});
  }
  return {{"schema", kRecordSchema},
          {"robot", model.name()},
          {"robot_file", robot_file},
          {"robot_yaml", RobotYamlText(spec)},
          {"base_link", spec.base_link},
          {"tip_link", spec.tip_link},
          {"data", data},
          {"date", date},
          {"calibration_hash", CalibrationHash(model, p.x)},
          {"parameters", params}};
}

CalibrationRecord ParseCalibrationRecord(const std::string& text, const std::string& source) {
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::exception& e) {
    throw std::runtime_error(source + ": not JSON: " + e.what());
  }
  std::string where = source + ": ";
  const json* j = &doc;
  if (doc.is_object() && doc.contains("calibration")) {
    j = &doc.at("calibration");
    where += "calibration.";
  } else if (doc.is_object() && !doc.contains("schema")) {
    throw std::runtime_error(source +
                             ": calibration: missing (a results.json of an rcal "
                             "calibrate older than rcal export? run it again)");
  }
  if (StrKey(*j, "schema", where) != kRecordSchema)
    throw std::runtime_error(where + "schema: '" + StrKey(*j, "schema", where) + "', expected " +
                             kRecordSchema);
  CalibrationRecord r;
  r.robot = StrKey(*j, "robot", where);
  r.robot_file = StrKey(*j, "robot_file", where);
  r.data = StrKey(*j, "data", where);
  r.date = StrKey(*j, "date", where);
  r.calibration_hash = StrKey(*j, "calibration_hash", where);
  r.spec = ParseRobotYaml(StrKey(*j, "robot_yaml", where), where + "robot_yaml");
  r.spec.base_link = StrKey(*j, "base_link", where);
  r.spec.tip_link = StrKey(*j, "tip_link", where);
  if (r.spec.name != r.robot)
    throw std::runtime_error(where + "robot: '" + r.robot + "', robot_yaml names '" + r.spec.name +
                             "'");
  const json& params = Key(*j, "parameters", where);
  if (!params.is_array()) throw std::runtime_error(where + "parameters: not an array");
  for (size_t i = 0; i < params.size(); ++i) {
    const std::string at = where + "parameters[" + std::to_string(i) + "].";
    r.names.push_back(StrKey(params[i], "name", at));
    const json& v = Key(params[i], "value", at);
    if (!v.is_number()) throw std::runtime_error(at + "value: not a number");
    r.values.push_back(v.get<double>());
    const json& s = Key(params[i], "sigma", at);
    if (!s.is_number() && !s.is_null())
      throw std::runtime_error(at + "sigma: not a number or null");
    r.sigmas.push_back(s.is_null() ? std::nan("") : s.get<double>());
    bool id = !s.is_null();
    if (params[i].contains("identified")) {
      if (!params[i]["identified"].is_boolean())
        throw std::runtime_error(at + "identified: not true or false");
      id = params[i]["identified"].get<bool>();
    }
    r.identified.push_back(id);
  }
  return r;
}

ParityReport CheckUrdfParity(const std::string& urdf_xml, const RobotSpec& spec,
                             const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                             const ParityOptions& options) {
  if (options.samples < 1) throw std::runtime_error("parity: samples must be at least 1");
  const std::string world = spec.base ? "rcal_world" : spec.base_link;
  struct Pair {
    ParityCheck check;
    UrdfChain chain;
    int slot = -1;  ///< marker slot of a position check; −1 (orientation)
    bool imu = false;
  };
  std::vector<Pair> pairs;
  const auto add = [&](const std::string& what, bool orientation, const std::string& root,
                       const std::string& tip, int slot, bool imu) {
    ParityCheck c;
    c.what = what + ": " + root + " -> " + tip;
    c.orientation = orientation;
    pairs.push_back({c, UrdfChain(urdf_xml, "exported URDF", root, tip), slot, imu});
  };
  const std::string tool =
      model.markers().empty() ? spec.tip_link : UrdfMarkerLink(model.markers()[0].id);
  if (model.markers().empty()) add("p_WT_W of the tool frame", false, world, tool, 0, false);
  for (size_t s = 0; s < model.markers().size(); ++s)
    add("p_WM_W of marker " + std::to_string(model.markers()[s].id), false, world,
        UrdfMarkerLink(model.markers()[s].id), static_cast<int>(s), false);
  add("R_WT of the tool frame", true, world, tool, -1, false);
  const bool has_earth = !model.ets(kinematics::Segment::kEarth).empty();
  const bool has_imu = !model.ets(kinematics::Segment::kImu).empty();
  if (has_earth || has_imu)
    add("R_EI of the IMU", true, has_earth ? "rcal_earth" : world, has_imu ? "rcal_imu" : tool, -1,
        true);
  // Joint vectors map by name: the URDF's joints must be the model's.
  std::vector<std::vector<int>> index(pairs.size());
  for (size_t p = 0; p < pairs.size(); ++p)
    for (const std::string& n : pairs[p].chain.joint_names()) {
      int k = -1;
      for (int i = 0; i < model.num_joints(); ++i)
        if (model.joints()[i].name == n) k = i;
      if (k < 0)
        throw std::runtime_error("exported URDF: joint '" + n + "' on " + pairs[p].check.what +
                                 " is not a joint of robot '" + model.name() + "'");
      index[p].push_back(k);
    }
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Eigen::VectorXd q(model.num_joints());
  for (int n = 0; n < options.samples; ++n) {
    for (int i = 0; i < q.size(); ++i) {
      const kinematics::Joint& j = model.joints()[i];
      q(i) = j.lower + (j.upper - j.lower) * u(rng);
    }
    const kinematics::ToolPose pose = model.Forward(q, x);
    const Eigen::Isometry3d T_WT = model.ToolFrame(q, x);
    for (size_t p = 0; p < pairs.size(); ++p) {
      Eigen::VectorXd qc(index[p].size());
      for (size_t i = 0; i < index[p].size(); ++i) qc(i) = q(index[p][i]);
      const Eigen::Isometry3d T = pairs[p].chain.Pose(qc);
      double e = 0.0;
      if (!pairs[p].check.orientation) {
        const Eigen::Vector3d p_model = model.markers().empty()
                                            ? T_WT.translation()
                                            : model.ForMarker(pairs[p].slot).Forward(q, x).p_WM_W;
        e = (T.translation() - p_model).norm();
      } else {
        e = Angle(T.linear(), pairs[p].imu ? pose.R_EI : T_WT.linear());
      }
      pairs[p].check.errors.push_back(e);
    }
  }
  ParityReport r;
  r.samples = options.samples;
  r.seed = options.seed;
  r.position_tol_m = options.position_tol_m;
  r.orientation_tol_rad = options.orientation_tol_rad;
  std::vector<double> all_p, all_o;
  for (Pair& p : pairs) {
    ParityCheck& c = p.check;
    c.max = *std::max_element(c.errors.begin(), c.errors.end());
    c.median = numeric::UpperMedian(c.errors);
    auto& all = c.orientation ? all_o : all_p;
    all.insert(all.end(), c.errors.begin(), c.errors.end());
    r.checks.push_back(std::move(c));
  }
  r.max_position_m = all_p.empty() ? 0.0 : *std::max_element(all_p.begin(), all_p.end());
  r.median_position_m = all_p.empty() ? 0.0 : numeric::UpperMedian(all_p);
  r.max_orientation_rad = all_o.empty() ? 0.0 : *std::max_element(all_o.begin(), all_o.end());
  r.median_orientation_rad = all_o.empty() ? 0.0 : numeric::UpperMedian(all_o);
  // NaN compares false: a NaN error fails.
  r.passed = r.max_position_m <= options.position_tol_m &&
             r.max_orientation_rad <= options.orientation_tol_rad;
  return r;
}

std::string ParameterYamlText(const ExportInput& in, const std::string& hash,
                              const std::string& date) {
  const kinematics::KinematicModel& model = in.model;
  const Eigen::VectorXd& x = in.parameters.x;
  const Eigen::VectorXd& sigma = in.parameters.sigma;
  std::string s;
  s += "# rcal export: every parameter of the identified model " + model.name() +
       " with its 1-sigma, SI units (m, rad).\n";
  s += "# error: identified error from the nominal (drawing) value; value = nominal + error.\n";
  s += "# sigma null: not identified (held at its value), or its sigma unknown (identified: "
       "true).\n";
  s += "# Frames: roll-pitch-yaw with\n";
  s += "# R = Rz(yaw) Ry(pitch) Rx(roll).\n";
  s += "schema: rcal.calibration_parameters/1\n";
  s += "robot: " + Y(model.name()) + "\n";
  s += "calibration_hash: " + Y(hash) + "\n";
  s += "date: " + Y(date) + "\n";
  s += "data: " + Y(in.data) + "\n";
  s += "from: " + Y(in.from) + "\n";
  s += "robot_file: " + Y(in.robot_file) + "\n";
  s += "units: {length: m, angle: rad}\n";
  s += "chain: {base_link: " + Y(in.spec.base_link) + ", tip_link: " + Y(in.spec.tip_link) +
       ", joints: [";
  for (int i = 0; i < model.num_joints(); ++i) s += (i ? ", " : "") + Y(model.joints()[i].name);
  s += "]}\nparameters:\n";
  for (int i = 0; i < model.num_params(); ++i) {
    const kinematics::Parameter& p = model.parameters()[i];
    s += "  - {name: " + Y(p.name) + ", frame: " + Y(ParameterFrameText(in.spec, model, i)) +
         ", unit: " + (p.is_angle ? "rad" : "m") + ", nominal: " + Y(p.nominal) +
         ", error: " + Y(x(i)) + ", value: " + Y(p.nominal + x(i)) + ", sigma: " + Y(sigma(i)) +
         ", identified: " + (in.parameters.Identified(i) ? "true" : "false") + "}\n";
  }
  const RobotSpec cal = CalibratedSpec(in.spec, model, x);
  s += "setup_frames:\n";
  if (cal.base)
    s += "  world_from_base: {parent: rcal_world, child: " + Y(in.spec.base_link) +
         ", what: T_WB, xyz_m: " + Y3(cal.base->xyz) + ", rpy_rad: " + Y3(cal.base->rpy) + "}\n";
  if (!cal.markers.empty()) {
    s += "  tip_to_markers:\n";
    for (const MarkerSpec& m : cal.markers)
      s += "    - {id: " + std::to_string(m.id) + ", parent: " + Y(in.spec.tip_link) +
           ", child: " + Y(UrdfMarkerLink(m.id)) + ", what: p_FM, xyz_m: " + Y3(m.xyz) + "}\n";
  }
  if (cal.imu)
    s += "  tip_to_imu: {parent: " + Y(in.spec.tip_link) +
         ", child: rcal_imu, what: R_FI, rpy_rad: " + Y3(cal.imu->rpy) + "}\n";
  if (cal.earth)
    s += "  earth_from_world: {parent: rcal_earth, child: rcal_world, what: R_EW, rpy_rad: " +
         Y3(cal.earth->rpy) + "}\n";
  if (!cal.base && cal.markers.empty() && !cal.imu && !cal.earth) s += "  {}\n";
  return s;
}

std::string UtcNow() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

ExportResult ExportCalibration(const ExportInput& in, const std::filesystem::path& out_dir,
                               const ParityOptions& options) {
  const kinematics::KinematicModel& model = in.model;
  const ModelParameters& p = in.parameters;
  if (p.x.size() != model.num_params() || p.sigma.size() != model.num_params())
    throw std::runtime_error("export: " + std::to_string(p.x.size()) + " values and " +
                             std::to_string(p.sigma.size()) + " sigmas for robot '" + model.name() +
                             "' with " + std::to_string(model.num_params()) + " parameters");
  ExportResult r;
  r.hash = CalibrationHash(model, p.x);
  r.date = in.date.empty() ? UtcNow() : in.date;
  // The σ of the identified parameters, for the URDF's header.
  std::vector<std::string> header = {
      " rcal export: calibrated robot " + model.name() + " ",
      " calibration_hash " + r.hash + ", date " + r.date + " ",
      " data: " + in.data + " (parameters from " + in.from + ") ",
      " every parameter with its 1-sigma [m, rad]: calibration.yaml; parity: parity.md "};
  std::string sig;
  for (int i = 0; i < model.num_params(); ++i)
    if (p.Identified(i))
      sig += " " + model.parameters()[i].name + "=" +
             (std::isnan(p.sigma(i)) ? std::string("unknown") : Y(p.sigma(i)));
  header.push_back(" sigma [m | rad]:" + (sig.empty() ? std::string(" none identified") : sig) +
                   " ");
  const std::string urdf =
      RobotDescriptionUrdf(in.spec, model, p.x, in.source_urdf_xml, in.robot_file, header);
  r.parity = CheckUrdfParity(urdf, in.spec, model, p.x, options);

  namespace fs = std::filesystem;
  const auto write = [&](const std::string& name, const std::string& text) {
    AtomicWriteFile(out_dir / name, text);
    r.files.push_back(out_dir / name);
  };
  write("robot_calibrated.urdf", urdf);
  write("calibration.yaml", ParameterYamlText(in, r.hash, r.date));
  write("calibration.json",
        CalibrationRecordJson(in.spec, model, p, in.robot_file, in.data, r.date).dump(2) + "\n");

  const ParityReport& par = r.parity;
  json checks = json::array();
  for (const ParityCheck& c : par.checks)
    checks.push_back({{"what", c.what},
                      {"unit", c.orientation ? "rad" : "m"},
                      {"max", c.max},
                      {"median", c.median}});
  const json pj = {{"schema", "rcal.urdf_parity/1"},
                   {"robot", model.name()},
                   {"calibration_hash", r.hash},
                   {"date", r.date},
                   {"data", in.data},
                   {"from", in.from},
                   {"urdf", "robot_calibrated.urdf"},
                   {"parser", "liburdfdom (rcal::io::UrdfChain)"},
                   {"samples", par.samples},
                   {"seed", par.seed},
                   {"position_tolerance_m", par.position_tol_m},
                   {"orientation_tolerance_rad", par.orientation_tol_rad},
                   {"max_position_error_m", par.max_position_m},
                   {"median_position_error_m", par.median_position_m},
                   {"max_orientation_error_rad", par.max_orientation_rad},
                   {"median_orientation_error_rad", par.median_orientation_rad},
                   {"checks", checks},
                   {"passed", par.passed}};
  write("parity.json", pj.dump(2) + "\n");

  // The error distribution: each check's errors sorted (a quantile plot), in nm and nrad.
  PlotSpec plot{"URDF parity: " + model.name() + ", " + std::to_string(par.samples) +
                    " random joint vectors (sorted)",
                "joint vectors, sorted by error",
                "position error [nm]",
                {}};
  plot.y2label = "orientation error [nrad]";
  for (const ParityCheck& c : par.checks) {
    std::vector<double> xs, ys = c.errors;
    std::sort(ys.begin(), ys.end());
    for (size_t i = 0; i < ys.size(); ++i) {
      xs.push_back(static_cast<double>(i + 1));
      ys[i] *= 1e9;
    }
    plot.series.push_back({c.what, xs, ys, "lines", c.orientation});
  }
  const bool plotted = PlotPng(plot, out_dir / "parity.png");
  if (plotted) r.files.push_back(out_dir / "parity.png");

  char line[512];
  std::string md = "# URDF parity: " + model.name() + "\n\n";
  md += std::string("**") + (par.passed ? "PASSED" : "FAILED") + "**: `robot_calibrated.urdf`, " +
        "reloaded through liburdfdom, against the identified model's forward kinematics at " +
        std::to_string(par.samples) + " random joint vectors within the limits (seed " +
        std::to_string(par.seed) + ").\n\n";
  md += "- Calibration hash: `" + r.hash + "`, date " + r.date + "\n- Data: `" + in.data +
        "`; parameters from `" + in.from + "`\n";
  std::snprintf(line, sizeof line,
                "- Position: max %.3g nm, median %.3g nm (tolerance %.3g nm)\n"
                "- Orientation: max %.3g nrad, median %.3g nrad (tolerance %.3g nrad)\n\n",
                par.max_position_m * 1e9, par.median_position_m * 1e9, par.position_tol_m * 1e9,
                par.max_orientation_rad * 1e9, par.median_orientation_rad * 1e9,
                par.orientation_tol_rad * 1e9);
  md += line;
  md += "| check | max | median |\n|---|---|---|\n";
  for (const ParityCheck& c : par.checks) {
    const char* unit = c.orientation ? "nrad" : "nm";
    std::snprintf(line, sizeof line, "| %s | %.3g %s | %.3g %s |\n", c.what.c_str(), c.max * 1e9,
                  unit, c.median * 1e9, unit);
    md += line;
  }
  md += plotted ? "\n![error distribution](parity.png)\n" : "\n(no plot: gnuplot unavailable)\n";
  md += "\nEvery parameter with its σ: `calibration.yaml`.\n";
  write("parity.md", md);
  return r;
}

}  // namespace rcal::io
