#include "rcal/transport/adapters.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <vector>

#include "rcal/identification/tracking.hpp"
#include "rcal/transport/lcm_schema.hpp"

namespace rcal::transport {
namespace {

bool AllFinite(const double* v, size_t n) {
  for (size_t i = 0; i < n; ++i)
    if (!std::isfinite(v[i])) return false;
  return true;
}

template <typename T>
std::optional<T> Fail(std::string* error, const std::string& what) {
  if (error) *error = what;
  return std::nullopt;
}

}  // namespace

std::string ModelId(const kinematics::KinematicModel& model) {
  uint64_t h = 1469598103934665603ull;  // FNV-1a 64
  for (const auto& p : model.parameters()) {
    for (unsigned char c : p.name) h = (h ^ c) * 1099511628211ull;
    h = (h ^ 0xffu) * 1099511628211ull;  // separator
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  return model.name() + ":" + hex;
}

pose_measurement_t ToMessage(const kinematics::PoseMeasurement& m, int64_t utime,
                             int32_t pose_index, int32_t marker_id,
                             const kinematics::EffectContext& context) {
  pose_measurement_t msg;
  msg.utime = utime;
  msg.pose_index = pose_index;
  msg.marker_id = marker_id;
  msg.num_joints = static_cast<int32_t>(m.q.size());
  msg.q.assign(m.q.data(), m.q.data() + m.q.size());
  for (int i = 0; i < 3; ++i) msg.p[i] = m.p_WM_W(i);
  msg.has_orientation = m.has_orientation;
  const Eigen::Quaterniond q_EI(m.R_EI);
  msg.q_EI[0] = q_EI.w();
  msg.q_EI[1] = q_EI.x();
  msg.q_EI[2] = q_EI.y();
  msg.q_EI[3] = q_EI.z();
  msg.dimension = static_cast<int8_t>(m.dimension());
  msg.num_covariance = static_cast<int32_t>(m.covariance.size());
  msg.covariance.resize(m.covariance.size());
  for (int r = 0; r < m.covariance.rows(); ++r)
    for (int c = 0; c < m.covariance.cols(); ++c)
      msg.covariance[r * m.covariance.cols() + c] = m.covariance(r, c);
  msg.temperature_c = context.temperature_c;
  msg.payload_kg = context.payload_kg;
  msg.time_s = context.time_s;
  msg.dq_sign.assign(m.q.size(), 0);
  if (context.dq_sign.size() == m.q.size())
    for (int j = 0; j < m.q.size(); ++j)
      msg.dq_sign[j] = static_cast<int8_t>(std::clamp(context.dq_sign(j), -1, 1));
  return msg;
}

namespace {

uint64_t ReadU64(const uint8_t* b) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = (v << 8) | b[i];
  return v;
}
void WriteU64(uint64_t v, uint8_t* b) {
  for (int i = 0; i < 8; ++i) b[i] = static_cast<uint8_t>(v >> (56 - 8 * i));
}
void AppendDouble(double d, std::vector<uint8_t>& out) {
  uint64_t v;
  std::memcpy(&v, &d, sizeof v);
  out.resize(out.size() + 8);
  WriteU64(v, out.data() + out.size() - 8);
}

}  // namespace

std::string DecodePoseMeasurement(const void* data, size_t size, pose_measurement_t* msg) {
  const std::string why = DecodeLcm(data, size, msg);
  // Earlier layouts, upgraded to today's by the fields they lacked:
  //  - before marker_id: fingerprint, utime, pose_index, then the fields from num_joints on,
  //    up to the covariance; marker_id = 0 inserted after pose_index;
  //  - before the context: today's fields up to the covariance; the context appended (temperature
  //    and time NaN, payload 0, dq_sign num_joints zeros).
  constexpr uint64_t kBeforeMarkerId = 0x257fdb5ac9ac24a6ULL;
  constexpr uint64_t kBeforeContext = 0xa1f22502bbcd6577ULL;
  constexpr size_t kMarkerIdAt = 8 + 8 + 4;
  constexpr size_t kNumJointsAt = kMarkerIdAt + 4;
  if (why.empty() || size < kMarkerIdAt) return why;
  const auto* b = static_cast<const uint8_t*>(data);
  const uint64_t hash = ReadU64(b);
  if (hash != kBeforeMarkerId && hash != kBeforeContext) return why;
  std::vector<uint8_t> up(b, b + size);
  if (hash == kBeforeMarkerId) up.insert(up.begin() + kMarkerIdAt, 4, 0);
  if (up.size() < kNumJointsAt + 4) return why;
  int32_t num_joints = 0;
  for (size_t i = 0; i < 4; ++i)
    num_joints =
        static_cast<int32_t>((static_cast<uint32_t>(num_joints) << 8) | up[kNumJointsAt + i]);
  WriteU64(static_cast<uint64_t>(pose_measurement_t::getHash()), up.data());
  // Each joint took 8 bytes of q: a count the bytes cannot hold is refused by the decoder, naming
  // num_joints, before any context is appended for it.
  if (num_joints < 0 || static_cast<size_t>(num_joints) > up.size() / 8)
    return DecodeLcm(up.data(), up.size(), msg);
  AppendDouble(std::numeric_limits<double>::quiet_NaN(), up);  // temperature_c
  AppendDouble(0.0, up);                                       // payload_kg
  AppendDouble(std::numeric_limits<double>::quiet_NaN(), up);  // time_s
  up.insert(up.end(), static_cast<size_t>(num_joints), 0);     // dq_sign
  return DecodeLcm(up.data(), up.size(), msg);
}

std::optional<kinematics::EffectContext> ContextFromMessage(const pose_measurement_t& msg,
                                                            std::string* error) {
  using R = kinematics::EffectContext;
  R c;
  if (!std::isnan(msg.temperature_c) && !(msg.temperature_c >= -60.0 && msg.temperature_c <= 200.0))
    return Fail<R>(error, "pose_measurement.temperature_c: " + std::to_string(msg.temperature_c) +
                              " °C is outside [-60, 200] (NaN: not measured)");
  if (!(msg.payload_kg >= 0.0 && msg.payload_kg <= 1000.0))
    return Fail<R>(error, "pose_measurement.payload_kg: " + std::to_string(msg.payload_kg) +
                              " kg is outside [0, 1000]");
  if (std::isinf(msg.time_s)) return Fail<R>(error, "pose_measurement.time_s: infinite");
  if (msg.num_joints < 0 || msg.dq_sign.size() != static_cast<size_t>(msg.num_joints))
    return Fail<R>(error, "pose_measurement.dq_sign: " + std::to_string(msg.dq_sign.size()) +
                              " values, expected num_joints (" + std::to_string(msg.num_joints) +
                              ")");
  bool any = false;
  for (size_t j = 0; j < msg.dq_sign.size(); ++j) {
    if (msg.dq_sign[j] < -1 || msg.dq_sign[j] > 1)
      return Fail<R>(error, "pose_measurement.dq_sign[" + std::to_string(j) +
                                "]: " + std::to_string(msg.dq_sign[j]) + " is not -1, 0 or +1");
    any = any || msg.dq_sign[j] != 0;
  }
  c.temperature_c = msg.temperature_c;
  c.payload_kg = msg.payload_kg;
  c.time_s = msg.time_s;
  if (any) {
    c.dq_sign.resize(msg.num_joints);
    for (int j = 0; j < msg.num_joints; ++j) c.dq_sign(j) = msg.dq_sign[j];
  }
  return c;
}

int32_t MarkerId(const kinematics::KinematicModel& model, int slot) {
  return model.markers().empty() ? 0 : model.markers().at(static_cast<size_t>(slot)).id;
}

std::optional<kinematics::PoseMeasurement> FromMessage(const pose_measurement_t& msg,
                                                       std::string* error,
                                                       const kinematics::KinematicModel* model) {
  using R = kinematics::PoseMeasurement;
  int slot = msg.marker_id == 0 ? 0 : -1;
  if (model && !model->markers().empty()) slot = model->MarkerSlot(msg.marker_id);
  if (slot < 0) {
    std::string known;
    if (model)
      for (const auto& mk : model->markers())
        known += (known.empty() ? "" : ", ") + std::to_string(mk.id);
    return Fail<R>(
        error,
        "pose_measurement.marker_id: " + std::to_string(msg.marker_id) + " is not a marker of " +
            (model
                 ? model->name() + " (markers: " + (known.empty() ? std::string("0") : known) + ")"
                 : std::string("a single-marker cell (0)")));
  }
  if (msg.num_joints < 1 || static_cast<size_t>(msg.num_joints) != msg.q.size())
    return Fail<R>(error, "pose_measurement.num_joints: " + std::to_string(msg.num_joints) +
                              " does not match q (" + std::to_string(msg.q.size()) + ")");
  if (!AllFinite(msg.q.data(), msg.q.size()))
    return Fail<R>(error, "pose_measurement.q: not finite");
  if (!AllFinite(msg.p, 3)) return Fail<R>(error, "pose_measurement.p: not finite");
  const int dim = msg.has_orientation ? 6 : 3;
  if (msg.dimension != dim)
    return Fail<R>(error, "pose_measurement.dimension: " + std::to_string(msg.dimension) +
                              ", expected " + std::to_string(dim) + " with has_orientation " +
                              (msg.has_orientation ? "true" : "false"));
  if (msg.num_covariance != dim * dim || msg.covariance.size() != static_cast<size_t>(dim * dim))
    return Fail<R>(error, "pose_measurement.covariance: " + std::to_string(msg.covariance.size()) +
                              " values, expected " + std::to_string(dim * dim));
  if (!AllFinite(msg.covariance.data(), msg.covariance.size()))
    return Fail<R>(error, "pose_measurement.covariance: not finite");
  R m;
  m.marker = slot;
  m.q = Eigen::Map<const Eigen::VectorXd>(msg.q.data(), msg.num_joints);
  m.p_WM_W = Eigen::Vector3d(msg.p[0], msg.p[1], msg.p[2]);
  m.has_orientation = msg.has_orientation;
  if (msg.has_orientation) {
    if (!AllFinite(msg.q_EI, 4)) return Fail<R>(error, "pose_measurement.q_EI: not finite");
    Eigen::Quaterniond q(msg.q_EI[0], msg.q_EI[1], msg.q_EI[2], msg.q_EI[3]);
    if (std::abs(q.norm() - 1.0) > 1e-6)
      return Fail<R>(error, "pose_measurement.q_EI: not a unit quaternion (norm " +
                                std::to_string(q.norm()) + ")");
    m.R_EI = q.normalized().toRotationMatrix();
  }
  m.covariance =
      Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          msg.covariance.data(), dim, dim);
  const double scale = m.covariance.cwiseAbs().maxCoeff();
  if ((m.covariance - m.covariance.transpose()).cwiseAbs().maxCoeff() > 1e-12 * scale)
    return Fail<R>(error, "pose_measurement.covariance: not symmetric");
  return m;
}

