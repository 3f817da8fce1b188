// ROS 2 standard messages <-> rcal's domain types (see include/rcal/dds/ros2_convert.hpp).
#include "rcal/dds/ros2_convert.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

#include "rcal/dds/convert_detail.hpp"

namespace rcal::dds {
using namespace detail;

namespace {

constexpr uint32_t kMaxJoints = 4096;  // a JointState longer than this is not an arm's

// A driver's stamp: ROS time is never negative (rclcpp refuses it), so a negative second is a
// broken driver, not a time before 1970.
std::optional<int64_t> Stamp(const std_msgs_msg_dds__Header_& h, const std::string& topic,
                             std::string* error) {
  if (h.stamp.sec < 0)
    return Fail(error,
                topic + ".header.stamp.sec: " + std::to_string(h.stamp.sec) + " is negative"),
           std::nullopt;
  return UtimeFromStamp(h.stamp, topic + ".header.stamp", error);
}

Eigen::Vector3d Vec(const geometry_msgs_msg_dds__Vector3_& v) {
  return {v.x, v.y, v.z};
}

void SetVec(geometry_msgs_msg_dds__Vector3_& to, const Eigen::Vector3d& v) {
  to.x = v.x();
  to.y = v.y();
  to.z = v.z();
}

void SetQuat(geometry_msgs_msg_dds__Quaternion_& to, const Eigen::Quaterniond& q) {
  to.x = q.x();
  to.y = q.y();
  to.z = q.z();
  to.w = q.w();
}

// A unit quaternion (x, y, z, w fields) within `tolerance`, named `field` on failure.
bool CheckUnit(const geometry_msgs_msg_dds__Quaternion_& q, const std::string& field,
               double tolerance, std::string* error) {
  for (double v : {q.x, q.y, q.z, q.w})
    if (!std::isfinite(v)) return Fail(error, field + ": not finite");
  const double n = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  if (std::abs(n - 1.0) > tolerance)
    return Fail(error, field + ": norm " + std::to_string(n) + " is not 1");
  return true;
}

std::optional<transport::PositionSample> Position(const geometry_msgs_msg_dds__Point_& p,
                                                  int64_t utime, int32_t marker_id,
                                                  const Eigen::Matrix3d& covariance,
                                                  const transport::SensorRanges& ranges,
                                                  const std::string& field, std::string* error) {
  position_sample_t msg{};
  msg.utime = utime;
  msg.marker_id = marker_id;
  msg.p[0] = p.x;
  msg.p[1] = p.y;
  msg.p[2] = p.z;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) msg.covariance[3 * r + c] = covariance(r, c);
  std::string why;
  auto s = transport::PositionFromMessage(msg, &why, ranges);
  if (!s) Fail(error, field + ": " + why);
  return s;
}

}  // namespace

// ---- input ------------------------------------------------------------------------------------

JointNameMap::JointNameMap(std::vector<std::string> names) : names_(std::move(names)) {
  for (size_t i = 0; i < names_.size(); ++i) {
    if (names_[i].empty())
      throw std::invalid_argument("joint " + std::to_string(i + 1) + ": empty name");
    if (!index_.emplace(names_[i], static_cast<int>(i)).second)
      throw std::invalid_argument("joint name '" + names_[i] + "' repeated");
  }
}

int JointNameMap::Index(const std::string& name) const {
  const auto it = index_.find(name);
  return it == index_.end() ? -1 : it->second;
}

