#include "rcal/io/robot_yaml.hpp"

#include <yaml-cpp/yaml.h>

#include <charconv>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>
#include <set>
#include <sstream>
#include <stdexcept>

#include "rcal/geometry/so3.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/yaml_reader.hpp"

namespace rcal::io {
namespace {

using kinematics::Joint;
using kinematics::JointType;

constexpr const char* kSchema = "rcal.robot/1";

using detail::Reader;

/// A robot's constant angles (D–H alpha, theta, beta; roll-pitch-yaw) lie within a turn, its
/// revolute limits within two turns (UR ±2π, a wrist's ±450° on some arms): written in degrees
/// (alpha: -90, upper: 170) they are beyond, refused naming degrees (Reader::BoundedAngle).
constexpr double kTurn = 2.0 * std::numbers::pi;

double ConstantAngle(const Reader& r, const YAML::Node& n, const std::string& path) {
  return r.BoundedAngle(n, path, kTurn, "a turn (2π)");
}

Eigen::Vector3d Rpy(const Reader& r, const YAML::Node& n, const std::string& path) {
  if (!n.IsSequence() || n.size() != 3)
    r.Fail(path, "expected a list of 3 angles [roll, pitch, yaw], got " + Reader::Kind(n), &n);
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) v(i) = ConstantAngle(r, n[i], path + "[" + std::to_string(i) + "]");
  return v;
}

Joint ReadJoint(const Reader& r, const YAML::Node& n, const std::string& path) {
  r.CheckMap(n, path, {"name", "type", "lower", "upper"});
  Joint j;
  j.name = r.String(r.Require(n, path, "name"), path + ".name");
  const YAML::Node type = r.Require(n, path, "type");
  const std::string t = r.String(type, path + ".type");
  if (t == "revolute") {
    j.type = JointType::kRevolute;
  } else if (t == "prismatic") {
    j.type = JointType::kPrismatic;
  } else {
    r.Fail(path + ".type", "expected revolute or prismatic, got '" + t + "'", &type);
  }
  const auto limit = [&](const char* key) {
    const YAML::Node v = r.Require(n, path, key);
    return j.type == JointType::kRevolute
               ? r.BoundedAngle(v, path + "." + key, 2 * kTurn, "two turns (4π)")
               : r.Number(v, path + "." + key, false);
  };
  j.lower = limit("lower");
  j.upper = limit("upper");
  if (!(j.lower < j.upper)) r.Fail(path, "lower limit must be below upper limit", &n);
  return j;
}

FrameSpec ReadFrame(const Reader& r, const YAML::Node& n, const std::string& path, bool xyz,
                    bool rpy) {
  std::set<std::string> keys{"identify"};
  if (xyz) keys.insert("xyz");
  if (rpy) keys.insert("rpy");
  r.CheckMap(n, path, keys);
  FrameSpec f;
  if (xyz) f.xyz = r.Vec3(r.Require(n, path, "xyz"), path + ".xyz", false);
  if (rpy) f.rpy = Rpy(r, r.Require(n, path, "rpy"), path + ".rpy");
  if (n["identify"]) f.identify = r.Bool(n["identify"], path + ".identify");
  return f;
}

LinkSpec ReadLink(const Reader& r, const YAML::Node& n, const std::string& path, Convention c) {
  LinkSpec l;
  if (c == Convention::kUrdf) {
    r.CheckMap(n, path, {"name", "xyz", "rpy", "axis", "joint", "identify"});
    if (n["name"]) l.name = r.String(n["name"], path + ".name");
    l.xyz = r.Vec3(r.Require(n, path, "xyz"), path + ".xyz", false);
    l.rpy = Rpy(r, r.Require(n, path, "rpy"), path + ".rpy");
    if (n["joint"]) {
      l.joint = ReadJoint(r, n["joint"], path + ".joint");
      const YAML::Node axis = r.Require(n, path, "axis");
      l.axis = r.Vec3(axis, path + ".axis", false);
      if (l.axis.norm() < 1e-9) r.Fail(path + ".axis", "axis must not be zero", &axis);
      l.axis.normalize();
      if (n["identify"]) l.identify = r.Bool(n["identify"], path + ".identify");
    } else {
      if (n["axis"]) r.Fail(path + ".axis", "only with a joint (this entry has no joint:)", &n);
      if (n["identify"])
        r.Fail(path + ".identify", "only with a joint (a fixed transform is never identified)", &n);
      l.identify = false;
    }
    return l;
  }
  r.CheckMap(n, path, {"a", "alpha", "d", "theta", "hayati", "beta", "joint"});
  l.a = r.Number(r.Require(n, path, "a"), path + ".a", false);
  l.alpha = ConstantAngle(r, r.Require(n, path, "alpha"), path + ".alpha");
  l.d = r.Number(r.Require(n, path, "d"), path + ".d", false);
  l.theta = ConstantAngle(r, r.Require(n, path, "theta"), path + ".theta");
  l.joint = ReadJoint(r, r.Require(n, path, "joint"), path + ".joint");
  if (n["hayati"]) l.hayati = r.Bool(n["hayati"], path + ".hayati");
  if (l.hayati && l.joint->type != JointType::kRevolute)
    r.Fail(path + ".hayati", "only for revolute joints", &n);
  if (n["beta"]) {
    if (!l.hayati) r.Fail(path + ".beta", "only with hayati: true", &n);
    l.beta = ConstantAngle(r, n["beta"], path + ".beta");
  }
  return l;
}

// ---------------------------------------------------------------------------------------------
// Writing.

std::string Num(double v) {
  if (v == 0.0) return "0";
  char buf[64];
  const auto [ptr, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  if (ec != std::errc()) throw std::runtime_error("cannot format a number");
  return std::string(buf, ptr);
}

std::string Angle(double v) {
  if (v == 0.0) return "0";
  const int dens[] = {1, 2, 3, 4, 5, 6, 8, 9, 10, 12, 18, 36};
  for (int den : dens) {
    for (int num = 1; num <= 4 * den; ++num) {
      if (std::gcd(num, den) != 1) continue;
      // Built by appending: GCC 12 warns falsely (-Wrestrict) on "x" + std::string.
      std::string s;
      if (num != 1) {
        s += std::to_string(num);
        s += '*';
      }
      s += "pi";
      if (den != 1) {
        s += '/';
        s += std::to_string(den);
      }
      if (ParseAngle(s) == v) return s;
      std::string neg(1, '-');
      neg += s;
      if (ParseAngle(neg) == v) return neg;
    }
  }
  return Num(v);
}

std::string Vec(const Eigen::Vector3d& v, bool angle) {
  std::string s = "[";
  for (int i = 0; i < 3; ++i) {
    if (i) s += ", ";
    s += angle ? Angle(v(i)) : Num(v(i));
  }
  return s + "]";
}

std::string Str(const std::string& s) {
  static const std::set<std::string> reserved{
      "true", "false", "yes",  "no",   "on",   "off",   "null", "True", "False", "Yes", "No",
      "On",   "Off",   "Null", "NULL", "TRUE", "FALSE", "~",    "y",    "n",     "Y",   "N"};
  bool plain = !s.empty() && !reserved.count(s) &&
               (std::isalpha(static_cast<unsigned char>(s[0])) || s[0] == '_');
  for (char ch : s)
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-' || ch == '.'))
      plain = false;
  if (plain) return s;
  std::string q = "\"";
  for (char ch : s) {
    if (ch == '"' || ch == '\\') q += '\\';
    q += ch;
  }
  return q + "\"";
}

std::string JointText(const Joint& j) {
  const bool angle = j.type == JointType::kRevolute;
  auto lim = [&](double v) { return angle ? Angle(v) : Num(v); };
  return "{name: " + Str(j.name) + ", type: " + (angle ? "revolute" : "prismatic") +
         ", lower: " + lim(j.lower) + ", upper: " + lim(j.upper) + "}";
}

std::string Identify(bool identify) {
  return identify ? "" : ", identify: false";
}

// ---------------------------------------------------------------------------------------------
// Parameter names → spec fields (ModelBuilder's naming).

bool IsDigits(const std::string& s) {
  if (s.empty()) return false;
  for (char ch : s)
    if (!std::isdigit(static_cast<unsigned char>(ch))) return false;
  return true;
}

}  // namespace

std::optional<double> ParseAngle(const std::string& text) {
  size_t i = 0;
  const size_t n = text.size();
  auto skip = [&] {
    while (i < n && (text[i] == ' ' || text[i] == '\t')) ++i;
  };
  auto factor = [&]() -> std::optional<double> {
    skip();
    if (text.compare(i, 2, "pi") == 0) {
      i += 2;
      return std::numbers::pi;
    }
    if (i < n && text[i] == '+') ++i;
    double v = 0;
    const auto [ptr, ec] = std::from_chars(text.data() + i, text.data() + n, v);
    if (ec != std::errc() || ptr == text.data() + i) return std::nullopt;
    i = ptr - text.data();
    return v;
  };
  skip();
  double sign = 1.0;
  if (i < n && (text[i] == '-' || text[i] == '+')) {
    if (text[i] == '-') sign = -1.0;
    ++i;
  }
  std::optional<double> v = factor();
  if (!v) return std::nullopt;
  double value = *v;
  for (;;) {
    skip();
    if (i == n) break;
    const char op = text[i];
    if (op != '*' && op != '/') return std::nullopt;
    ++i;
    const std::optional<double> f = factor();
    if (!f) return std::nullopt;
    value = op == '*' ? value * *f : value / *f;
  }
  return sign * value;
}

RobotSpec ParseRobotYaml(const std::string& text, const std::string& source) {
  const Reader r(source);
  const YAML::Node root = detail::LoadYaml(text, source);
  r.CheckMap(root, "",
             {"schema", "name", "convention", "base", "links", "tool", "marker", "markers", "imu",
              "earth"});
  const YAML::Node schema = r.Require(root, "", "schema");
  if (r.String(schema, "schema") != kSchema)
    r.Fail("schema", std::string("expected ") + kSchema + ", got '" + schema.Scalar() + "'",
           &schema);
  RobotSpec spec;
  spec.name = r.String(r.Require(root, "", "name"), "name");
  const YAML::Node conv = r.Require(root, "", "convention");
  const std::string c = r.String(conv, "convention");
  if (c == "dh") {
    spec.convention = Convention::kDh;
  } else if (c == "mdh") {
    spec.convention = Convention::kModifiedDh;
  } else if (c == "urdf") {
    spec.convention = Convention::kUrdf;
  } else {
    r.Fail("convention", "expected dh, mdh or urdf, got '" + c + "'", &conv);
  }
  const YAML::Node links = r.Require(root, "", "links");
  if (!links.IsSequence() || links.size() == 0)
    r.Fail("links", "expected a list of links, got " + Reader::Kind(links), &links);
  std::set<std::string> joint_names;
  for (size_t i = 0; i < links.size(); ++i) {
    const std::string path = "links[" + std::to_string(i) + "]";
    const YAML::Node link = links[i];
    spec.links.push_back(ReadLink(r, link, path, spec.convention));
    const auto& j = spec.links.back().joint;
    if (j && !joint_names.insert(j->name).second)
      r.Fail(path + ".joint.name", "joint name '" + j->name + "' used twice", &link);
  }
  if (joint_names.empty()) r.Fail("links", "no joint in the chain", &links);
  if (root["base"]) spec.base = ReadFrame(r, root["base"], "base", true, true);
  if (root["marker"] && root["markers"]) {
    const YAML::Node both = root["markers"];
    r.Fail("markers", "give marker (one, id 0) or markers (a list), not both", &both);
  }
  if (root["marker"]) {
    const FrameSpec f = ReadFrame(r, root["marker"], "marker", true, false);
    spec.markers.push_back({0, f.xyz, f.identify});
  }
  if (root["markers"]) {
    const YAML::Node list = root["markers"];
    if (!list.IsSequence() || list.size() == 0)
      r.Fail("markers", "expected a list of markers, got " + Reader::Kind(list), &list);
    for (size_t i = 0; i < list.size(); ++i) {
      const std::string path = "markers[" + std::to_string(i) + "]";
      const YAML::Node n = list[i];
      r.CheckMap(n, path, {"id", "xyz", "identify"});
      MarkerSpec m;
      const YAML::Node id = r.Require(n, path, "id");
      const std::string text = id.IsScalar() ? id.Scalar() : std::string();
      const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), m.id);
      if (text.empty() || ec != std::errc() || end != text.data() + text.size() || m.id < 0 ||
          m.id > 1000000)
        r.Fail(path + ".id", "expected an integer id from 0 to 1000000, got '" + text + "'", &id);
      m.xyz = r.Vec3(r.Require(n, path, "xyz"), path + ".xyz", false);
      if (n["identify"]) m.identify = r.Bool(n["identify"], path + ".identify");
      for (const MarkerSpec& o : spec.markers)
        if (o.id == m.id) r.Fail(path + ".id", "marker id " + std::to_string(m.id) + " twice", &id);
      spec.markers.push_back(m);
    }
  }
  if (root["imu"]) spec.imu = ReadFrame(r, root["imu"], "imu", false, true);
  if (root["earth"]) spec.earth = ReadFrame(r, root["earth"], "earth", false, true);
  if (root["tool"]) {
    const YAML::Node t = root["tool"];
    r.CheckMap(t, "tool", {"a", "alpha", "d", "theta", "identify"});
    ToolSpec tool;
    tool.a = r.Number(r.Require(t, "tool", "a"), "tool.a", false);
    tool.alpha = ConstantAngle(r, r.Require(t, "tool", "alpha"), "tool.alpha");
    tool.d = r.Number(r.Require(t, "tool", "d"), "tool.d", false);
    tool.theta = ConstantAngle(r, r.Require(t, "tool", "theta"), "tool.theta");
    if (t["identify"]) tool.identify = r.Bool(t["identify"], "tool.identify");
    spec.tool = tool;
  }
  CheckArmSize(spec, source);
  return spec;
}