joint_state_t ToJointState(const kinematics::KinematicModel& model, const Eigen::VectorXd& q,
                           int64_t utime, const Eigen::VectorXd& dq) {
  joint_state_t msg;
  msg.utime = utime;
  msg.num_joints = static_cast<int32_t>(q.size());
  for (int i = 0; i < q.size(); ++i) {
    std::string name = std::to_string(i + 1);
    if (i < model.num_joints()) name = model.joints()[i].name;
    msg.names.push_back(name);
  }
  msg.q.assign(q.data(), q.data() + q.size());
  msg.dq.assign(q.size(), 0.0);
  if (dq.size() == q.size()) msg.dq.assign(dq.data(), dq.data() + dq.size());
  return msg;
}

kinematic_params_t ToKinematicParams(const kinematics::KinematicModel& model,
                                     const Eigen::VectorXd& x, const Eigen::VectorXd& sigma,
                                     const std::vector<int>& identified,
                                     const std::string& robot_id, int64_t utime,
                                     int32_t poses_used) {
  kinematic_params_t msg;
  msg.utime = utime;
  msg.robot_id = robot_id;
  msg.model_id = ModelId(model);
  msg.num_params = model.num_params();
  msg.identified.assign(model.num_params(), false);
  for (int i : identified)
    if (i >= 0 && i < model.num_params()) msg.identified[i] = true;
  for (int i = 0; i < model.num_params(); ++i) {
    msg.names.push_back(model.parameters()[i].name);
    msg.values.push_back(i < x.size() ? x(i) : 0.0);
    msg.sigmas.push_back(i < sigma.size() ? sigma(i) : 0.0);
  }
  msg.poses_used = poses_used;
  msg.num_effect_params = 0;  // a geometric estimate
  return msg;
}