std::optional<joint_state_t> FromRos(const JointState& m, const JointNameMap& map,
                                     const std::string& topic, std::string* error) {
  const uint32_t n = m.name._length;
  if (n > kMaxJoints)
    return Fail(error, topic + ".name: " + std::to_string(n) + " entries (at most " +
                           std::to_string(kMaxJoints) + ")"),
           std::nullopt;
  if (m.position._length != n)
    return Fail(error, topic + ".position: " + std::to_string(m.position._length) +
                           " entries, name has " + std::to_string(n)),
           std::nullopt;
  // velocity: one per name or none (REP: empty when the driver has none).
  const bool has_velocity = m.velocity._length == n && n > 0;
  if (m.velocity._length != 0 && !has_velocity)
    return Fail(error, topic + ".velocity: " + std::to_string(m.velocity._length) +
                           " entries, name has " + std::to_string(n)),
           std::nullopt;
  const auto utime = Stamp(m.header, topic, error);
  if (!utime) return std::nullopt;
  const auto nj = map.names().size();
  std::vector<int> row(nj, -1);
  for (uint32_t i = 0; i < n; ++i) {
    const std::string name = Str(m.name._buffer[i]);
    const int j = map.Index(name);
    if (j < 0) continue;  // a joint of something else (gripper, track): not the arm's
    if (row[j] >= 0)
      return Fail(error, Indexed((topic + ".name").c_str(), i) + ": '" + name + "' repeated"),
             std::nullopt;
    row[j] = static_cast<int>(i);
  }
  joint_state_t js;
  js.utime = *utime;
  js.num_joints = static_cast<int32_t>(nj);
  js.names = map.names();
  js.q.resize(nj);
  js.dq.assign(nj, 0.0);
  for (size_t j = 0; j < nj; ++j) {
    if (row[j] < 0)
      return Fail(error, topic + ".name: '" + map.names()[j] + "' missing"), std::nullopt;
    const auto i = static_cast<uint32_t>(row[j]);
    auto field = [&](const char* array) {
      return Indexed((topic + "." + array).c_str(), i) + " (" + map.names()[j] + ")";
    };
    if (!CheckValue(
            m.position._buffer[i], [&] { return field("position"); }, error))
      return std::nullopt;
    js.q[j] = m.position._buffer[i];
    if (has_velocity) {
      if (!CheckValue(
              m.velocity._buffer[i], [&] { return field("velocity"); }, error))
        return std::nullopt;
      js.dq[j] = m.velocity._buffer[i];
    }
  }
  return js;
}

std::optional<transport::ImuSample> FromRos(const Imu& m, const transport::SensorRanges& ranges,
                                            const std::string& topic, std::string* error) {
  const auto utime = Stamp(m.header, topic, error);
  if (!utime) return std::nullopt;
  imu_sample_t msg{};
  msg.utime = *utime;
  const Eigen::Vector3d w = Vec(m.angular_velocity), f = Vec(m.linear_acceleration);
  for (int i = 0; i < 3; ++i) {
    msg.gyro[i] = w[i];
    msg.accel[i] = f[i];
  }
  msg.has_mag = false;
  std::string why;
  auto s = transport::ImuFromMessage(msg, &why, ranges);
  if (!s) {
    // Name the ROS field, and the likely unit mistake (°/s, g).
    std::string hint;
    if (w.allFinite() && w.cwiseAbs().maxCoeff() > ranges.gyro) hint = " (degrees per second?)";
    if (f.allFinite() && f.norm() > 0.5 && f.norm() < 2.0) hint = " (in g? ROS wants m/s²)";
    Fail(error, topic + ": " + why + hint);
  } else if (f.norm() > 0.5 && f.norm() < 2.0) {
    // At rest or in slow motion a specific force of about 1 is a driver publishing g, not m/s².
    Fail(error, topic + ".linear_acceleration: |f| = " + std::to_string(f.norm()) +
                    " m/s² (in g? ROS wants m/s²)");
    return std::nullopt;
  }
  return s;
}

std::optional<MagReading> FromRos(const MagneticField& m, const transport::SensorRanges& ranges,
                                  const std::string& topic, std::string* error) {
  const auto utime = Stamp(m.header, topic, error);
  if (!utime) return std::nullopt;
  const Eigen::Vector3d b = Vec(m.magnetic_field);
  for (int i = 0; i < 3; ++i)
    if (!CheckValue(
            b[i], [&] { return Indexed((topic + ".magnetic_field").c_str(), i); }, error))
      return std::nullopt;
  if (b.cwiseAbs().maxCoeff() > ranges.mag)
    return Fail(error, topic + ".magnetic_field: " + std::to_string(b.cwiseAbs().maxCoeff()) +
                           " T is beyond the range " + std::to_string(ranges.mag) +
                           " T (µT or gauss? ROS wants tesla)"),
           std::nullopt;
  return MagReading{*utime, b};
}

