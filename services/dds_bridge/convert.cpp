// LCM <-> DDS conversion (see include/rcal/dds/convert.hpp).
#include "rcal/dds/convert.hpp"

#include "rcal/dds/convert_detail.hpp"

#include <cmath>
#include <initializer_list>
#include <limits>
#include <type_traits>
#include <utility>

namespace rcal::dds {
using namespace detail;

std::optional<Time> StampFromUtime(int64_t utime, const std::string& field, std::string* error) {
  int64_t sec = utime / kMicrosPerSecond, rest = utime % kMicrosPerSecond;
  if (rest < 0) {  // floor division: nanosec is never negative
    --sec;
    rest += kMicrosPerSecond;
  }
  if (sec < std::numeric_limits<int32_t>::min() || sec > std::numeric_limits<int32_t>::max()) {
    Fail(error, field + ": " + std::to_string(utime) + " µs does not fit a stamp (int32 seconds)");
    return std::nullopt;
  }
  return Time{static_cast<int32_t>(sec), static_cast<uint32_t>(rest * 1000)};
}

std::optional<int64_t> UtimeFromStamp(const Time& stamp, const std::string& field,
                                      std::string* error) {
  if (stamp.nanosec >= 1'000'000'000u) {
    Fail(error, field + ".nanosec: " + std::to_string(stamp.nanosec) + " is not below 1e9");
    return std::nullopt;
  }
  return static_cast<int64_t>(stamp.sec) * kMicrosPerSecond + stamp.nanosec / 1000;
}

bool FillHeader(std_msgs_msg_dds__Header_& h, int64_t utime, const char* frame,
                const std::string& field, std::string* error) {
  auto stamp = StampFromUtime(utime, field, error);
  if (!stamp) return false;
  h.stamp = *stamp;
  h.frame_id = dds_string_dup(frame);
  return true;
}

// ---- kinematic parameters ---------------------------------------------------------------------

namespace {
// True when every array has n entries, else false with the refusal naming the first that has
// not ("kinematic_params.sigmas: 27 entries, num_params is 28").
template <typename Size>
bool SizesAre(Size n, const char* counted_by,
              std::initializer_list<std::pair<const char*, Size>> arrays, std::string* error) {
  for (auto [name, size] : arrays)
    if (size != n)
      return Fail(error, std::string("kinematic_params.") + name + ": " + std::to_string(size) +
                             " entries, " + counted_by + " " + std::to_string(n));
  return true;
}

std::string ParamField(const char* array, size_t i, const std::string& name) {
  std::string s = Indexed((std::string("kinematic_params.") + array).c_str(), i);
  s += " (";
  s += name;
  s += ')';
  return s;
}
}  // namespace

std::optional<Sample<KinematicParams>> ToDds(const kinematic_params_t& msg, std::string* error) {
  if (msg.robot_id.empty()) return Fail(error, "kinematic_params.robot_id: empty"), std::nullopt;
  if (msg.num_params < 0) return Fail(error, "kinematic_params.num_params: negative"), std::nullopt;
  const auto n = static_cast<size_t>(msg.num_params);
  if (!SizesAre<size_t>(n, "num_params is",
                        {{"names", msg.names.size()},
                         {"values", msg.values.size()},
                         {"sigmas", msg.sigmas.size()},
                         {"identified", msg.identified.size()}},
                        error))
    return std::nullopt;
  for (size_t i = 0; i < n; ++i)
    if (!CheckValue(
            msg.values[i], [&] { return ParamField("values", i, msg.names[i]); }, error) ||
        !CheckValue(
            msg.sigmas[i], [&] { return ParamField("sigmas", i, msg.names[i]); }, error))
      return std::nullopt;
  if (msg.num_effect_params < 0)
    return Fail(error, "kinematic_params.num_effect_params: negative"), std::nullopt;
  const auto k = static_cast<size_t>(msg.num_effect_params);
  if (!SizesAre<size_t>(k, "num_effect_params is",
                        {{"effect_names", msg.effect_names.size()},
                         {"effect_units", msg.effect_units.size()},
                         {"effect_values", msg.effect_values.size()},
                         {"effect_sigmas", msg.effect_sigmas.size()}},
                        error))
    return std::nullopt;
  for (size_t i = 0; i < k; ++i)
    if (!CheckValue(
            msg.effect_values[i],
            [&] { return ParamField("effect_values", i, msg.effect_names[i]); }, error) ||
        !CheckValue(
            msg.effect_sigmas[i],
            [&] { return ParamField("effect_sigmas", i, msg.effect_names[i]); }, error))
      return std::nullopt;

  Sample<KinematicParams> s;
  auto& d = s.get();
  if (!FillHeader(d.header, msg.utime, kKinematicParamsFrame, "kinematic_params.utime", error))
    return std::nullopt;
  d.robot_id = Dup(msg.robot_id);
  d.model_id = Dup(msg.model_id);
  AllocSeq<dds_sequence_string, char*>(d.names, n);
  AllocSeq<dds_sequence_double, double>(d.values, n);
  AllocSeq<dds_sequence_double, double>(d.sigmas, n);
  AllocSeq<dds_sequence_bool, bool>(d.identified, n);
  for (size_t i = 0; i < n; ++i) {
    d.names._buffer[i] = Dup(msg.names[i]);
    d.values._buffer[i] = msg.values[i];
    d.sigmas._buffer[i] = msg.sigmas[i];
    d.identified._buffer[i] = msg.identified[i] != 0;
  }
  d.poses_used = msg.poses_used;
  AllocSeq<dds_sequence_string, char*>(d.effect_names, k);
  AllocSeq<dds_sequence_string, char*>(d.effect_units, k);
  AllocSeq<dds_sequence_double, double>(d.effect_values, k);
  AllocSeq<dds_sequence_double, double>(d.effect_sigmas, k);
  for (size_t i = 0; i < k; ++i) {
    d.effect_names._buffer[i] = Dup(msg.effect_names[i]);
    d.effect_units._buffer[i] = Dup(msg.effect_units[i]);
    d.effect_values._buffer[i] = msg.effect_values[i];
    d.effect_sigmas._buffer[i] = msg.effect_sigmas[i];
  }
  return s;
}

std::optional<kinematic_params_t> FromDds(const KinematicParams& d, std::string* error) {
  const std::string robot_id = Str(d.robot_id);
  if (robot_id.empty()) return Fail(error, "kinematic_params.robot_id: empty"), std::nullopt;
  const uint32_t n = d.names._length;
  if (!SizesAre<uint32_t>(n, "names has",
                          {{"values", d.values._length},
                           {"sigmas", d.sigmas._length},
                           {"identified", d.identified._length}},
                          error))
    return std::nullopt;
  if (n > static_cast<uint32_t>(std::numeric_limits<int32_t>::max()))
    return Fail(error, "kinematic_params.names: too many entries"), std::nullopt;
  const auto utime = UtimeFromStamp(d.header.stamp, "kinematic_params.header.stamp", error);
  if (!utime) return std::nullopt;

  kinematic_params_t m;
  m.utime = *utime;
  m.robot_id = robot_id;
  m.model_id = Str(d.model_id);
  m.num_params = static_cast<int32_t>(n);
  for (uint32_t i = 0; i < n; ++i) {
    m.names.push_back(Str(d.names._buffer[i]));
    if (!CheckValue(
            d.values._buffer[i], [&] { return ParamField("values", i, m.names.back()); }, error) ||
        !CheckValue(
            d.sigmas._buffer[i], [&] { return ParamField("sigmas", i, m.names.back()); }, error))
      return std::nullopt;
    m.values.push_back(d.values._buffer[i]);
    m.sigmas.push_back(d.sigmas._buffer[i]);
    m.identified.push_back(d.identified._buffer[i] ? 1 : 0);
  }
  m.poses_used = d.poses_used;
  const uint32_t k = d.effect_names._length;
  if (!SizesAre<uint32_t>(k, "effect_names has",
                          {{"effect_units", d.effect_units._length},
                           {"effect_values", d.effect_values._length},
                           {"effect_sigmas", d.effect_sigmas._length}},
                          error))
    return std::nullopt;
  if (k > static_cast<uint32_t>(std::numeric_limits<int32_t>::max()))
    return Fail(error, "kinematic_params.effect_names: too many entries"), std::nullopt;
  m.num_effect_params = static_cast<int32_t>(k);
  for (uint32_t i = 0; i < k; ++i) {
    m.effect_names.push_back(Str(d.effect_names._buffer[i]));
    m.effect_units.push_back(Str(d.effect_units._buffer[i]));
    if (!CheckValue(
            d.effect_values._buffer[i],
            [&] { return ParamField("effect_values", i, m.effect_names.back()); }, error) ||
        !CheckValue(
            d.effect_sigmas._buffer[i],
            [&] { return ParamField("effect_sigmas", i, m.effect_names.back()); }, error))
      return std::nullopt;
    m.effect_values.push_back(d.effect_values._buffer[i]);
    m.effect_sigmas.push_back(d.effect_sigmas._buffer[i]);
  }
  return m;
}

// ---- calibration status -----------------------------------------------------------------------

namespace {
template <typename Status>
bool CheckStatus(const Status& s, std::string* error) {
  return CheckValue(s.condition_number, "calibration_status.condition_number", error, true) &&
         CheckValue(s.rms_position_residual, "calibration_status.rms_position_residual", error) &&
         CheckValue(s.rms_orientation_residual, "calibration_status.rms_orientation_residual",
                    error) &&
         CheckValue(s.last_nis, "calibration_status.last_nis", error);
}
}  // namespace

std::optional<Sample<CalibrationStatus>> ToDds(const calibration_status_t& msg,
                                               const std::string& robot_id, std::string* error) {
  if (robot_id.empty()) return Fail(error, "calibration_status: empty robot id"), std::nullopt;
  if (!CheckStatus(msg, error)) return std::nullopt;
  Sample<CalibrationStatus> s;
  auto& d = s.get();
  if (!FillHeader(d.header, msg.utime, kCalibrationStatusFrame, "calibration_status.utime", error))
    return std::nullopt;
  d.robot_id = Dup(robot_id);
  d.poses_accepted = msg.poses_accepted;
  d.poses_rejected = msg.poses_rejected;
  d.last_rejection = Dup(msg.last_rejection);
  d.condition_number = msg.condition_number;
  d.rms_position_residual = msg.rms_position_residual;
  d.rms_orientation_residual = msg.rms_orientation_residual;
  d.last_nis = msg.last_nis;
  d.relinearizations = msg.relinearizations;
  d.converged = msg.converged != 0;
  return s;
}

std::optional<calibration_status_t> FromDds(const CalibrationStatus& d, std::string* error) {
  if (Str(d.robot_id).empty())
    return Fail(error, "calibration_status.robot_id: empty"), std::nullopt;
  if (!CheckStatus(d, error)) return std::nullopt;
  const auto utime = UtimeFromStamp(d.header.stamp, "calibration_status.header.stamp", error);
  if (!utime) return std::nullopt;
  calibration_status_t m{};  // value-initialised: fields the DDS type lacks stay 0 / empty
  m.utime = *utime;
  m.poses_accepted = d.poses_accepted;
  m.poses_rejected = d.poses_rejected;
  m.last_rejection = Str(d.last_rejection);
  m.condition_number = d.condition_number;
  m.rms_position_residual = d.rms_position_residual;
  m.rms_orientation_residual = d.rms_orientation_residual;
  m.last_nis = d.last_nis;
  m.relinearizations = d.relinearizations;
  m.converged = d.converged ? 1 : 0;
  return m;
}

// ---- tool pose --------------------------------------------------------------------------------

std::optional<Sample<ToolPose>> ToDds(const tool_position_estimate_t& position,
                                      const orientation_estimate_t* orientation,
                                      const std::string& robot_id, std::string* error) {
  if (robot_id.empty()) return Fail(error, "tool_pose: empty robot id"), std::nullopt;
  if (!CheckArray(position.p, "tool_position_estimate.p", error) ||
      !CheckArray(position.v, "tool_position_estimate.v", error) ||
      !CheckArray(position.covariance, "tool_position_estimate.covariance", error))
    return std::nullopt;
  if (orientation &&
      (!CheckArray(orientation->q_EI, "orientation_estimate.q_EI", error) ||
       !CheckArray(orientation->covariance, "orientation_estimate.covariance", error)))
    return std::nullopt;
  Sample<ToolPose> s;
  auto& d = s.get();
  if (!FillHeader(d.header, position.utime, kToolPoseFrame, "tool_position_estimate.utime", error))
    return std::nullopt;
  d.robot_id = Dup(robot_id);
  Copy(d.position, position.p);
  Copy(d.velocity, position.v);
  Copy(d.covariance, position.covariance);
  d.has_orientation = orientation != nullptr;
  if (orientation) {
    auto stamp = StampFromUtime(orientation->utime, "orientation_estimate.utime", error);
    if (!stamp) return std::nullopt;
    d.orientation_stamp = *stamp;
    Copy(d.orientation, orientation->q_EI);
    Copy(d.orientation_covariance, orientation->covariance);
  }
  return s;
}

std::optional<ToolPoseMessages> FromDds(const ToolPose& d, std::string* error) {
  if (Str(d.robot_id).empty()) return Fail(error, "tool_pose.robot_id: empty"), std::nullopt;
  if (!CheckArray(d.position, "tool_pose.position", error) ||
      !CheckArray(d.velocity, "tool_pose.velocity", error) ||
      !CheckArray(d.covariance, "tool_pose.covariance", error))
    return std::nullopt;
  const auto utime = UtimeFromStamp(d.header.stamp, "tool_pose.header.stamp", error);
  if (!utime) return std::nullopt;
  ToolPoseMessages out;
  out.position.utime = *utime;
  Copy(out.position.p, d.position);
  Copy(out.position.v, d.velocity);
  Copy(out.position.covariance, d.covariance);
  if (d.has_orientation) {
    if (!CheckArray(d.orientation, "tool_pose.orientation", error) ||
        !CheckArray(d.orientation_covariance, "tool_pose.orientation_covariance", error))
      return std::nullopt;
    const auto t = UtimeFromStamp(d.orientation_stamp, "tool_pose.orientation_stamp", error);
    if (!t) return std::nullopt;
    orientation_estimate_t o{};
    o.utime = *t;
    Copy(o.q_EI, d.orientation);
    Copy(o.covariance, d.orientation_covariance);
    for (double& b : o.gyro_bias) b = 0;
    out.orientation = o;
  }
  return out;
}

}  // namespace rcal::dds