kinematic_params_t ToKinematicParams(const identification::EkfIdentifier& ekf,
                                     const std::string& robot_id, int64_t utime) {
  kinematic_params_t msg = ToKinematicParams(ekf.model(), ekf.x(), ekf.sigma(), ekf.identified(),
                                             robot_id, utime, ekf.accepted());
  const auto names = ekf.extended_model().EffectParameters();
  const Eigen::VectorXd e = ekf.e(), sigma = ekf.sigma_e();
  msg.num_effect_params = static_cast<int32_t>(names.size());
  for (size_t k = 0; k < names.size(); ++k) {
    msg.effect_names.push_back(names[k].name);
    msg.effect_units.push_back(names[k].unit);
    msg.effect_values.push_back(e(static_cast<Eigen::Index>(k)));
    msg.effect_sigmas.push_back(sigma(static_cast<Eigen::Index>(k)));
  }
  return msg;
}

std::string DecodeKinematicParams(const void* data, size_t size, kinematic_params_t* msg) {
  const std::string why = DecodeLcm(data, size, msg);
  // Before the effect parameters: today's fields up to poses_used; num_effect_params = 0
  // appended.
  constexpr uint64_t kBeforeEffects = 0xf474f493449420b3ULL;
  if (why.empty() || size < 8 || ReadU64(static_cast<const uint8_t*>(data)) != kBeforeEffects)
    return why;
  const auto* b = static_cast<const uint8_t*>(data);
  std::vector<uint8_t> up(b, b + size);
  WriteU64(static_cast<uint64_t>(kinematic_params_t::getHash()), up.data());
  up.insert(up.end(), 4, 0);
  return DecodeLcm(up.data(), up.size(), msg);
}