std::optional<transport::ArmConditions> FromRos(const Temperature& m, const std::string& topic,
                                                std::string* error) {
  const auto utime = Stamp(m.header, topic, error);
  if (!utime) return std::nullopt;
  if (!CheckValue(
          m.temperature, [&] { return topic + ".temperature"; }, error))
    return std::nullopt;
  if (const std::string why = transport::TemperatureProblem(m.temperature); !why.empty())
    return Fail(error, topic + ".temperature: " + why + " (ROS wants °C)"), std::nullopt;
  if (!CheckValue(
          m.variance, [&] { return topic + ".variance"; }, error))
    return std::nullopt;
  if (m.variance < 0)
    return Fail(error, topic + ".variance: " + std::to_string(m.variance) + " is negative"),
           std::nullopt;
  transport::ArmConditions c;
  c.utime = *utime;
  c.temperature_c = m.temperature;
  return c;
}

std::optional<transport::ArmConditions> FromRos(const InertiaStamped& m, const std::string& topic,
                                                std::string* error) {
  const auto utime = Stamp(m.header, topic, error);
  if (!utime) return std::nullopt;
  const geometry_msgs_msg_dds__Inertia_& i = m.inertia;
  if (!CheckValue(
          i.m, [&] { return topic + ".inertia.m"; }, error))
    return std::nullopt;
  if (const std::string why = transport::PayloadProblem(i.m); !why.empty())
    return Fail(error, topic + ".inertia.m: " + why + " (ROS wants kg)"), std::nullopt;
  const double rest[] = {i.com.x, i.com.y, i.com.z, i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz};
  for (double v : rest)
    if (!std::isfinite(v))
      return Fail(error, topic + ".inertia: the centre of mass or the tensor is not finite"),
             std::nullopt;
  transport::ArmConditions c;
  c.utime = *utime;
  c.payload_kg = i.m;
  return c;
}

std::optional<transport::PositionSample> FromRos(const PoseStamped& m, int32_t marker_id,
                                                 const Eigen::Matrix3d& covariance,
                                                 const transport::SensorRanges& ranges,
                                                 const std::string& topic, std::string* error) {
  const auto utime = Stamp(m.header, topic, error);
  if (!utime) return std::nullopt;
  if (!CheckUnit(m.pose.orientation, topic + ".pose.orientation", 1e-3, error)) return std::nullopt;
  return Position(m.pose.position, *utime, marker_id, covariance, ranges, topic + ".pose.position",
                  error);
}

std::optional<transport::PositionSample> FromRos(const PointStamped& m, int32_t marker_id,
                                                 const Eigen::Matrix3d& covariance,
                                                 const transport::SensorRanges& ranges,
                                                 const std::string& topic, std::string* error) {
  const auto utime = Stamp(m.header, topic, error);
  if (!utime) return std::nullopt;
  return Position(m.point, *utime, marker_id, covariance, ranges, topic + ".point", error);
}

// ---- input, the other way (simulated drivers, tests) ------------------------------------------

std::optional<Sample<JointState>> ToRos(const joint_state_t& js, const std::vector<int>& order,
                                        const char* frame_id, std::string* error) {
  const auto n = static_cast<size_t>(std::max(js.num_joints, 0));
  if (js.q.size() != n || js.names.size() != n || (!js.dq.empty() && js.dq.size() != n))
    return Fail(error, "joint_state: sizes disagree with num_joints"), std::nullopt;
  std::vector<int> rows = order;
  if (rows.empty())
    for (size_t i = 0; i < n; ++i) rows.push_back(static_cast<int>(i));
  if (rows.size() != n) return Fail(error, "joint_state: order is not a permutation"), std::nullopt;
  Sample<JointState> s;
  auto& d = s.get();
  if (!FillHeader(d.header, js.utime, frame_id, "joint_state.utime", error)) return std::nullopt;
  AllocSeq<dds_sequence_string, char*>(d.name, n);
  AllocSeq<dds_sequence_double, double>(d.position, n);
  AllocSeq<dds_sequence_double, double>(d.velocity, js.dq.empty() ? 0 : n);
  AllocSeq<dds_sequence_double, double>(d.effort, 0);
  for (size_t i = 0; i < n; ++i) {
    const int j = rows[i];
    if (j < 0 || static_cast<size_t>(j) >= n)
      return Fail(error, "joint_state: order is not a permutation"), std::nullopt;
    d.name._buffer[i] = Dup(js.names[j]);
    d.position._buffer[i] = js.q[j];
    if (!js.dq.empty()) d.velocity._buffer[i] = js.dq[j];
  }
  return s;
}

