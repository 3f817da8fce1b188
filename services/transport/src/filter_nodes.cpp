#include "rcal/transport/filter_nodes.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "rcal/transport/adapters.hpp"

namespace rcal::transport {
namespace {

template <typename T>
std::optional<T> Fail(std::string* error, const std::string& what) {
  if (error) *error = what;
  return std::nullopt;
}

bool Finite3(const double* v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

Eigen::Vector3d V3(const double* v) {
  return Eigen::Vector3d(v[0], v[1], v[2]);
}

void Put3(const Eigen::Vector3d& v, double* out) {
  for (int i = 0; i < 3; ++i) out[i] = v(i);
}

// Empty, or why v is beyond ±range on some axis.
std::string BeyondRange(const char* field, const double* v, double range, const char* unit) {
  for (int i = 0; i < 3; ++i)
    if (std::abs(v[i]) > range)
      return std::string(field) + ": " + std::to_string(v[i]) + " " + unit +
             " is beyond the sensor range (" + std::to_string(range) + " " + unit + ")";
  return "";
}

bool Finite(const Eigen::MatrixXd& m) {
  return m.allFinite();
}

}  // namespace

// ---- raw sensor samples -----------------------------------------------------------------------

imu_sample_t ToMessage(const ImuSample& s) {
  imu_sample_t m;
  m.utime = s.utime;
  m.sensor_id = s.sensor_id;
  Put3(s.gyro_B, m.gyro);
  Put3(s.f_B, m.accel);
  m.has_mag = s.has_mag;
  Put3(s.has_mag ? s.m_B : Eigen::Vector3d::Zero(), m.mag);
  return m;
}

std::optional<ImuSample> ImuFromMessage(const imu_sample_t& msg, std::string* error,
                                        const SensorRanges& ranges) {
  if (!Finite3(msg.gyro)) return Fail<ImuSample>(error, "imu_sample.gyro: not finite");
  if (!Finite3(msg.accel)) return Fail<ImuSample>(error, "imu_sample.accel: not finite");
  if (msg.has_mag && !Finite3(msg.mag)) return Fail<ImuSample>(error, "imu_sample.mag: not finite");
  for (const std::string& e :
       {BeyondRange("imu_sample.gyro", msg.gyro, ranges.gyro, "rad/s"),
        BeyondRange("imu_sample.accel", msg.accel, ranges.accel, "m/s^2"),
        msg.has_mag ? BeyondRange("imu_sample.mag", msg.mag, ranges.mag, "T") : std::string()})
    if (!e.empty()) return Fail<ImuSample>(error, e);
  ImuSample s;
  s.utime = msg.utime;
  s.sensor_id = msg.sensor_id;
  s.gyro_B = V3(msg.gyro);
  s.f_B = V3(msg.accel);
  s.has_mag = msg.has_mag;
  if (msg.has_mag) s.m_B = V3(msg.mag);
  return s;
}

position_sample_t ToMessage(const PositionSample& s) {
  position_sample_t m;
  m.utime = s.utime;
  m.marker_id = s.marker_id;
  Put3(s.p, m.p);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m.covariance[3 * r + c] = s.covariance(r, c);
  return m;
}

std::optional<PositionSample> PositionFromMessage(const position_sample_t& msg, std::string* error,
                                                  const SensorRanges& ranges) {
  if (!Finite3(msg.p)) return Fail<PositionSample>(error, "position_sample.p: not finite");
  if (V3(msg.p).norm() > ranges.position)
    return Fail<PositionSample>(error, "position_sample.p: " + std::to_string(V3(msg.p).norm()) +
                                           " m from the origin is beyond the sensor range (" +
                                           std::to_string(ranges.position) + " m)");
  PositionSample s;
  s.utime = msg.utime;
  s.marker_id = msg.marker_id;
  s.p = V3(msg.p);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      const double v = msg.covariance[3 * r + c];
      if (!std::isfinite(v))
        return Fail<PositionSample>(error, "position_sample.covariance: not finite");
      s.covariance(r, c) = v;
    }
  for (int i = 0; i < 3; ++i)
    if (s.covariance(i, i) < 0)
      return Fail<PositionSample>(error, "position_sample.covariance: negative variance");
  if ((s.covariance - s.covariance.transpose()).cwiseAbs().maxCoeff() >
      1e-9 * std::max(1e-30, s.covariance.cwiseAbs().maxCoeff()))
    return Fail<PositionSample>(error, "position_sample.covariance: not symmetric");
  return s;
}

// ---- estimates --------------------------------------------------------------------------------

orientation_estimate_t ToOrientationEstimate(const estimation::OrientationKf& kf, int64_t utime) {
  orientation_estimate_t m;
  m.utime = utime;
  for (int i = 0; i < 4; ++i) m.q_EI[i] = kf.q_EB()(i);
  const Eigen::Matrix3d P = kf.attitude_covariance();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m.covariance[3 * r + c] = P(r, c);
  Put3(kf.bias_B(), m.gyro_bias);
  return m;
}

std::optional<Eigen::Matrix3d> RotationFromMessage(const orientation_estimate_t& msg,
                                                   std::string* error) {
  Eigen::Vector4d q(msg.q_EI[0], msg.q_EI[1], msg.q_EI[2], msg.q_EI[3]);
  if (!q.allFinite()) return Fail<Eigen::Matrix3d>(error, "orientation_estimate.q_EI: not finite");
  if (std::abs(q.norm() - 1.0) > 1e-6)
    return Fail<Eigen::Matrix3d>(
        error, "orientation_estimate.q_EI: norm " + std::to_string(q.norm()) + " is not 1");
  q.normalize();
  return Eigen::Quaterniond(q(0), q(1), q(2), q(3)).toRotationMatrix();
}

namespace {
// F: a PositionKf or a PositionKfBank (the same accessors).
template <typename F>
tool_position_estimate_t ToolPositionEstimate(const F& kf, int64_t utime) {
  tool_position_estimate_t m;
  m.utime = utime;
  Put3(kf.p_WM_W(), m.p);
  Put3(kf.v_W(), m.v);
  Eigen::Map<Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(m.covariance) =
      kf.position_velocity_covariance();
  return m;
}
}  // namespace

tool_position_estimate_t ToToolPositionEstimate(const estimation::PositionKf& kf, int64_t utime) {
  return ToolPositionEstimate(kf, utime);
}

tool_position_estimate_t ToToolPositionEstimate(const estimation::PositionKfBank& kf,
                                                int64_t utime) {
  return ToolPositionEstimate(kf, utime);
}

std::optional<WorldFromEarth> WorldFromEarthFromMessage(const kinematic_params_t& msg,
                                                        const kinematics::KinematicModel& model,
                                                        std::string* error) {
  const auto x = ParamsFromMessage(msg, model, error);
  if (!x) return std::nullopt;
  const auto n = static_cast<size_t>(model.num_params());
  if (msg.sigmas.size() != n)
    return Fail<WorldFromEarth>(error,
                                "kinematic_params.sigmas: " + std::to_string(msg.sigmas.size()) +
                                    " values, model has " + std::to_string(n));
  const Eigen::Map<const Eigen::VectorXd> sigma(msg.sigmas.data(), static_cast<Eigen::Index>(n));
  if (!sigma.allFinite() || sigma.minCoeff() < 0.0 || sigma.maxCoeff() > 1e3)
    return Fail<WorldFromEarth>(error,
                                "kinematic_params.sigmas: not finite, negative or beyond 1e3");
  return WorldFromEarth{model.EarthFromWorld(*x).transpose(),
                        model.WorldFromEarthCovariance(*x, sigma)};
}

// ---- orientation node -------------------------------------------------------------------------

std::string ImuSilencesActivity(int64_t silences, double max_step) {
  char seconds[32];
  std::snprintf(seconds, sizeof seconds, "%g", max_step);
  return "attitude started again from the sensors after " + std::to_string(silences) +
         (silences == 1 ? " IMU silence" : " IMU silences") + " longer than " + seconds + " s";
}

OrientationKfNode::OrientationKfNode(Transport& t,
                                     const estimation::OrientationKfSettings& settings,
                                     Options options)
    : t_(t), o_(std::move(options)), kf_(settings), health_(o_.name), gate_(o_.time) {
  t_.Subscribe<imu_sample_t>(
      o_.imu_channel, [this](const imu_sample_t& m) { OnImu(m); },
      [this](const std::string& e) { OnUndecodable(e); });
}

void OrientationKfNode::Announce() {
  health_.Published();
  t_.Publish(o_.health_channel, health_.Message(0));
}

// Heartbeats follow the accepted samples' time only: a refused time never schedules one.
void OrientationKfNode::Beat() {
  if (gate_.last()) health_.Tick(*gate_.last(), t_, o_.health_channel);
}

void OrientationKfNode::Reject(const std::string& reason) {
  health_.Rejected(reason);
  Beat();
}

void OrientationKfNode::OnUndecodable(const std::string& reason) {
  health_.Received();
  Reject(reason);
}

void OrientationKfNode::OnImu(const imu_sample_t& msg) {
  health_.Received();
  if (msg.sensor_id != o_.sensor_id) return;
  std::string error;
  const auto s = ImuFromMessage(msg, &error, o_.ranges);
  if (!s) return Reject(error);
  if (!s->has_mag)
    return Reject("imu_sample.has_mag: false (the orientation KF needs the magnetometer)");
  const auto verdict = health_.Gate(gate_, msg.utime, "imu_sample.utime");
  if (!estimation::Usable(verdict)) return Beat();
  // A source that started over (a restarted driver): so does the filter.
  if (verdict == estimation::TimeVerdict::kResynchronised) kf_.Reset();
  const int64_t resets = kf_.counters().resets;
  const int64_t reinitialised = kf_.counters().reinitialised;
  const auto status = kf_.Update(SensorSeconds(msg.utime), s->gyro_B, s->f_B, s->m_B);
  if (!status) {
    if (kf_.counters().resets != resets) health_.FilterReset("imu_sample: " + status.error());
    return Reject("imu_sample: " + status.error());
  }
  if (kf_.counters().reinitialised != reinitialised)
    health_.Activity(ImuSilencesActivity(++silences_, kf_.settings().max_step));
  const orientation_estimate_t out = ToOrientationEstimate(kf_, msg.utime);
  // Belt and braces: the filter resets on a non-finite state, so this never refuses.
  const bool finite = Eigen::Map<const Eigen::Vector4d>(out.q_EI).allFinite() &&
                      Eigen::Map<const Eigen::Matrix<double, 9, 1>>(out.covariance).allFinite() &&
                      Finite3(out.gyro_bias);
  if (kf_.initialized() && finite && t_.Publish(o_.orientation_channel, out)) health_.Published();
  health_.Tick(msg.utime, t_, o_.health_channel);
}

// ---- position node ----------------------------------------------------------------------------

int64_t SteadyNowUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

int64_t PositionKfNode::PairedUpTo() const {
  if (!last_imu_ || !last_orientation_) return INT64_MIN;
  return std::min(*last_imu_, *last_orientation_);
}

int64_t PositionKfNode::ImuWatermark() const {
  if (!last_imu_) return INT64_MIN;
  const bool stopped =
      !last_orientation_arrival_us_ ||
      o_.steady_now_us() - *last_orientation_arrival_us_ > o_.orientation_timeout_us;
  return stopped ? *last_imu_ - o_.orientation_wait_us : INT64_MIN;
}

MergingNode::MergingNode(Transport& t, const std::string& name, std::string health_channel)
    : t_(t), health_(name), health_channel_(std::move(health_channel)) {}

void MergingNode::Announce() {
  health_.Published();
  t_.Publish(health_channel_, health_.Message(0));
}

void MergingNode::Reject(const std::string& reason) {
  health_.Rejected(reason);
  health_.Tick(latest_, t_, health_channel_);
}

void MergingNode::OnUndecodable(const std::string& reason) {
  health_.Received();
  Reject(reason);
}

bool MergingNode::Admit(estimation::TimeGate& gate, int64_t utime, const char* field) {
  const auto verdict = health_.Gate(gate, utime, field);
  if (!estimation::Usable(verdict)) {
    health_.Tick(latest_, t_, health_channel_);
    return false;
  }
  if (verdict == estimation::TimeVerdict::kResynchronised) StartOver();
  return true;
}

PositionKfNode::PositionKfNode(Transport& t, const estimation::PositionKfBankSettings& settings,
                               Options options)
    : MergingNode(t, options.name, options.health_channel),
      o_(std::move(options)),
      kf_(settings),
      imu_gate_(o_.time),
      orientation_gate_(o_.time),
      position_gate_(o_.time) {
  auto undecodable = [this](const std::string& e) { OnUndecodable(e); };
  t_.Subscribe<imu_sample_t>(
      o_.imu_channel, [this](const imu_sample_t& m) { OnImu(m); }, undecodable);
  t_.Subscribe<orientation_estimate_t>(
      o_.orientation_channel, [this](const orientation_estimate_t& m) { OnOrientation(m); },
      undecodable);
  t_.Subscribe<position_sample_t>(
      o_.position_channel, [this](const position_sample_t& m) { OnPosition(m); }, undecodable);
  if (const auto st = kf_.SetWorldFromEarth(o_.world_from_earth, o_.world_from_earth_covariance);
      !st)
    throw std::invalid_argument("Options::world_from_earth: " + st.error());
  if (o_.model && o_.model->has_earth()) {
    t_.Subscribe<kinematic_params_t>(
        o_.kinematic_params_channel, [this](const kinematic_params_t& m) { OnKinematicParams(m); },
        undecodable);
    frame_activity_ = "R_WE: the cell's, awaiting the identifier's";
  } else {
    frame_activity_ = "R_WE: fixed";
  }
  position_totals_.assign(kf_.filters().size(), {0, 0});
  position_counts_before_ = position_totals_;
  SayActivity();
}

void PositionKfNode::SayActivity() {
  std::string a = frame_activity_;
  bool any = false;
  for (const auto& t : position_totals_) any = any || t[0] > 0 || t[1] > 0;
  if (any) {
    // "; positions (white jerk, accelerometer-driven): 3, 5 refused by the χ² gate; 0, 1
    // re-initialised": the bank's filters in its order.
    std::string models, refused, reinitialised;
    for (size_t i = 0; i < position_totals_.size(); ++i) {
      const char* sep = i == 0 ? "" : ", ";
      models += sep;
      models +=
          kf_.filters()[i].settings().motion_model == estimation::MotionModel::kAccelerometerDriven
              ? "accelerometer-driven"
              : "white jerk";
      refused += sep + std::to_string(position_totals_[i][0]);
      reinitialised += sep + std::to_string(position_totals_[i][1]);
    }
    a += "; positions (" + models + "): " + refused + " refused by the χ² gate; " + reinitialised +
         " re-initialised";
  }
  health_.Activity(std::move(a));
}

void PositionKfNode::OnKinematicParams(const kinematic_params_t& msg) {
  health_.Received();
  // Another model's estimate (a pose-level identifier on the same bus): not this cell's earth.
  if (msg.model_id != ModelId(*o_.model)) {
    ++ignored_params_;
    return;
  }
  std::string error;
  const auto frame = WorldFromEarthFromMessage(msg, *o_.model, &error);
  if (!frame) return Reject(error);
  if (const auto s = kf_.SetWorldFromEarth(frame->R_WE, frame->covariance); !s)
    return Reject("kinematic_params.values: the earth frame's " + s.error());
  ++world_from_earth_updates_;
  // Told in HEALTH: from the first heartbeat saying so, every estimate is in the identifier's
  // frame (a replay or a test scores from there; an operator sees the frame was found).
  frame_activity_ = "R_WE: the identifier's (" + std::to_string(world_from_earth_updates_) +
                    (world_from_earth_updates_ == 1 ? " estimate)" : " estimates)");
  SayActivity();
}

void PositionKfNode::StartOver() {
  kf_.Reset();
  pending_accel_.clear();
  early_orientation_.clear();
  ready_accel_.clear();
  pending_position_.clear();
  last_applied_.reset();
  last_imu_ = imu_gate_.last();
  last_orientation_ = orientation_gate_.last();
  last_position_ = position_gate_.last();
  latest_ =
      std::max({last_imu_.value_or(0), last_orientation_.value_or(0), last_position_.value_or(0)});
}

void PositionKfNode::FilterFailed(const std::string& reason, int64_t resets_before) {
  if (kf_.resets() != resets_before) health_.FilterReset(reason);
  Reject(reason);
}

void PositionKfNode::OnImu(const imu_sample_t& msg) {
  health_.Received();
  if (msg.sensor_id != o_.sensor_id) return;
  std::string error;
  const auto s = ImuFromMessage(msg, &error, o_.ranges);
  if (!s) return Reject(error);
  if (!Admit(imu_gate_, msg.utime, "imu_sample.utime")) return;
  last_imu_ = msg.utime;
  latest_ = std::max(latest_, msg.utime);
  // Its orientation may have come first (two senders: the multicast copy of this sample can reach
  // this socket after orientation_kf has already answered it).
  auto early = early_orientation_.begin();
  while (early != early_orientation_.end() && early->first < msg.utime)
    early = early_orientation_.erase(early);  // their IMU sample never came: nothing to pair
  if (early != early_orientation_.end() && early->first == msg.utime) {
    ready_accel_.emplace(msg.utime, std::make_pair(AccelSample{s->f_B, s->gyro_B}, early->second));
    early_orientation_.erase(early);
  } else {
    pending_accel_[msg.utime] = AccelSample{s->f_B, s->gyro_B};
  }
  while (pending_accel_.size() > o_.max_pending) {
    health_.Gap(1);  // a sample the filter never used: counted as missing
    pending_accel_.erase(pending_accel_.begin());
    ++unpaired_accel_;
  }
  // Without orientations, positions still go in after orientation_wait_us of IMU time.
  Flush(std::max(PairedUpTo(), ImuWatermark()));
}

void PositionKfNode::OnOrientation(const orientation_estimate_t& msg) {
  health_.Received();
  std::string error;
  const auto R = RotationFromMessage(msg, &error);
  if (!R) return Reject(error);
  const Eigen::Vector3d bias_B(msg.gyro_bias[0], msg.gyro_bias[1], msg.gyro_bias[2]);
  if (!bias_B.allFinite()) return Reject("orientation_estimate.gyro_bias: not finite");
  if (!Admit(orientation_gate_, msg.utime, "orientation_estimate.utime")) return;
  last_orientation_ = msg.utime;
  last_orientation_arrival_us_ = o_.steady_now_us();
  latest_ = std::max(latest_, msg.utime);
  // Accelerometer samples before this orientation never got theirs: drop them.
  auto it = pending_accel_.begin();
  while (it != pending_accel_.end() && it->first < msg.utime) {
    // Every loss counted, as missing (gaps): its orientation never came, or came after the
    // filter had moved on (orientation_kf stopped for --orientation-timeout and then came back).
    health_.Gap(1);
    it = pending_accel_.erase(it);
    ++unpaired_accel_;
  }
  if (it != pending_accel_.end() && it->first == msg.utime) {
    ready_accel_.emplace(msg.utime, std::make_pair(it->second, Attitude{*R, bias_B}));
    pending_accel_.erase(it);
  } else if (!last_imu_ || msg.utime > *last_imu_) {
    // Ahead of its IMU sample: kept until the sample comes (OnImu pairs it).
    early_orientation_[msg.utime] = Attitude{*R, bias_B};
    while (early_orientation_.size() > o_.max_pending)
      early_orientation_.erase(early_orientation_.begin());
  }
  Flush(std::max(PairedUpTo(), ImuWatermark()));
}

void PositionKfNode::OnPosition(const position_sample_t& msg) {
  health_.Received();
  if (msg.marker_id != o_.marker_id) return;
  std::string error;
  const auto s = PositionFromMessage(msg, &error, o_.ranges);
  if (!s) return Reject(error);
  if (last_applied_ && msg.utime < *last_applied_ && msg.utime > last_position_.value_or(INT64_MIN))
    return Reject("position_sample.utime: " + std::to_string(msg.utime) +
                  " came after the filter reached " + std::to_string(*last_applied_));
  if (!Admit(position_gate_, msg.utime, "position_sample.utime")) return;
  last_position_ = msg.utime;
  latest_ = std::max(latest_, msg.utime);
  pending_position_.emplace(msg.utime, s->p);
  Flush(std::max(PairedUpTo(), ImuWatermark()));
}

void PositionKfNode::Applied(int64_t utime) {
  last_applied_ = utime;
  const tool_position_estimate_t out = ToToolPositionEstimate(kf_, utime);
  // Belt and braces: the filter resets on a non-finite state, so this never refuses.
  const bool finite = Finite3(out.p) && Finite3(out.v) &&
                      Finite(Eigen::Map<const Eigen::Matrix<double, 36, 1>>(out.covariance));
  if (kf_.initialized() && finite && t_.Publish(o_.tool_position_channel, out)) health_.Published();
  health_.Tick(utime, t_, o_.health_channel);
}

void PositionKfNode::Flush(int64_t watermark) {
  // Merge the two queues in utime order, accelerometer first at equal utime.
  for (;;) {
    const bool has_a = !ready_accel_.empty() && ready_accel_.begin()->first <= watermark;
    const bool has_p = !pending_position_.empty() && pending_position_.begin()->first <= watermark;
    if (!has_a && !has_p) break;
    if (has_a && (!has_p || ready_accel_.begin()->first <= pending_position_.begin()->first)) {
      const auto [utime, sample] = *ready_accel_.begin();
      ready_accel_.erase(ready_accel_.begin());
      if (last_applied_ && utime < *last_applied_) {
        Reject("imu_sample.utime: " + std::to_string(utime) + " came after the filter reached " +
               std::to_string(*last_applied_));
        continue;
      }
      const int64_t resets = kf_.resets();
      const auto& [imu, attitude] = sample;
      // ω_B from the gyro less the orientation filter's bias: the lever arm's rotational terms
      // (nothing when the lever arm is zero and not estimated).
      const auto status = kf_.UpdateAccel(SensorSeconds(utime), imu.f_B, attitude.R_EB,
                                          imu.gyro_B - attitude.bias_B);
      if (!status) {
        FilterFailed("imu_sample: " + status.error(), resets);
        continue;
      }
      Applied(utime);
    } else {
      const auto [utime, p] = *pending_position_.begin();
      pending_position_.erase(pending_position_.begin());
      if (last_applied_ && utime < *last_applied_) {
        Reject("position_sample.utime: " + std::to_string(utime) +
               " came after the filter reached " + std::to_string(*last_applied_));
        continue;
      }
      const int64_t resets = kf_.resets();
      const auto counts = [this](size_t i) {
        const auto& c = kf_.filters()[i].counters();
        return std::array<int64_t, 2>{c.position_rejected, c.reinitialised};
      };
      for (size_t i = 0; i < position_counts_before_.size(); ++i)
        position_counts_before_[i] = counts(i);
      const auto status = kf_.UpdatePosition(SensorSeconds(utime), p);
      // Added to the node's totals: what this sample added to each filter's (CounterAdded).
      bool changed = false;
      for (size_t i = 0; i < position_totals_.size(); ++i) {
        const auto after = counts(i);
        for (int k = 0; k < 2; ++k) {
          const int64_t added = CounterAdded(position_counts_before_[i][k], after[k]);
          position_totals_[i][k] += added;
          changed = changed || added > 0;
        }
      }
      if (changed) SayActivity();
      if (!status) {
        FilterFailed("position_sample: " + status.error(), resets);
        continue;
      }
      Applied(utime);
    }
  }
}

}  // namespace rcal::transport