std::optional<Eigen::VectorXd> EffectsFromMessage(const kinematic_params_t& msg,
                                                  const kinematics::ExtendedModel& model,
                                                  std::string* error) {
  using R = Eigen::VectorXd;
  const auto params = model.EffectParameters();
  const size_t n = params.size();
  if (msg.num_effect_params != static_cast<int32_t>(n) || msg.effect_names.size() != n ||
      msg.effect_values.size() != n || msg.effect_sigmas.size() != n)
    return Fail<R>(error,
                   "kinematic_params.num_effect_params: " + std::to_string(msg.num_effect_params) +
                       ", the model has " + std::to_string(n));
  R e(static_cast<Eigen::Index>(n));
  for (size_t k = 0; k < n; ++k) {
    const std::string at = "[" + std::to_string(k) + "]";
    if (msg.effect_names[k] != params[k].name)
      return Fail<R>(error, "kinematic_params.effect_names" + at + ": " + msg.effect_names[k] +
                                ", expected " + params[k].name);
    if (!std::isfinite(msg.effect_values[k]))
      return Fail<R>(error, "kinematic_params.effect_values" + at + ": not finite");
    if (!(std::isfinite(msg.effect_sigmas[k]) && msg.effect_sigmas[k] >= 0))
      return Fail<R>(error, "kinematic_params.effect_sigmas" + at + ": not a finite σ ≥ 0");
    e(static_cast<Eigen::Index>(k)) = msg.effect_values[k];
  }
  return e;
}

std::optional<Eigen::VectorXd> ParamsFromMessage(const kinematic_params_t& msg,
                                                 const kinematics::KinematicModel& model,
                                                 std::string* error) {
  using R = Eigen::VectorXd;
  if (msg.model_id != ModelId(model))
    return Fail<R>(
        error, "kinematic_params.model_id: " + msg.model_id + ", this model is " + ModelId(model));
  const size_t n = static_cast<size_t>(model.num_params());
  if (msg.num_params != model.num_params() || msg.names.size() != n || msg.values.size() != n)
    return Fail<R>(error, "kinematic_params.num_params: " + std::to_string(msg.num_params) +
                              ", model has " + std::to_string(n));
  for (size_t i = 0; i < n; ++i)
    if (msg.names[i] != model.parameters()[i].name)
      return Fail<R>(error, "kinematic_params.names[" + std::to_string(i) + "]: " + msg.names[i] +
                                ", expected " + model.parameters()[i].name);
  if (!AllFinite(msg.values.data(), n))
    return Fail<R>(error, "kinematic_params.values: not finite");
  return Eigen::Map<const Eigen::VectorXd>(msg.values.data(), static_cast<Eigen::Index>(n));
}

calibration_status_t ToCalibrationStatus(const identification::EkfIdentifier& ekf,
                                         const StatusFigures& figures, int64_t utime) {
  calibration_status_t msg{};  // value-initialised: the generated struct leaves counts unset
  msg.utime = utime;
  msg.poses_accepted = ekf.accepted();
  msg.poses_rejected = ekf.rejected();
  msg.last_rejection = ekf.last_rejection();
  msg.condition_number = figures.condition_number;
  msg.rms_position_residual = figures.rms_position_residual;
  msg.rms_orientation_residual = figures.rms_orientation_residual;
  msg.last_nis = figures.last_nis;
  msg.relinearizations = ekf.relinearizations();
  msg.converged = figures.converged;
  msg.tracking_status = identification::TrackingStatusName(ekf.status());
  msg.changes_detected = static_cast<int32_t>(ekf.changes().size());
  if (!ekf.changes().empty()) {
    const identification::DetectedChange& c = ekf.changes().back();
    msg.changed = identification::ChangeNames(ekf.model(), c);
    msg.changed_step.assign(c.step.data(), c.step.data() + c.step.size());
    msg.changed_probability =
        c.probability.empty() ? std::vector<double>(msg.changed.size(), 1.0) : c.probability;
    msg.num_changed = static_cast<int32_t>(msg.changed.size());
  }
  return msg;
}