std::optional<Sample<Imu>> ToRos(const transport::ImuSample& s, const char* frame_id,
                                 std::string* error) {
  Sample<Imu> out;
  auto& d = out.get();
  if (!FillHeader(d.header, s.utime, frame_id, "imu.utime", error)) return std::nullopt;
  d.orientation.w = 1.0;
  d.orientation_covariance[0] = -1.0;  // REP 145: no orientation estimate
  SetVec(d.angular_velocity, s.gyro_B);
  SetVec(d.linear_acceleration, s.f_B);
  return out;
}

std::optional<Sample<MagneticField>> ToRos(const MagReading& s, const char* frame_id,
                                           std::string* error) {
  Sample<MagneticField> out;
  auto& d = out.get();
  if (!FillHeader(d.header, s.utime, frame_id, "magnetic_field.utime", error)) return std::nullopt;
  SetVec(d.magnetic_field, s.m_S);
  return out;
}

std::optional<Sample<Temperature>> ToRos(const transport::ArmConditions& c, double variance,
                                         const char* frame_id, std::string* error) {
  if (!std::isfinite(c.temperature_c) || !std::isfinite(variance) || variance < 0)
    return Fail(error, "temperature: temperature or variance not finite, or variance negative"),
           std::nullopt;
  Sample<Temperature> out;
  auto& d = out.get();
  if (!FillHeader(d.header, c.utime, frame_id, "temperature.utime", error)) return std::nullopt;
  d.temperature = c.temperature_c;
  d.variance = variance;
  return out;
}

std::optional<Sample<InertiaStamped>> ToRosPayload(const transport::ArmConditions& c,
                                                   const char* frame_id, std::string* error) {
  if (!std::isfinite(c.payload_kg))
    return Fail(error, "payload: payload_kg not finite"), std::nullopt;
  Sample<InertiaStamped> out;
  auto& d = out.get();
  if (!FillHeader(d.header, c.utime, frame_id, "payload.utime", error)) return std::nullopt;
  d.inertia.m = c.payload_kg;
  return out;
}

std::optional<Sample<PoseStamped>> ToRosPose(const transport::PositionSample& s,
                                             const char* frame_id, std::string* error) {
  Sample<PoseStamped> out;
  auto& d = out.get();
  if (!FillHeader(d.header, s.utime, frame_id, "pose.utime", error)) return std::nullopt;
  d.pose.position = {s.p.x(), s.p.y(), s.p.z()};
  d.pose.orientation.w = 1.0;
  return out;
}

std::optional<Sample<PointStamped>> ToRosPoint(const transport::PositionSample& s,
                                               const char* frame_id, std::string* error) {
  Sample<PointStamped> out;
  auto& d = out.get();
  if (!FillHeader(d.header, s.utime, frame_id, "point.utime", error)) return std::nullopt;
  d.point = {s.p.x(), s.p.y(), s.p.z()};
  return out;
}

// ---- output -----------------------------------------------------------------------------------

std::optional<Sample<TFMessage>> ToRos(const std::vector<NamedTransform>& transforms, int64_t utime,
                                       std::string* error) {
  Sample<TFMessage> out;
  auto& d = out.get();
  AllocSeq<dds_sequence_geometry_msgs_msg_dds__TransformStamped_,
           geometry_msgs_msg_dds__TransformStamped_>(d.transforms, transforms.size());
  for (size_t i = 0; i < transforms.size(); ++i) {
    const NamedTransform& t = transforms[i];
    const std::string field = Indexed("tf.transforms", i);
    if (t.parent.empty() || t.child.empty())
      return Fail(error, field + ": frame names must not be empty"), std::nullopt;
    if (!t.p_PC_P.allFinite() || !t.q_PC.coeffs().allFinite() ||
        std::abs(t.q_PC.norm() - 1.0) > 1e-6)
      return Fail(error, field + " (" + t.parent + " -> " + t.child +
                             "): not finite or not a unit quaternion"),
             std::nullopt;
    auto& ts = d.transforms._buffer[i];
    if (!FillHeader(ts.header, utime, t.parent.c_str(), field + ".header.stamp", error))
      return std::nullopt;
    ts.child_frame_id = Dup(t.child);
    SetVec(ts.transform.translation, t.p_PC_P);
    SetQuat(ts.transform.rotation, t.q_PC);
  }
  return out;
}