void CheckArmSize(const RobotSpec& spec, const std::string& source) {
  double total = 0.0;
  for (const LinkSpec& l : spec.links)
    total += spec.convention == Convention::kUrdf ? l.xyz.norm() : std::abs(l.a) + std::abs(l.d);
  if (spec.tool) total += std::abs(spec.tool->a) + std::abs(spec.tool->d);
  if (!(total > detail::kMaxLength)) return;
  std::ostringstream o;
  o << source << ": links: the arm's lengths add up to " << total
    << " m, beyond 100 m: no arm is that long (the largest industrial arms reach about 4 m)"
    << (total * 1e-3 <= detail::kMaxLength ? ": millimetres? rcal files are in metres" : "");
  throw std::runtime_error(o.str());
}

RobotSpec LoadRobotSpec(const std::filesystem::path& path) {
  return ParseRobotYaml(ReadFile(path), path.string());
}

kinematics::KinematicModel BuildModel(const RobotSpec& spec) {
  kinematics::ModelBuilder b(spec.name);
  try {
    if (spec.base) b.BaseFrame(spec.base->xyz, spec.base->rpy, spec.base->identify);
    for (size_t i = 0; i < spec.links.size(); ++i) {
      const LinkSpec& l = spec.links[i];
      const std::string where = spec.name + ": links[" + std::to_string(i) + "]";
      if (spec.convention == Convention::kUrdf) {
        if (l.joint) {
          b.UrdfJoint(l.xyz, l.rpy, l.axis, *l.joint, l.identify);
        } else {
          b.FixedTransform(l.xyz, l.rpy);
        }
        continue;
      }
      if (!l.joint) throw std::runtime_error(where + ": a D–H link needs a joint");
      if (spec.convention == Convention::kDh) {
        b.DhLink(l.a, l.alpha, l.d, l.theta, *l.joint, l.hayati, l.beta);
      } else {
        b.ModifiedDhLink(l.a, l.alpha, l.d, l.theta, *l.joint, l.hayati, l.beta);
      }
    }
    if (spec.tool)
      b.ToolDh(spec.tool->a, spec.tool->alpha, spec.tool->d, spec.tool->theta, spec.tool->identify);
    for (const MarkerSpec& m : spec.markers) b.MarkerOffset(m.xyz, m.identify, m.id);
    if (spec.imu) b.ImuMounting(spec.imu->rpy, spec.imu->identify);
    if (spec.earth) b.EarthFrame(spec.earth->rpy, spec.earth->identify);
  } catch (const std::logic_error& e) {
    throw std::runtime_error(spec.name + ": " + e.what());
  }
  return b.Build();
}