std::optional<IkQuery> FromMessage(const ik_request_t& msg, int expected_joints,
                                   std::string* error) {
  using R = IkQuery;
  if (msg.num_joints < 1 || static_cast<size_t>(msg.num_joints) != msg.q_seed.size())
    return Fail<R>(error, "ik_request.num_joints: " + std::to_string(msg.num_joints) +
                              " does not match q_seed (" + std::to_string(msg.q_seed.size()) + ")");
  if (expected_joints >= 0 && msg.num_joints != expected_joints)
    return Fail<R>(error, "ik_request.num_joints: " + std::to_string(msg.num_joints) +
                              ", the robot has " + std::to_string(expected_joints));
  if (!AllFinite(msg.q_seed.data(), msg.q_seed.size()))
    return Fail<R>(error, "ik_request.q_seed: not finite");
  if (!AllFinite(msg.p, 3)) return Fail<R>(error, "ik_request.p: not finite");
  IkQuery query;
  query.request_id = msg.request_id;
  query.position_only = msg.position_only;
  query.q_seed = Eigen::Map<const Eigen::VectorXd>(msg.q_seed.data(), msg.num_joints);
  query.T_WT.translation() = Eigen::Vector3d(msg.p[0], msg.p[1], msg.p[2]);
  if (!msg.position_only) {
    if (!AllFinite(msg.q_WT, 4)) return Fail<R>(error, "ik_request.q_WT: not finite");
    Eigen::Quaterniond q(msg.q_WT[0], msg.q_WT[1], msg.q_WT[2], msg.q_WT[3]);
    if (std::abs(q.norm() - 1.0) > 1e-6)
      return Fail<R>(
          error, "ik_request.q_WT: not a unit quaternion (norm " + std::to_string(q.norm()) + ")");
    query.T_WT.linear() = q.normalized().toRotationMatrix();
  }
  return query;
}

ik_request_t ToMessage(const IkQuery& query, int64_t utime) {
  ik_request_t msg;
  msg.utime = utime;
  msg.request_id = query.request_id;
  for (int i = 0; i < 3; ++i) msg.p[i] = query.T_WT.translation()(i);
  const Eigen::Quaterniond q(query.T_WT.rotation());
  msg.q_WT[0] = q.w();
  msg.q_WT[1] = q.x();
  msg.q_WT[2] = q.y();
  msg.q_WT[3] = q.z();
  msg.position_only = query.position_only;
  msg.num_joints = static_cast<int32_t>(query.q_seed.size());
  msg.q_seed.assign(query.q_seed.data(), query.q_seed.data() + query.q_seed.size());
  return msg;
}

ik_command_t ToIkCommand(const ik_request_t& request, const ik::IkResult& calibrated,
                         const ik::IkResult& nominal, double nominal_tool_error,
                         int64_t params_utime) {
  ik_command_t msg;
  msg.utime = request.utime;
  msg.request_id = request.request_id;
  msg.converged = calibrated.converged;
  msg.status = ik::ToString(calibrated.status);
  msg.reason = calibrated.reason;
  msg.num_joints = static_cast<int32_t>(calibrated.q.size());
  msg.q.assign(calibrated.q.data(), calibrated.q.data() + calibrated.q.size());
  msg.q_nominal.assign(msg.num_joints, 0.0);
  for (int i = 0; i < std::min<int>(msg.num_joints, nominal.q.size()); ++i)
    msg.q_nominal[i] = nominal.q(i);
  msg.position_error = calibrated.position_error;
  msg.orientation_error = calibrated.orientation_error;
  msg.nominal_tool_error = nominal_tool_error;
  msg.params_utime = params_utime;
  return msg;
}

// ---- clock offsets ----------------------------------------------------------------------------