std::optional<std::vector<NamedTransform>> FromRos(const TFMessage& m, std::string* error) {
  if (m.transforms._length > kMaxJoints)
    return Fail(error, "tf.transforms: too many entries"), std::nullopt;
  std::vector<NamedTransform> out;
  for (uint32_t i = 0; i < m.transforms._length; ++i) {
    const auto& ts = m.transforms._buffer[i];
    const std::string field = Indexed("tf.transforms", i);
    if (!UtimeFromStamp(ts.header.stamp, field + ".header.stamp", error)) return std::nullopt;
    if (!CheckUnit(ts.transform.rotation, field + ".transform.rotation", 1e-6, error))
      return std::nullopt;
    NamedTransform t;
    t.parent = Str(ts.header.frame_id);
    t.child = Str(ts.child_frame_id);
    t.p_PC_P = Vec(ts.transform.translation);
    if (!t.p_PC_P.allFinite())
      return Fail(error, field + ".transform.translation: not finite"), std::nullopt;
    const auto& q = ts.transform.rotation;
    t.q_PC = Eigen::Quaterniond(q.w, q.x, q.y, q.z);
    out.push_back(std::move(t));
  }
  return out;
}

DiagnosticLevel LevelOf(const health_t& now, const health_t* previous) {
  if (!previous)
    return now.rejected > 0 || now.dropped > 0 ? DiagnosticLevel::kWarn : DiagnosticLevel::kOk;
  if (now.filter_resets > previous->filter_resets) return DiagnosticLevel::kError;
  if (now.rejected > previous->rejected || now.dropped > previous->dropped ||
      now.gaps > previous->gaps)
    return DiagnosticLevel::kWarn;
  return DiagnosticLevel::kOk;
}

std::optional<Sample<DiagnosticArray>> ToRos(const std::vector<DiagnosticEntry>& entries,
                                             const std::string& hardware_id, int64_t utime,
                                             std::string* error) {
  Sample<DiagnosticArray> out;
  auto& d = out.get();
  if (!FillHeader(d.header, utime, "", "diagnostics.utime", error)) return std::nullopt;
  AllocSeq<dds_sequence_diagnostic_msgs_msg_dds__DiagnosticStatus_,
           diagnostic_msgs_msg_dds__DiagnosticStatus_>(d.status, entries.size());
  for (size_t i = 0; i < entries.size(); ++i) {
    const health_t& h = entries[i].health;
    auto& st = d.status._buffer[i];
    st.level = static_cast<uint8_t>(entries[i].level);
    st.name = Dup("rcal/" + h.process);
    st.message = Dup(h.last_error.empty() ? std::string("ok") : h.last_error);
    st.hardware_id = Dup(hardware_id);
    std::vector<std::pair<std::string, std::string>> kv = {
        {"pid", std::to_string(h.pid)},
        {"utime", std::to_string(h.utime)},
        {"received", std::to_string(h.received)},
        {"rejected", std::to_string(h.rejected)},
        {"published", std::to_string(h.published)},
        {"duplicates", std::to_string(h.duplicates)},
        {"out_of_horizon", std::to_string(h.out_of_horizon)},
        {"out_of_order", std::to_string(h.out_of_order)},
        {"gaps", std::to_string(h.gaps)},
        {"resyncs", std::to_string(h.resyncs)},
        {"filter_resets", std::to_string(h.filter_resets)},
        {"stale", std::to_string(h.stale)},
        {"dropped", std::to_string(h.dropped)}};
    if (!h.activity.empty()) kv.emplace_back("activity", h.activity);
    kv.insert(kv.end(), entries[i].extra.begin(), entries[i].extra.end());
    AllocSeq<dds_sequence_diagnostic_msgs_msg_dds__KeyValue_, diagnostic_msgs_msg_dds__KeyValue_>(
        st.values, kv.size());
    for (size_t k = 0; k < kv.size(); ++k) {
      st.values._buffer[k].key = Dup(kv[k].first);
      st.values._buffer[k].value = Dup(kv[k].second);
    }
  }
  return out;
}

