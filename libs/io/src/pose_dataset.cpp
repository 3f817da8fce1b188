#include "rcal/io/pose_dataset.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>

#include "rcal/geometry/so3.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/numeric/median.hpp"

namespace rcal::io {
namespace {

/// Quaternions whose norm is further than this from 1 are rejected, not normalised: a file with
/// such values is wrong, not imprecise.
constexpr double kUnitTolerance = 1e-3;

/// prefix + number. (Not `"q" + std::to_string(j)`: GCC 12 warns falsely, -Wrestrict, at -O3.)
std::string Indexed(const char* prefix, int i) {
  std::string s(prefix);
  s += std::to_string(i);
  return s;
}

std::string Row(int r) {
  return "row " + std::to_string(r + 1);
}

[[noreturn]] void Fail(const CsvTable& t, const std::string& what) {
  throw std::runtime_error(t.source() + ": " + what);
}

/// A cell that must hold a number.
double Required(const CsvTable& t, int r, const std::string& column) {
  const double v = t.At(r, column);
  if (!std::isfinite(v))
    Fail(t, Row(r) + " column '" + column + "' is " +
                (t.Text(r, column).empty() ? "empty" : "'" + t.Text(r, column) + "'") +
                ": a number is required");
  return v;
}

/// Bounds of values no measurement can have (pose_dataset.hpp); beyond them a cell is garbage.
constexpr double kMaxJoint = 1e3;        // [rad | m]
constexpr double kMaxPosition = 1e6;     // [m]
constexpr double kMaxAngle = 100.0;      // [rad], FIGAROH roll, pitch, yaw
constexpr double kMaxTime = 1e10;        // [s]
constexpr double kMaxPayload = 1e4;      // [kg]
constexpr double kMaxTemperature = 1e3;  // [°C]
constexpr double kAbsoluteZero = -273.15;

std::string Number(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

/// A required cell within [lo, hi].
double Bounded(const CsvTable& t, int r, const std::string& column, double lo, double hi,
               const char* unit) {
  const double v = Required(t, r, column);
  if (v < lo || v > hi)
    Fail(t, Row(r) + " column '" + column + "' is " + t.Text(r, column) + ": outside [" +
                Number(lo) + ", " + Number(hi) + "] " + unit);
  return v;
}

/// An optional cell (NaN when absent) within [lo, hi] when present.
double OptionalBounded(const CsvTable& t, int r, const std::string& column, double lo, double hi,
                       const char* unit) {
  const double v = t.At(r, column);
  if (std::isnan(v)) return v;
  if (!std::isfinite(v) || v < lo || v > hi)
    Fail(t, Row(r) + " column '" + column + "' is " + t.Text(r, column) + ": outside [" +
                Number(lo) + ", " + Number(hi) + "] " + unit);
  return v;
}

void WarnIgnored(const CsvTable& t, const std::vector<std::string>& ignored) {
  if (ignored.empty()) return;
  std::string list;
  for (const auto& c : ignored) list += (list.empty() ? "'" : ", '") + c + "'";
  spdlog::warn("{}: ignoring unknown column(s) {}", t.source(), list);
}

/// Checks and normalises a measured quaternion [w, x, y, z].
Eigen::Vector4d UnitQuaternion(const CsvTable& t, int r, const Eigen::Vector4d& q) {
  const double n = q.norm();
  if (n < 1e-12) Fail(t, Row(r) + " columns 'qw,qx,qy,qz': zero quaternion");
  if (std::abs(n - 1.0) > kUnitTolerance)
    Fail(t,
         Row(r) + " columns 'qw,qx,qy,qz': not a unit quaternion (norm " + std::to_string(n) + ")");
  // Within rounding of unit: kept bit for bit, so a dataset survives save and load unchanged.
  return std::abs(n - 1.0) > 1e-12 ? Eigen::Vector4d(q / n) : q;
}

PoseDataset ParseFigaroh(const CsvTable& t, int expected_num_joints,
                         const std::vector<std::string>& joint_names) {
  PoseDataset out;
  out.comments = t.comments();
  // Marker columns: x1,y1,z1[,phix1,phiy1,phiz1], x2, ...
  std::set<std::string> used;
  std::vector<bool> marker_orientation;
  for (int k = 1; t.Has(Indexed("x", k)); ++k) {
    const std::string s = std::to_string(k);
    for (const char* c : {"x", "y", "z"}) {
      if (!t.Has(c + s)) Fail(t, "missing column '" + std::string(c) + s + "'");
      used.insert(c + s);
    }
    int phi = 0;
    for (const char* c : {"phix", "phiy", "phiz"}) phi += t.Has(c + s) ? 1 : 0;
    if (phi != 0 && phi != 3)
      Fail(t, "columns 'phix" + s + ",phiy" + s + ",phiz" + s + "' come together: some missing");
    for (const char* c : {"phix", "phiy", "phiz"})
      if (phi) used.insert(c + s);
    marker_orientation.push_back(phi == 3);
  }
  std::vector<std::string> joints;
  if (!joint_names.empty()) {
    for (const auto& n : joint_names) {
      if (!t.Has(n)) Fail(t, "missing column '" + n + "' (joint)");
      joints.push_back(n);
      used.insert(n);
    }
    for (const auto& c : t.header())
      if (!used.count(c)) out.ignored_columns.push_back(c);
    WarnIgnored(t, out.ignored_columns);
  } else {
    for (const auto& c : t.header())
      if (!used.count(c)) joints.push_back(c);
  }
  if (joints.empty()) Fail(t, "no joint columns besides the marker columns");
  if (expected_num_joints > 0 && static_cast<int>(joints.size()) != expected_num_joints)
    Fail(t, "has " + std::to_string(joints.size()) + " joint columns, expected " +
                std::to_string(expected_num_joints));
  out.num_joints = static_cast<int>(joints.size());
  out.joint_names = joints;
  out.has_orientation = true;
  for (int r = 0; r < t.rows(); ++r) {
    Eigen::VectorXd q(out.num_joints);
    for (int j = 0; j < out.num_joints; ++j)
      q(j) = Bounded(t, r, joints[j], -kMaxJoint, kMaxJoint, "rad or m");
    for (size_t m = 0; m < marker_orientation.size(); ++m) {
      const std::string s = std::to_string(m + 1);
      PoseSample p;
      p.q = q;
      p.row = r + 1;
      p.marker = static_cast<int>(m);
      for (int i = 0; i < 3; ++i)
        p.p_WM_W(i) = Bounded(t, r, std::string(1, "xyz"[i]) + s, -kMaxPosition, kMaxPosition, "m");
      if (marker_orientation[m]) {
        const double roll = Bounded(t, r, "phix" + s, -kMaxAngle, kMaxAngle, "rad"),
                     pitch = Bounded(t, r, "phiy" + s, -kMaxAngle, kMaxAngle, "rad"),
                     yaw = Bounded(t, r, "phiz" + s, -kMaxAngle, kMaxAngle, "rad");
        p.has_orientation = true;
        p.q_EI_wxyz = geometry::MatrixToQuat(geometry::FromRpy(roll, pitch, yaw));
      }
      out.has_orientation = out.has_orientation && p.has_orientation;
      out.samples.push_back(p);
    }
  }
  if (out.samples.empty()) out.has_orientation = false;
  return out;
}

PoseDataset ParseRcal(const CsvTable& t, int expected_num_joints) {
  PoseDataset out;
  out.comments = t.comments();
  std::set<std::string> known{"x", "y", "z", "marker", "temperature", "payload", "time", "set"};
  int n = 0;
  while (t.Has(Indexed("q", n + 1))) ++n;
  if (expected_num_joints > 0 && n < expected_num_joints)
    Fail(t, "missing column 'q" + std::to_string(n + 1) + "' (expected joints q1..q" +
                std::to_string(expected_num_joints) + ")");
  if (expected_num_joints > 0 && n > expected_num_joints)
    Fail(t, "has joint columns q1..q" + std::to_string(n) + ", expected q1..q" +
                std::to_string(expected_num_joints));
  if (n == 0) Fail(t, "missing column 'q1' (joint positions q1..qN)");
  out.num_joints = n;
  std::vector<std::string> qcols, dqcols;
  for (int j = 1; j <= n; ++j) {
    qcols.push_back(Indexed("q", j));
    dqcols.push_back(Indexed("dq", j));
  }
  known.insert(qcols.begin(), qcols.end());
  for (const char* c : {"x", "y", "z"})
    if (!t.Has(c)) Fail(t, "missing column '" + std::string(c) + "' (measured marker position)");
  const std::vector<std::string> quat{"qw", "qx", "qy", "qz"};
  std::string quat_missing;
  int quat_count = 0;
  for (const auto& c : quat) {
    if (t.Has(c)) {
      ++quat_count;
    } else {
      quat_missing += (quat_missing.empty() ? "'" : ", '") + c + "'";
    }
  }
  if (quat_count != 0 && quat_count != 4)
    Fail(t, "columns 'qw,qx,qy,qz' come together: missing column " + quat_missing);
  const bool quat_cols = quat_count == 4;
  if (quat_cols) known.insert(quat.begin(), quat.end());
  int dq_count = 0;
  for (const auto& c : dqcols) dq_count += t.Has(c) ? 1 : 0;
  if (dq_count != 0)
    for (const auto& c : dqcols)
      if (!t.Has(c)) Fail(t, "missing column '" + c + "' (dq1..dqN come together)");
  if (dq_count != 0) known.insert(dqcols.begin(), dqcols.end());
  for (const auto& c : t.header())
    if (!known.count(c)) out.ignored_columns.push_back(c);
  WarnIgnored(t, out.ignored_columns);

  out.has_orientation = quat_cols && t.rows() > 0;
  for (int r = 0; r < t.rows(); ++r) {
    PoseSample p;
    p.row = r + 1;
    p.q.resize(n);
    for (int j = 0; j < n; ++j) p.q(j) = Bounded(t, r, qcols[j], -kMaxJoint, kMaxJoint, "rad or m");
    for (int i = 0; i < 3; ++i)
      p.p_WM_W(i) = Bounded(t, r, std::string(1, "xyz"[i]), -kMaxPosition, kMaxPosition, "m");
    if (quat_cols) {
      Eigen::Vector4d q;
      int present = 0;
      for (int i = 0; i < 4; ++i) {
        q(i) = t.At(r, quat[i]);
        present += std::isfinite(q(i)) ? 1 : 0;
      }
      if (present == 4) {
        p.has_orientation = true;
        p.q_EI_wxyz = UnitQuaternion(t, r, q);
      } else if (present != 0) {
        for (int i = 0; i < 4; ++i)
          if (!std::isfinite(q(i)))
            Fail(t, Row(r) + " column '" + quat[i] +
                        "' is empty or NaN while other quaternion cells are set");
      }
    }
    out.has_orientation = out.has_orientation && p.has_orientation;
    if (t.Has("marker")) {
      const double m = t.At(r, "marker");
      if (!std::isfinite(m) || m != std::round(m) || m < 0 || m > 1e6)
        Fail(t, Row(r) + " column 'marker' must be an integer id from 0 to 1000000, got '" +
                    t.Text(r, "marker") + "'");
      p.marker = static_cast<int>(m);
    }
    if (t.Has("temperature"))
      p.temperature = OptionalBounded(t, r, "temperature", kAbsoluteZero, kMaxTemperature, "°C");
    if (t.Has("payload")) p.payload = OptionalBounded(t, r, "payload", 0.0, kMaxPayload, "kg");
    if (t.Has("time")) p.time = OptionalBounded(t, r, "time", -kMaxTime, kMaxTime, "s");
    if (dq_count != 0) {
      int present = 0;
      for (const auto& c : dqcols) present += std::isfinite(t.At(r, c)) ? 1 : 0;
      if (present == n) {
        p.dq_sign.resize(n);
        for (int j = 0; j < n; ++j) {
          const double s = t.At(r, dqcols[j]);
          if (s != -1.0 && s != 0.0 && s != 1.0)
            Fail(t, Row(r) + " column '" + dqcols[j] + "' must be -1, 0 or 1, got '" +
                        t.Text(r, dqcols[j]) + "'");
          p.dq_sign(j) = static_cast<int>(s);
        }
      } else if (present != 0) {
        for (const auto& c : dqcols)
          if (!std::isfinite(t.At(r, c)))
            Fail(t, Row(r) + " column '" + c + "' is empty while other dq cells are set");
      }
    }
    if (t.Has("set")) {
      const std::string& s = t.Text(r, "set");
      if (s == "cal") {
        p.set = PoseSample::kCal;
      } else if (s == "test") {
        p.set = PoseSample::kTest;
      } else if (s.empty()) {
        p.set = PoseSample::kUnspecified;
      } else {
        Fail(t, Row(r) + " column 'set' must be cal or test (or empty), got '" + s + "'");
      }
    }
    out.samples.push_back(std::move(p));
  }
  return out;
}

std::string Num(double v) {
  if (std::isnan(v)) return "";
  if (v == 0.0) return "0";
  char buf[64];
  const auto [ptr, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  if (ec != std::errc()) throw std::runtime_error("cannot format a number");
  return std::string(buf, ptr);
}

/// "row N" of a sample (its file row), else "pose N" (its place in the dataset, 1 = first).
std::string Where(const PoseSample& p, size_t i) {
  return p.row > 0 ? "row " + std::to_string(p.row) : "pose " + std::to_string(i + 1);
}

bool IsUnknownBase(const kinematics::KinematicModel& model,
                   const kinematics::ElementaryTransform& et) {
  return et.param >= 0 && model.parameters()[et.param].group == "base";
}

bool Wraps(const kinematics::Joint& jt) {
  return jt.type == kinematics::JointType::kRevolute &&
         jt.upper - jt.lower >= 2.0 * std::numbers::pi - 1e-9;
}

/// Whether a reading is beyond what the joint allows: its limits plus the margin, or for a
/// wrapping joint ±PosePlausibility::wrapping_joint_bound_rad.
bool BeyondLimits(const kinematics::Joint& jt, double q, const PosePlausibility& s) {
  if (Wraps(jt)) return std::abs(q) > s.wrapping_joint_bound_rad;
  const double margin = jt.type == kinematics::JointType::kRevolute ? s.joint_limit_margin_rad
                                                                    : s.joint_limit_margin_m;
  return q < jt.lower - margin || q > jt.upper + margin;
}

/// Joints of one kind (revolute or prismatic) read in another unit (degrees, millimetres): the
/// readings of some joint the robot file bounds span more than no arm's joint of that kind does in
/// SI (a revolute joint limited to less than a turn: more than two turns, 4π, which even another
/// arm's file with ±2π joints does not explain; a prismatic joint: more than ten times its travel),
/// or a wrapping joint reads beyond its bound, while every reading of every joint of that kind,
/// times `to_si`, lies within what the joint allows.
bool JointsInUnit(const PoseDataset& data, const kinematics::KinematicModel& model,
                  kinematics::JointType type, double to_si, const PosePlausibility& s) {
  bool far = false;
  for (int j = 0; j < model.num_joints(); ++j) {
    const kinematics::Joint& jt = model.joints()[j];
    if (jt.type != type) continue;
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (const PoseSample& p : data.samples) {
      if (p.q.size() != model.num_joints()) return false;
      if (!std::isfinite(p.q(j)) || BeyondLimits(jt, p.q(j) * to_si, s)) return false;
      lo = std::min(lo, p.q(j));
      hi = std::max(hi, p.q(j));
      far = far || (Wraps(jt) && BeyondLimits(jt, p.q(j), s));
    }
    const double most = type == kinematics::JointType::kRevolute
                            ? 4.0 * std::numbers::pi + 2.0 * s.joint_limit_margin_rad
                            : 10.0 * (jt.upper - jt.lower + 2.0 * s.joint_limit_margin_m);
    far = far || (!Wraps(jt) && hi - lo > most);
  }
  return far;
}

/// What a refusal of joint j adds: the file's likely unit mistake, else how many rows are beyond
/// the limits when more than one is (one can be a corrupted cell; several mean the robot file's
/// limits are not the measured arm's).
std::string JointHint(const PoseDataset& data, const kinematics::KinematicModel& model, int j,
                      const std::string& column, const PosePlausibility& s) {
  const kinematics::Joint& jt = model.joints()[j];
  const bool revolute = jt.type == kinematics::JointType::kRevolute;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const PoseSample& p : data.samples) {
    if (p.q.size() != model.num_joints()) return "";
    lo = std::min(lo, p.q(j));
    hi = std::max(hi, p.q(j));
  }
  if (JointsInUnit(data, model, jt.type, revolute ? std::numbers::pi / 180.0 : 1e-3, s))
    return revolute ? "; column '" + column + "' reads from " + Number(lo) + " to " + Number(hi) +
                          ", and every revolute joint's readings × π/180 lie within its limits: "
                          "joints in degrees? rcal reads radians"
                    : "; column '" + column + "' reads from " + Number(lo) + " to " + Number(hi) +
                          ", and every prismatic joint's readings × 1e-3 lie within its limits: "
                          "joints in millimetres? rcal reads metres";
  size_t rows = 0;
  for (const PoseSample& p : data.samples) {
    bool beyond = false;
    for (int k = 0; k < model.num_joints(); ++k)
      beyond = beyond || BeyondLimits(model.joints()[k], p.q(k), s);
    rows += beyond ? 1 : 0;
  }
  if (rows < 2) return "";
  return "; " + std::to_string(rows) + " of " + std::to_string(data.samples.size()) +
         " poses have a joint beyond the limits of robot '" + model.name() +
         "': is this the robot that was measured?";
}

}  // namespace

double ArmReach(const kinematics::KinematicModel& model, bool include_base) {
  double reach = 0.0;
  for (const auto& et : model.ets(kinematics::Segment::kChain)) {
    if (et.kind != kinematics::ElementaryTransform::Kind::kTranslation) continue;
    if (!include_base && IsUnknownBase(model, et)) continue;
    double v = std::abs(et.nominal);
    if (et.joint >= 0) {
      const kinematics::Joint& j = model.joints()[et.joint];
      v += std::max(std::abs(j.lower), std::abs(j.upper));
    }
    reach += v;
  }
  return reach;
}

void CheckPosesPlausible(const PoseDataset& data, const kinematics::KinematicModel& model,
                         const std::string& source, const PosePlausibility& settings) {
  const auto& joints = model.joints();
  for (size_t i = 0; i < data.samples.size(); ++i) {
    const PoseSample& p = data.samples[i];
    if (p.q.size() != model.num_joints())
      throw std::runtime_error(source + ": " + Where(p, i) + " has " + std::to_string(p.q.size()) +
                               " joints, the robot " + std::to_string(model.num_joints()));
    for (int j = 0; j < model.num_joints(); ++j) {
      const kinematics::Joint& jt = joints[j];
      const std::string column =
          data.joint_names.size() == joints.size() ? data.joint_names[j] : Indexed("q", j + 1);
      const std::string at = source + ": " + Where(p, i) + " column '" + column + "' (joint '" +
                             jt.name + "') is " + Number(p.q(j));
      if (!std::isfinite(p.q(j))) throw std::runtime_error(at + ": not a number");
      const bool revolute = jt.type == kinematics::JointType::kRevolute;
      if (!BeyondLimits(jt, p.q(j), settings)) continue;
      const std::string hint = JointHint(data, model, j, column, settings);
      if (Wraps(jt))
        throw std::runtime_error(at + " rad: beyond ±" + Number(settings.wrapping_joint_bound_rad) +
                                 " rad (PosePlausibility::wrapping_joint_bound_rad)" + hint);
      const double margin =
          revolute ? settings.joint_limit_margin_rad : settings.joint_limit_margin_m;
      throw std::runtime_error(
          at + (revolute ? " rad" : " m") + ": beyond its limits [" + Number(jt.lower) + ", " +
          Number(jt.upper) + "] by more than " + Number(margin) + (revolute ? " rad" : " m") +
          " (PosePlausibility::joint_limit_margin_" + (revolute ? "rad" : "m") + ")" + hint);
    }
  }
  // Positions: against the origin when the base is known, else against the median position.
  bool unknown_base = false;
  for (const auto& et : model.ets(kinematics::Segment::kChain))
    unknown_base =
        unknown_base || (et.kind == kinematics::ElementaryTransform::Kind::kTranslation &&
                         IsUnknownBase(model, et));
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double bound = ArmReach(model, true) + settings.reach_margin_m;
  if (unknown_base && !data.samples.empty()) {
    for (int k = 0; k < 3; ++k) {
      std::vector<double> v;
      for (const auto& p : data.samples)
        if (std::isfinite(p.p_WM_W(k))) v.push_back(p.p_WM_W(k));
      if (v.empty()) continue;
      centre(k) = numeric::UpperMedian(std::move(v));
    }
    bound = (1.0 + std::sqrt(3.0)) * ArmReach(model, false) + settings.reach_margin_m;
  }
  // Positions in millimetres: the bulk of them (half: one corrupted row does not move the
  // median) lies beyond the reach, while × 1e-3 every one lies within it.
  std::string hint;
  {
    std::vector<double> dist;
    bool all_in_mm = true;
    for (const PoseSample& p : data.samples) {
      const double d = (p.p_WM_W - centre).norm();
      dist.push_back(std::isfinite(d) ? d : std::numeric_limits<double>::infinity());
      all_in_mm = all_in_mm && std::isfinite(d) && d * 1e-3 <= bound;
    }
    if (!dist.empty()) {
      const double median = numeric::UpperMedian(std::move(dist));
      const double reach = ArmReach(model, !unknown_base);
      if (median > bound)
        hint = "; half the positions lie " + Number(median) + " m or more from " +
               (unknown_base ? "their median" : "the world origin") + ", " +
               Number(std::round(median / reach)) + "× the arm's reach of " + Number(reach) + " m" +
               (all_in_mm ? ", and × 1e-3 every one lies within it: positions in millimetres? "
                            "rcal reads metres"
                          : ": is this the robot that was measured?");
    }
  }
  for (size_t i = 0; i < data.samples.size(); ++i) {
    const PoseSample& p = data.samples[i];
    const double dist = (p.p_WM_W - centre).norm();
    if (std::isfinite(dist) && dist <= bound) continue;
    int k = 0;
    (p.p_WM_W - centre).cwiseAbs().maxCoeff(&k);
    const std::string marker = data.joint_names.empty() ? "" : std::to_string(p.marker + 1);
    const std::string column = std::string(1, "xyz"[k]) + marker;
    throw std::runtime_error(
        source + ": " + Where(p, i) + " column '" + column + "' is " + Number(p.p_WM_W(k)) +
        " m: the marker is " + Number(dist) + " m from " +
        (unknown_base ? "the median of the measured positions" : "the world origin") +
        ", beyond the arm's reach (" + Number(bound - settings.reach_margin_m) + " m + " +
        Number(settings.reach_margin_m) + " m, PosePlausibility::reach_margin_m)" + hint);
  }
}

PoseDataset ParsePoseDataset(const std::string& text, const std::string& source,
                             int expected_num_joints, const std::vector<std::string>& joint_names) {
  const CsvTable t = CsvTable::Parse(text, source);
  if (t.Has("x1") && !t.Has("x")) return ParseFigaroh(t, expected_num_joints, joint_names);
  return ParseRcal(t, expected_num_joints);
}

PoseDataset LoadPoseDataset(const std::filesystem::path& path, int expected_num_joints,
                            const std::vector<std::string>& joint_names) {
  return ParsePoseDataset(ReadFile(path), path.string(), expected_num_joints, joint_names);
}

PoseDataset LoadFigarohDataset(const std::filesystem::path& path,
                               const std::vector<std::string>& joint_names) {
  const CsvTable t = CsvTable::Load(path);
  if (!t.Has("x1")) Fail(t, "missing column 'x1' (not the FIGAROH layout)");
  return ParseFigaroh(t, -1, joint_names);
}

PoseDataset LoadFigarohUr10(const std::filesystem::path& path) {
  return LoadFigarohDataset(path, {"shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                                   "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"});
}

std::string PoseDatasetText(const PoseDataset& data) {
  const int n = data.num_joints > 0    ? data.num_joints
                : data.samples.empty() ? 0
                                       : static_cast<int>(data.samples[0].q.size());
  if (n <= 0) throw std::invalid_argument("pose dataset: no joints");
  bool orientation = false, marker = false, temperature = false, payload = false, time = false,
       dq = false, set = false;
  for (size_t i = 0; i < data.samples.size(); ++i) {
    const PoseSample& p = data.samples[i];
    if (p.q.size() != n)
      throw std::invalid_argument("pose dataset: sample " + std::to_string(i) + " has " +
                                  std::to_string(p.q.size()) + " joints, expected " +
                                  std::to_string(n));
    if (p.dq_sign.size() != 0 && p.dq_sign.size() != n)
      throw std::invalid_argument("pose dataset: sample " + std::to_string(i) + " has " +
                                  std::to_string(p.dq_sign.size()) + " dq signs, expected " +
                                  std::to_string(n));
    orientation |= p.has_orientation;
    marker |= p.marker != 0;
    temperature |= !std::isnan(p.temperature);
    payload |= !std::isnan(p.payload);
    time |= !std::isnan(p.time);
    dq |= p.dq_sign.size() != 0;
    set |= p.set != PoseSample::kUnspecified;
  }
  std::ostringstream o;
  for (const auto& c : data.comments) o << '#' << c << '\n';
  std::vector<std::string> header;
  for (int j = 1; j <= n; ++j) header.push_back(Indexed("q", j));
  for (const char* c : {"x", "y", "z"}) header.push_back(c);
  if (orientation)
    for (const char* c : {"qw", "qx", "qy", "qz"}) header.push_back(c);
  if (marker) header.push_back("marker");
  if (temperature) header.push_back("temperature");
  if (payload) header.push_back("payload");
  if (time) header.push_back("time");
  if (dq)
    for (int j = 1; j <= n; ++j) header.push_back(Indexed("dq", j));
  if (set) header.push_back("set");
  for (size_t i = 0; i < header.size(); ++i) o << (i ? "," : "") << header[i];
  o << '\n';
  for (const PoseSample& p : data.samples) {
    std::vector<std::string> cells;
    for (int j = 0; j < n; ++j) cells.push_back(Num(p.q(j)));
    for (int i = 0; i < 3; ++i) cells.push_back(Num(p.p_WM_W(i)));
    if (orientation)
      for (int i = 0; i < 4; ++i) cells.push_back(p.has_orientation ? Num(p.q_EI_wxyz(i)) : "");
    if (marker) cells.push_back(std::to_string(p.marker));
    if (temperature) cells.push_back(Num(p.temperature));
    if (payload) cells.push_back(Num(p.payload));
    if (time) cells.push_back(Num(p.time));
    if (dq)
      for (int j = 0; j < n; ++j)
        cells.push_back(p.dq_sign.size() ? std::to_string(p.dq_sign(j)) : "");
    if (set)
      cells.push_back(p.set == PoseSample::kCal ? "cal" : p.set == PoseSample::kTest ? "test" : "");
    for (size_t i = 0; i < cells.size(); ++i) o << (i ? "," : "") << cells[i];
    o << '\n';
  }
  return o.str();
}

void SavePoseDataset(const std::filesystem::path& path, const PoseDataset& data) {
  AtomicWriteFile(path, PoseDatasetText(data));
}

}  // namespace rcal::io