kinematics::KinematicModel LoadRobotYaml(const std::filesystem::path& path) {
  return BuildModel(LoadRobotSpec(path));
}

Eigen::Vector3d RobustRpy(const Eigen::Matrix3d& R) {
  const double pitch = std::atan2(-R(2, 0), std::hypot(R(0, 0), R(1, 0)));
  const double yaw = std::atan2(R(1, 0), R(0, 0));
  const Eigen::Matrix3d M = (geometry::Rz(yaw) * geometry::Ry(pitch)).transpose() * R;
  const double roll = std::atan2(M(2, 1), M(1, 1));
  return {roll, pitch, yaw};
}

void ComposeUrdfOrigin(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy,
                       const Eigen::Matrix<double, 6, 1>& error, Eigen::Vector3d* xyz_out,
                       Eigen::Vector3d* rpy_out) {
  if (error.isZero(0.0)) {
    *xyz_out = xyz;
    *rpy_out = rpy;
    return;
  }
  const Eigen::Matrix3d R = geometry::FromRpy(rpy);
  *xyz_out = xyz + R * error.head<3>();
  // Rz(drz)·Ry(dry)·Rx(drx) = FromRpy(roll = drx, pitch = dry, yaw = drz).
  *rpy_out = RobustRpy(R * geometry::FromRpy(error(5), error(4), error(3)));
}