std::optional<std::vector<DiagnosticReading>> FromRos(const DiagnosticArray& m,
                                                      std::string* error) {
  if (!UtimeFromStamp(m.header.stamp, "diagnostics.header.stamp", error)) return std::nullopt;
  std::vector<DiagnosticReading> out;
  for (uint32_t i = 0; i < m.status._length; ++i) {
    const auto& st = m.status._buffer[i];
    if (st.level > 3)
      return Fail(error, Indexed("diagnostics.status", i) + ".level: " + std::to_string(st.level) +
                             " is not OK, WARN, ERROR or STALE"),
             std::nullopt;
    DiagnosticReading r;
    r.name = Str(st.name);
    r.message = Str(st.message);
    r.hardware_id = Str(st.hardware_id);
    r.level = static_cast<DiagnosticLevel>(st.level);
    for (uint32_t k = 0; k < st.values._length; ++k)
      r.values.emplace_back(Str(st.values._buffer[k].key), Str(st.values._buffer[k].value));
    out.push_back(std::move(r));
  }
  return out;
}

std::optional<Sample<PoseWithCovarianceStamped>> ToRos(const tool_position_estimate_t& position,
                                                       const orientation_estimate_t* orientation,
                                                       const Eigen::Matrix3d* R_WE,
                                                       const char* frame_id, std::string* error) {
  if (!CheckArray(position.p, "tool_position_estimate.p", error) ||
      !CheckArray(position.covariance, "tool_position_estimate.covariance", error))
    return std::nullopt;
  Sample<PoseWithCovarianceStamped> out;
  auto& d = out.get();
  if (!FillHeader(d.header, position.utime, frame_id, "tool_position_estimate.utime", error))
    return std::nullopt;
  d.pose.pose.position = {position.p[0], position.p[1], position.p[2]};
  double* c = d.pose.covariance;  // 6×6 row-major (x, y, z, rot x, rot y, rot z)
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) c[6 * r + k] = position.covariance[6 * r + k];
  if (orientation && R_WE) {
    if (!CheckArray(orientation->q_EI, "orientation_estimate.q_EI", error) ||
        !CheckArray(orientation->covariance, "orientation_estimate.covariance", error))
      return std::nullopt;
    const Eigen::Quaterniond q_EI(orientation->q_EI[0], orientation->q_EI[1], orientation->q_EI[2],
                                  orientation->q_EI[3]);
    if (std::abs(q_EI.norm() - 1.0) > 1e-6)
      return Fail(error, "orientation_estimate.q_EI: not a unit quaternion"), std::nullopt;
    if (!R_WE->allFinite()) return Fail(error, "R_WE: not finite"), std::nullopt;
    // The rotation error is on the left (earth frame): in the world frame C_W = R_WE C_E R_WEᵀ.
    const Eigen::Quaterniond q_WI(*R_WE * q_EI.toRotationMatrix());
    SetQuat(d.pose.pose.orientation, q_WI.normalized());
    const Eigen::Matrix3d C_E =
        Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(orientation->covariance);
    const Eigen::Matrix3d C_W = *R_WE * C_E * R_WE->transpose();
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) c[6 * (r + 3) + (k + 3)] = C_W(r, k);
  } else {
    d.pose.pose.orientation.w = 1.0;
    for (int r = 3; r < 6; ++r) c[6 * r + r] = -1.0;  // unknown (REP 145's convention)
  }
  return out;
}

Sample<RosString> ToRos(const std::string& text) {
  Sample<RosString> out;
  out.get().data = Dup(text);
  return out;
}

}  // namespace rcal::dds