std::optional<std::vector<SourceClock>> ClockOffsetsFromMessage(const clock_offset_t& m,
                                                                std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error) *error = "clock_offset." + why;
    return std::nullopt;
  };
  if (m.num_sources < 0 || m.num_sources > 4096)
    return fail("num_sources: " + std::to_string(m.num_sources) + " is not 0 to 4096");
  const auto n = static_cast<size_t>(m.num_sources);
  if (m.source.size() != n || m.state.size() != n || m.offset.size() != n || m.sigma.size() != n ||
      m.resets.size() != n)
    return fail("num_sources: " + std::to_string(n) + ", the arrays disagree");
  std::vector<SourceClock> out(n);
  for (size_t i = 0; i < n; ++i) {
    const std::string at = "source[" + std::to_string(i) + "] (" + m.source[i] + ")";
    if (m.state[i] < 0 || m.state[i] > 3)
      return fail(at + ".state: " + std::to_string(m.state[i]) + " is not 0 to 3");
    if (!std::isfinite(m.offset[i])) return fail(at + ".offset: not finite");
    if (std::isnan(m.sigma[i]) || m.sigma[i] < 0) return fail(at + ".sigma: NaN or negative");
    SourceClock& c = out[i];
    c.source = m.source[i];
    c.fixed = m.state[i] == 3;
    c.resets = m.resets[i];
    c.offset.state = m.state[i] == 2   ? estimation::ClockState::kLocked
                     : m.state[i] == 1 ? estimation::ClockState::kEstimating
                                       : estimation::ClockState::kUnknown;
    c.offset.usable = c.offset.state == estimation::ClockState::kLocked;
    c.offset.offset_s = m.offset[i];
    c.offset.sigma_s = m.sigma[i];
  }
  return out;
}

arm_conditions_t ToArmConditions(const ArmConditions& c) {
  arm_conditions_t m{};
  m.utime = c.utime;
  m.temperature_c = c.temperature_c;
  m.payload_kg = c.payload_kg;
  return m;
}

std::string TemperatureProblem(double t) {
  if (std::isinf(t)) return "infinite";
  if (!std::isnan(t) && (t < -60.0 || t > 200.0))
    return std::to_string(t) + " °C is not -60 to 200" +
           (t >= 213.0 && t <= 473.0 ? " (kelvin?)" : "");
  return "";
}

std::string PayloadProblem(double kg) {
  if (std::isinf(kg)) return "infinite";
  if (!std::isnan(kg) && (kg < 0.0 || kg > 1000.0))
    return std::to_string(kg) + " kg is not 0 to 1000" + (kg > 1000.0 ? " (grams?)" : "");
  return "";
}

std::optional<ArmConditions> ArmConditionsFromMessage(const arm_conditions_t& m,
                                                      std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error) *error = "arm_conditions." + why;
    return std::nullopt;
  };
  if (m.utime < 0) return fail("utime: " + std::to_string(m.utime) + " is negative");
  // NaN says "not measured"; ±inf is no measurement of anything.
  if (const std::string why = TemperatureProblem(m.temperature_c); !why.empty())
    return fail("temperature_c: " + why);
  if (const std::string why = PayloadProblem(m.payload_kg); !why.empty())
    return fail("payload_kg: " + why);
  return ArmConditions{m.utime, m.temperature_c, m.payload_kg};
}

next_poses_t ToNextPoses(const cell::NextPoseAdvice& a, int64_t utime, int32_t poses_used,
                         int num_joints) {
  next_poses_t m{};
  m.utime = utime;
  m.poses_used = poses_used;
  m.num_joints = num_joints;
  m.count = static_cast<int32_t>(a.poses.size());
  m.num_values = m.count * num_joints;
  for (size_t i = 0; i < a.poses.size(); ++i) {
    for (int j = 0; j < num_joints; ++j) m.q.push_back(a.q[i](j));
    m.gain.push_back(a.poses[i].gain_m2);
    m.distance.push_back(a.poses[i].distance);
  }
  m.predicted_rms_position = a.predicted_rms_m;
  return m;
}