RobotSpec CalibratedSpec(const RobotSpec& spec, const kinematics::KinematicModel& model,
                         const Eigen::VectorXd& x) {
  const std::string who = "calibrated robot '" + spec.name + "'";
  if (x.size() != model.num_params())
    throw std::runtime_error(who + ": x has " + std::to_string(x.size()) + " values, the model " +
                             std::to_string(model.num_params()) + " parameters");
  {
    const kinematics::KinematicModel rebuilt = BuildModel(spec);
    bool same =
        rebuilt.num_params() == model.num_params() && rebuilt.num_joints() == model.num_joints();
    for (int i = 0; same && i < model.num_params(); ++i)
      same = rebuilt.parameters()[i].name == model.parameters()[i].name;
    if (!same)
      throw std::runtime_error(who + ": the model was not built from this robot description");
  }
  for (int i = 0; i < x.size(); ++i)
    if (!std::isfinite(x(i)))
      throw std::runtime_error(who + ": parameter '" + model.parameters()[i].name +
                               "' is not finite");
  RobotSpec out = spec;
  std::vector<Eigen::Matrix<double, 6, 1>> urdf_error(spec.links.size(),
                                                      Eigen::Matrix<double, 6, 1>::Zero());
  const std::vector<std::string> urdf_suffix{"_dx", "_dy", "_dz", "_drz", "_dry", "_drx"};
  for (int i = 0; i < model.num_params(); ++i) {
    const std::string& n = model.parameters()[i].name;
    const double v = x(i);
    auto rpy_index = [](char axis) { return axis == 'x' ? 0 : axis == 'y' ? 1 : 2; };
    auto is = [&](std::initializer_list<const char*> names) {
      for (const char* s : names)
        if (n == s) return true;
      return false;
    };
    if (out.base && is({"base_x", "base_y", "base_z"})) {
      out.base->xyz(n[5] - 'x') += v;
      continue;
    }
    if (out.base && is({"base_rx", "base_ry", "base_rz"})) {
      out.base->rpy(rpy_index(n[6])) += v;
      continue;
    }
    if (model.parameters()[i].group == "marker") {
      // marker_x (id 0) or marker<id>_x: the slot's spec entry.
      bool done = false;
      for (int slot = 0; slot < static_cast<int>(model.markers().size()) && !done; ++slot)
        for (int a = 0; a < 3 && !done; ++a)
          if (model.markers()[slot].param[a] == i) {
            for (MarkerSpec& m : out.markers)
              if (m.id == model.markers()[slot].id) m.xyz(a) += v;
            done = true;
          }
      if (done) continue;
    }
    if (out.imu && is({"imu_rx", "imu_ry", "imu_rz"})) {
      out.imu->rpy(rpy_index(n[5])) += v;
      continue;
    }
    if (out.earth && is({"earth_rx", "earth_ry", "earth_rz"})) {
      out.earth->rpy(rpy_index(n[7])) += v;
      continue;
    }
    if (out.tool && is({"tool_a", "tool_alpha", "tool_d", "tool_theta"})) {
      if (n == "tool_a") out.tool->a += v;
      if (n == "tool_alpha") out.tool->alpha += v;
      if (n == "tool_d") out.tool->d += v;
      if (n == "tool_theta") out.tool->theta += v;
      continue;
    }
    if (spec.convention != Convention::kUrdf) {
      size_t k = 0;
      while (k < n.size() && std::isalpha(static_cast<unsigned char>(n[k]))) ++k;
      const std::string field = n.substr(0, k), index = n.substr(k);
      if (IsDigits(index)) {
        const size_t li = std::stoul(index) - 1;
        if (li < out.links.size()) {
          LinkSpec& l = out.links[li];
          if (field == "a") l.a += v;
          if (field == "alpha") l.alpha += v;
          if (field == "d") l.d += v;
          if (field == "theta") l.theta += v;
          if (field == "beta") l.beta += v;
          if (field == "a" || field == "alpha" || field == "d" || field == "theta" ||
              field == "beta")
            continue;
        }
      }
    } else {
      bool found = false;
      for (size_t k = 0; k < urdf_suffix.size() && !found; ++k) {
        const std::string& suf = urdf_suffix[k];
        if (n.size() <= suf.size() || n.compare(n.size() - suf.size(), suf.size(), suf) != 0)
          continue;
        const std::string joint = n.substr(0, n.size() - suf.size());
        for (size_t li = 0; li < out.links.size() && !found; ++li)
          if (out.links[li].joint && out.links[li].joint->name == joint) {
            urdf_error[li](k) += v;
            found = true;
          }
      }
      if (found) continue;
    }
    throw std::runtime_error(who + ": parameter '" + n + "' has no place in the description");
  }
  for (size_t li = 0; li < out.links.size(); ++li)
    ComposeUrdfOrigin(spec.links[li].xyz, spec.links[li].rpy, urdf_error[li], &out.links[li].xyz,
                      &out.links[li].rpy);
  return out;
}