std::optional<NextPoses> NextPosesFromMessage(const next_poses_t& m,
                                              const kinematics::KinematicModel& model,
                                              std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error) *error = "next_poses." + why;
    return std::nullopt;
  };
  const int nj = model.num_joints();
  if (m.num_joints != nj)
    return fail("num_joints: " + std::to_string(m.num_joints) + ", the model has " +
                std::to_string(nj));
  if (m.count < 0 || m.count > 1000)
    return fail("count: " + std::to_string(m.count) + " is not 0 to 1000");
  const auto n = static_cast<size_t>(m.count);
  if (m.num_values != m.count * nj || m.q.size() != n * static_cast<size_t>(nj))
    return fail("num_values: " + std::to_string(m.num_values) + " is not count × num_joints (" +
                std::to_string(m.count * nj) + ") or q disagrees");
  if (m.gain.size() != n || m.distance.size() != n)
    return fail("count: " + std::to_string(n) + ", gain or distance disagrees");
  if (!(std::isfinite(m.predicted_rms_position) && m.predicted_rms_position >= 0))
    return fail("predicted_rms_position: not a finite value ≥ 0");
  NextPoses out;
  out.utime = m.utime;
  out.poses_used = m.poses_used;
  out.predicted_rms_m = m.predicted_rms_position;
  for (size_t i = 0; i < n; ++i) {
    const std::string at = "[" + std::to_string(i) + "]";
    if (!(std::isfinite(m.gain[i]) && m.gain[i] >= 0))
      return fail("gain" + at + ": not a finite value ≥ 0");
    if (!(std::isfinite(m.distance[i]) && m.distance[i] >= 0))
      return fail("distance" + at + ": not a finite value ≥ 0");
    Eigen::VectorXd q(nj);
    for (int j = 0; j < nj; ++j) {
      q(j) = m.q[i * nj + j];
      const kinematics::Joint& joint = model.joints()[j];
      if (!std::isfinite(q(j))) return fail("q" + at + " joint " + joint.name + ": not finite");
      if (q(j) < joint.lower || q(j) > joint.upper)
        return fail("q" + at + " joint " + joint.name + ": " + std::to_string(q(j)) +
                    " outside its limits [" + std::to_string(joint.lower) + ", " +
                    std::to_string(joint.upper) + "]");
    }
    out.q.push_back(std::move(q));
    out.gain_m2.push_back(m.gain[i]);
    out.distance.push_back(m.distance[i]);
  }
  return out;
}

model_discrepancy_t ToModelDiscrepancy(const cell::DiscrepancyReport& r, int64_t utime,
                                       int32_t poses_used, bool switched_in,
                                       const std::vector<cell::WithdrawnChange>& withdrawn) {
  model_discrepancy_t m;
  m.utime = utime;
  m.poses_used = poses_used;
  m.window_poses = r.window_poses;
  m.chi2 = r.chi2;
  m.chi2_dof = r.chi2_dof;
  m.chi2_log_p = std::min(r.chi2_log_p, 0.0);
  m.num_suspects = static_cast<int32_t>(r.suspects.size());
  for (const auto& s : r.suspects) {
    m.cause.push_back(s.cause);
    std::string joints;
    for (const auto& j : s.joints) joints += (joints.empty() ? "" : ",") + j;
    m.joints.push_back(joints);
    m.description.push_back(s.description);
    m.z.push_back(s.z);
    m.in_model.push_back(s.in_model ? 1 : 0);
  }
  m.heldout_rms_before = r.heldout_rms_before_m;
  m.heldout_rms_after = r.heldout_rms_after_m;
  m.expected_gain = r.expected_gain;
  m.scheme = r.scheme;
  m.switched_in = switched_in ? 1 : 0;
  m.num_withdrawn = static_cast<int32_t>(withdrawn.size());
  for (const auto& w : withdrawn) {
    std::string names;
    for (const auto& n : w.names) names += (names.empty() ? "" : ",") + n;
    m.withdrawn_onset_pose_index.push_back(w.onset_pose_index);
    m.withdrawn_changed.push_back(names);
    m.withdrawn_evidence.push_back(w.evidence_gain);
  }
  m.num_correlations = static_cast<int32_t>(r.correlations.size());
  for (const auto& c : r.correlations) {
    m.regressor.push_back(c.regressor);
    m.correlation.push_back(c.r);
    m.correlation_log_p.push_back(std::min(c.log_p, 0.0));
  }
  return m;
}

std::optional<ModelDiscrepancy> ModelDiscrepancyFromMessage(const model_discrepancy_t& m,
                                                            std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error) *error = "model_discrepancy." + why;
    return std::nullopt;
  };
  const auto finite_nonneg = [](double v) { return std::isfinite(v) && v >= 0; };
  if (m.window_poses < 0) return fail("window_poses: negative");
  if (m.poses_used < 0) return fail("poses_used: negative");
  if (m.num_suspects < 0 || m.num_suspects > 64)
    return fail("num_suspects: " + std::to_string(m.num_suspects) + " is not 0 to 64");
  const auto n = static_cast<size_t>(m.num_suspects);
  if (m.cause.size() != n || m.joints.size() != n || m.description.size() != n || m.z.size() != n ||
      m.in_model.size() != n)
    return fail("num_suspects: " + std::to_string(n) +
                ", cause, joints, description, z or in_model disagrees");
  if (!finite_nonneg(m.chi2)) return fail("chi2: not a finite value ≥ 0");
  if (!finite_nonneg(m.chi2_dof)) return fail("chi2_dof: not a finite value ≥ 0");
  if (std::isnan(m.chi2_log_p) || m.chi2_log_p > 0) return fail("chi2_log_p: not ≤ 0");
  if (!finite_nonneg(m.heldout_rms_before))
    return fail("heldout_rms_before: not a finite value ≥ 0");
  if (!finite_nonneg(m.heldout_rms_after)) return fail("heldout_rms_after: not a finite value ≥ 0");
  if (!(std::isfinite(m.expected_gain) && m.expected_gain <= 1))
    return fail("expected_gain: not a finite value ≤ 1");
  if (m.switched_in != 0 && m.switched_in != 1) return fail("switched_in: not 0 or 1");
  constexpr size_t kMaxText = 256;
  if (m.scheme.size() > kMaxText) return fail("scheme: longer than 256 bytes");
  ModelDiscrepancy out;
  out.utime = m.utime;
  out.poses_used = m.poses_used;
  out.window_poses = m.window_poses;
  out.chi2 = m.chi2;
  out.chi2_dof = m.chi2_dof;
  out.chi2_log_p = m.chi2_log_p;
  for (size_t i = 0; i < n; ++i) {
    const std::string at = "[" + std::to_string(i) + "]";
    if (!kinematics::ParseEffectCause(m.cause[i]))
      return fail("cause" + at + ": '" + m.cause[i].substr(0, kMaxText) +
                  "' is not joint_compliance, joint_periodic, joint_scale, backlash or thermal");
    if (m.joints[i].size() > kMaxText) return fail("joints" + at + ": longer than 256 bytes");
    if (m.description[i].size() > kMaxText)
      return fail("description" + at + ": longer than 256 bytes");
    if (std::isnan(m.z[i])) return fail("z" + at + ": NaN");
    if (m.in_model[i] != 0 && m.in_model[i] != 1) return fail("in_model" + at + ": not 0 or 1");
    out.suspects.push_back({m.cause[i], m.joints[i], m.description[i], m.z[i], m.in_model[i] == 1});
  }
  if (m.num_correlations < 0 || m.num_correlations > 64)
    return fail("num_correlations: " + std::to_string(m.num_correlations) + " is not 0 to 64");
  const auto nc = static_cast<size_t>(m.num_correlations);
  if (m.regressor.size() != nc || m.correlation.size() != nc || m.correlation_log_p.size() != nc)
    return fail("num_correlations: " + std::to_string(nc) +
                ", regressor, correlation or correlation_log_p disagrees");
  for (size_t i = 0; i < nc; ++i) {
    const std::string at = "[" + std::to_string(i) + "]";
    if (m.regressor[i].size() > kMaxText) return fail("regressor" + at + ": longer than 256 bytes");
    if (!(std::isfinite(m.correlation[i]) && std::abs(m.correlation[i]) <= 1))
      return fail("correlation" + at + ": not a finite value in [-1, 1]");
    if (std::isnan(m.correlation_log_p[i]) || m.correlation_log_p[i] > 0)
      return fail("correlation_log_p" + at + ": not ≤ 0");
    out.correlations.push_back({m.regressor[i], m.correlation[i], m.correlation_log_p[i]});
  }
  out.heldout_rms_before_m = m.heldout_rms_before;
  out.heldout_rms_after_m = m.heldout_rms_after;
  out.expected_gain = m.expected_gain;
  out.scheme = m.scheme;
  out.switched_in = m.switched_in == 1;
  if (m.num_withdrawn < 0 || m.num_withdrawn > 64)
    return fail("num_withdrawn: " + std::to_string(m.num_withdrawn) + " is not 0 to 64");
  const auto nw = static_cast<size_t>(m.num_withdrawn);
  if (m.withdrawn_onset_pose_index.size() != nw || m.withdrawn_changed.size() != nw ||
      m.withdrawn_evidence.size() != nw)
    return fail("num_withdrawn: " + std::to_string(nw) +
                ", withdrawn_onset_pose_index, withdrawn_changed or withdrawn_evidence disagrees");
  for (size_t i = 0; i < nw; ++i) {
    const std::string at = "[" + std::to_string(i) + "]";
    if (m.withdrawn_onset_pose_index[i] < -1)
      return fail("withdrawn_onset_pose_index" + at + ": below −1");
    if (m.withdrawn_changed[i].size() > kMaxText)
      return fail("withdrawn_changed" + at + ": longer than 256 bytes");
    if (!finite_nonneg(m.withdrawn_evidence[i]))
      return fail("withdrawn_evidence" + at + ": not a finite value ≥ 0");
    out.withdrawn.push_back(
        {m.withdrawn_onset_pose_index[i], m.withdrawn_changed[i], m.withdrawn_evidence[i]});
  }
  return out;
}

}  // namespace rcal::transport