std::string RobotYamlText(const RobotSpec& spec, const std::vector<std::string>& header) {
  std::ostringstream o;
  for (const auto& h : header) o << "# " << h << "\n";
  o << "schema: " << kSchema << "\n";
  o << "name: " << Str(spec.name) << "\n";
  o << "convention: "
    << (spec.convention == Convention::kDh           ? "dh"
        : spec.convention == Convention::kModifiedDh ? "mdh"
                                                     : "urdf")
    << "\n";
  if (spec.base)
    o << "base: {xyz: " << Vec(spec.base->xyz, false) << ", rpy: " << Vec(spec.base->rpy, true)
      << Identify(spec.base->identify) << "}\n";
  o << "links:\n";
  for (const LinkSpec& l : spec.links) {
    if (spec.convention == Convention::kUrdf) {
      const char* first = "  - ";
      if (!l.name.empty() && !l.joint) {
        o << first << "name: " << Str(l.name) << "\n";
        first = "    ";
      }
      o << first << "xyz: " << Vec(l.xyz, false) << "\n";
      o << "    rpy: " << Vec(l.rpy, true) << "\n";
      if (l.joint) {
        o << "    axis: " << Vec(l.axis, false) << "\n";
        o << "    joint: " << JointText(*l.joint) << "\n";
        if (!l.identify) o << "    identify: false\n";
      }
      continue;
    }
    o << "  - a: " << Num(l.a) << "\n";
    o << "    alpha: " << Angle(l.alpha) << "\n";
    o << "    d: " << Num(l.d) << "\n";
    o << "    theta: " << Angle(l.theta) << "\n";
    if (l.hayati) {
      o << "    hayati: true\n";
      if (l.beta != 0.0) o << "    beta: " << Angle(l.beta) << "\n";
    }
    if (l.joint) o << "    joint: " << JointText(*l.joint) << "\n";
  }
  if (spec.tool)
    o << "tool: {a: " << Num(spec.tool->a) << ", alpha: " << Angle(spec.tool->alpha)
      << ", d: " << Num(spec.tool->d) << ", theta: " << Angle(spec.tool->theta)
      << Identify(spec.tool->identify) << "}\n";
  if (spec.markers.size() == 1 && spec.markers[0].id == 0) {
    o << "marker: {xyz: " << Vec(spec.markers[0].xyz, false) << Identify(spec.markers[0].identify)
      << "}\n";
  } else if (!spec.markers.empty()) {
    o << "markers:\n";
    for (const MarkerSpec& m : spec.markers)
      o << "  - {id: " << m.id << ", xyz: " << Vec(m.xyz, false) << Identify(m.identify) << "}\n";
  }
  if (spec.imu)
    o << "imu: {rpy: " << Vec(spec.imu->rpy, true) << Identify(spec.imu->identify) << "}\n";
  if (spec.earth)
    o << "earth: {rpy: " << Vec(spec.earth->rpy, true) << Identify(spec.earth->identify) << "}\n";
  return o.str();
}

void SaveRobotYaml(const std::filesystem::path& path, const RobotSpec& spec,
                   const std::vector<std::string>& header) {
  AtomicWriteFile(path, RobotYamlText(spec, header));
}

void SaveCalibratedRobotYaml(const std::filesystem::path& path, const RobotSpec& spec,
                             const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                             const std::vector<std::string>& header) {
  SaveRobotYaml(path, CalibratedSpec(spec, model, x), header);
}

}  // namespace rcal::io
