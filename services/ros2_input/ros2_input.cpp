// ros2_input's core (see ros2_input.hpp).
#include "ros2_input.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "rcal/estimation/arm_conditions.hpp"
#include "rcal/estimation/clock_offset.hpp"
#include "rcal/numeric/median.hpp"

namespace rcal::ros2 {

using numeric::UpperMedian;  // of µs stamps; the upper one of an even count

// ---- clocks -----------------------------------------------------------------------------------

// Source indices: 0 the IMU (when the cell has one), then one per position topic. One estimator
// per source (each also takes the joints), so that a restarted driver resets its source alone.
//
// Coarse alignment: a driver's clock may count from anywhere (its boot, another epoch), far beyond
// the estimator's search range (max_clock_offset). The first samples of a source after a (re)start
// give a coarse offset from their arrival: the median over kCoarseSamples of (source stamp − the
// newest joints' stamp received before it), good to the transport's latency. The estimator then
// works on the source's stamps minus that coarse offset and finds the rest within ±max_lag; the
// offset reported is their sum.
class ClockOffsetTracker {
 public:
  static constexpr int kCoarseSamples = 21;

  ClockOffsetTracker(const Ros2InputSettings& s, const kinematics::KinematicModel& model)
      : estimate_(s.estimate_clock_offsets) {
    estimation::ClockOffsetSettings es;
    es.max_lag_s = s.max_clock_offset;
    es.max_sigma_s = s.lock_sigma;
    if (!s.imu_topic.empty()) Add("imu", estimation::ClockSource::kImu, model, es);
    has_imu_ = !s.imu_topic.empty();
    for (const auto& p : s.positions) {
      const int slot = model.markers().empty() ? 0 : model.MarkerSlot(p.marker);
      Add("position/" + std::to_string(p.marker), estimation::ClockSource::kMarker,
          model.ForMarker(std::max(slot, 0)), es);
    }
  }
  int ImuSource() const { return has_imu_ ? 0 : -1; }
  int PositionSource(size_t i) const { return static_cast<int>(i) + (has_imu_ ? 1 : 0); }

  void PushJoints(int64_t utime, const joint_state_t& js) {
    latest_joints_ = utime;
    if (!estimate_) return;
    const Eigen::Map<const Eigen::VectorXd> q(js.q.data(), static_cast<Eigen::Index>(js.q.size()));
    const Eigen::Map<const Eigen::VectorXd> qd(js.dq.data(),
                                               static_cast<Eigen::Index>(js.dq.size()));
    const double t = 1e-6 * static_cast<double>(utime);
    for (Source& s : sources_) {
      if (has_velocity_)
        s.estimator.PushJoints(t, q, qd);
      else
        s.estimator.PushJoints(t, q);
    }
  }
  void SetJointVelocities(bool given) { has_velocity_ = given; }
  void PushGyro(int source, int64_t utime, const Eigen::Vector3d& w) {
    if (Coarse(source, utime)) sources_[source].estimator.PushGyro(Shifted(source, utime), w);
    Update(source);
  }
  void PushMarker(int source, int64_t utime, const Eigen::Vector3d& p) {
    if (Coarse(source, utime)) sources_[source].estimator.PushMarker(Shifted(source, utime), p);
    Update(source);
  }
  /// The source's clock restarted: estimate anew.
  void Reset(int source) {
    if (source < 0) return;
    Source& s = sources_[source];
    ++s.status.resets;
    s.arrivals.clear();
    s.coarse_us.reset();
    s.estimator.Reset();
    if (estimate_) {
      s.status.state = ClockState::kUnknown;
      s.status.offset = 0.0;
      s.status.sigma = std::numeric_limits<double>::infinity();
    }
  }
  void ResetAll() {
    for (size_t i = 0; i < sources_.size(); ++i) Reset(static_cast<int>(i));
  }
  /// Offset [s] to subtract from the source's stamps: the estimate, else the coarse one.
  double Offset(int source) const { return source < 0 ? 0.0 : sources_[source].status.offset; }
  std::vector<ClockStatus> status() const {
    std::vector<ClockStatus> out;
    for (const Source& s : sources_) out.push_back(s.status);
    return out;
  }

 private:
  struct Source {
    estimation::ClockSource kind;
    estimation::ClockOffsetEstimator estimator;
    ClockStatus status;
    std::vector<int64_t> arrivals;  // source stamp − newest joints' stamp [µs]
    std::optional<int64_t> coarse_us;
  };
  void Add(const std::string& name, estimation::ClockSource kind,
           const kinematics::KinematicModel& model, const estimation::ClockOffsetSettings& es) {
    Source s{kind, estimation::ClockOffsetEstimator(model, es), {}, {}, {}};
    s.status.source = name;
    if (!estimate_) {
      s.status.state = ClockState::kFixed;
      s.status.sigma = 0.0;
    }
    sources_.push_back(std::move(s));
  }
  // True once the source's coarse offset is known (collecting it until then).
  bool Coarse(int source, int64_t utime) {
    if (!estimate_ || source < 0 || !latest_joints_) return false;
    Source& s = sources_[source];
    if (s.coarse_us) return true;
    s.arrivals.push_back(utime - *latest_joints_);
    if (static_cast<int>(s.arrivals.size()) < kCoarseSamples) return false;
    s.coarse_us = UpperMedian(s.arrivals);
    // Within the search range, the estimator finds it all: no coarse shift (exact, no latency).
    if (std::abs(1e-6 * static_cast<double>(*s.coarse_us)) < 0.5 * s.estimator.settings().max_lag_s)
      s.coarse_us = 0;
    s.status.offset = 1e-6 * static_cast<double>(*s.coarse_us);
    s.status.state = ClockState::kUnknown;
    return true;
  }
  double Shifted(int source, int64_t utime) const {
    return 1e-6 * static_cast<double>(utime - *sources_[source].coarse_us);
  }
  void Update(int source) {
    if (!estimate_ || source < 0) return;
    Source& s = sources_[source];
    if (!s.coarse_us) return;
    const estimation::ClockOffset& o = s.estimator.offset(s.kind);
    if (o.state == estimation::ClockState::kUnknown) return;
    s.status.offset = 1e-6 * static_cast<double>(*s.coarse_us) + o.offset_s;
    s.status.sigma = o.sigma_s;
    s.status.state =
        o.state == estimation::ClockState::kLocked ? ClockState::kLocked : ClockState::kEstimating;
  }

  bool estimate_;
  bool has_imu_ = false, has_velocity_ = true;
  std::optional<int64_t> latest_joints_;
  std::vector<Source> sources_;
};

// ---- settings ---------------------------------------------------------------------------------

Ros2InputSettings FromCell(const io::BuiltCell& cell) {
  if (!cell.spec.ros2)
    throw std::runtime_error(cell.spec.source +
                             ": no `ros2:` section (the cell's ROS 2 topics, cell_yaml.hpp)");
  const io::Ros2Spec& r = *cell.spec.ros2;
  Ros2InputSettings s;
  s.joint_names = cell.ros2_joint_names;
  s.joint_topic = r.joint_states;
  s.imu_topic = r.imu;
  s.mag_topic = r.magnetic_field;
  s.temperature_topic = r.temperature;
  s.payload_topic = r.payload;
  s.imu_frame = r.imu_frame;
  for (const io::Ros2PositionTopic& p : r.positions)
    s.positions.push_back({p.topic, p.marker, p.pose, p.frame_id});
  s.position_covariance = cell.spec.position.sigma.cwiseAbs2().asDiagonal();
  if (cell.spec.imu) {
    s.ranges.gyro = cell.spec.imu->gyro_range;
    s.ranges.accel = cell.spec.imu->accel_range;
    s.ranges.mag = cell.spec.imu->mag_range;
  }
  s.estimate_clock_offsets = r.estimate_clock_offsets;
  s.max_clock_offset = r.max_clock_offset;
  // A driver restart jumps back by more than the largest offset.
  s.gate.resync_min_jump_back_us =
      std::max<int64_t>(s.gate.resync_min_jump_back_us, std::llround(2e6 * r.max_clock_offset));
  return s;
}

// ---- the core ---------------------------------------------------------------------------------

Ros2Input::Ros2Input(const Ros2InputSettings& settings, const kinematics::KinematicModel& model,
                     transport::Health& health)
    : s_(settings),
      health_(health),
      names_(settings.joint_names),
      joints_{settings.joint_topic, estimation::TimeGate(settings.gate)},
      imu_{settings.imu_topic, estimation::TimeGate(settings.gate)},
      mag_{settings.mag_topic, estimation::TimeGate(settings.gate)},
      temperature_{settings.temperature_topic,
                   estimation::TimeGate(estimation::ArmConditionsGateSettings(
                       settings.gate, settings.temperature_horizon))},
      payload_{settings.payload_topic, estimation::TimeGate(estimation::ArmConditionsGateSettings(
                                           settings.gate, settings.temperature_horizon))},
      clocks_(std::make_unique<ClockOffsetTracker>(settings, model)) {
  if (static_cast<int>(s_.joint_names.size()) != model.num_joints())
    throw std::invalid_argument("ros2_input: " + std::to_string(s_.joint_names.size()) +
                                " joint names for an arm of " + std::to_string(model.num_joints()) +
                                " joints");
  for (const auto& p : s_.positions) positions_.push_back({p.topic, estimation::TimeGate(s_.gate)});
}

Ros2Input::~Ros2Input() = default;

void Ros2Input::Refuse(const std::string& reason) {
  health_.Rejected(reason);
}

bool Ros2Input::Admit(Stream& st, int64_t utime, int clock_source) {
  const estimation::TimeVerdict v = health_.Gate(st.gate, utime, st.name + ".header.stamp");
  if (!estimation::Usable(v)) return false;
  if (v == estimation::TimeVerdict::kResynchronised) {
    // A restarted driver: its clock is a new one.
    st.lags.clear();
    if (&st == &joints_) {
      temperature_.lags.clear();
      payload_.lags.clear();
      // The arm's clock is the pipeline's: what waits in the buffer belongs to the old time base.
      conditions_.utime = std::numeric_limits<int64_t>::min();
      clocks_->ResetAll();
      queue_.clear();
      released_ = newest_ = std::numeric_limits<int64_t>::min();
    } else if (clock_source >= 0) {
      clocks_->Reset(clock_source);
    }
  }
  return true;
}

void Ros2Input::Queue(int64_t utime, sensors::SensorEvent e) {
  if (utime < released_) {
    ++late_;
    health_.Rejected("ros2_input: a sample at " + std::to_string(utime) +
                     " µs (joints' clock) came after " + std::to_string(released_) +
                     " µs had been published (later than the reorder delay)");
    return;
  }
  newest_ = std::max(newest_, utime);
  queue_.emplace(std::pair{utime, sequence_++}, std::move(e));
}

std::vector<sensors::SensorEvent> Ros2Input::Ready(bool flush) {
  std::vector<sensors::SensorEvent> out;
  // newest_ is a real stamp (|utime| < 2.2e15 µs: int32 seconds) once a sample was queued; the
  // conditions alone wait for the samples (or the flush).
  if (queue_.empty() || (!flush && newest_ == std::numeric_limits<int64_t>::min())) return out;
  const int64_t until =
      flush ? std::numeric_limits<int64_t>::max() : newest_ - std::llround(s_.reorder_delay * 1e6);
  while (!queue_.empty() && queue_.begin()->first.first <= until) {
    // (A report taken late leaves behind what left: released_ never goes back.)
    released_ = std::max(released_, queue_.begin()->first.first);
    if (const auto* c = std::get_if<transport::ArmConditions>(&queue_.begin()->second)) {
      // One stream of conditions: each report carries the newest of both, after the last one (a
      // report at its time would be a duplicate downstream). conditions_.utime starts at
      // INT64_MIN, so + 1 cannot overflow and takes any first time.
      conditions_.utime = std::max(c->utime, conditions_.utime + 1);
      if (!std::isnan(c->temperature_c)) conditions_.temperature_c = c->temperature_c;
      if (!std::isnan(c->payload_kg)) conditions_.payload_kg = c->payload_kg;
      out.emplace_back(conditions_);
    } else {
      out.push_back(std::move(queue_.begin()->second));
    }
    queue_.erase(queue_.begin());
  }
  return out;
}

void Ros2Input::OnJointState(const dds::JointState& m) {
  health_.Received();
  std::string error;
  auto js = dds::FromRos(m, names_, s_.joint_topic, &error);
  if (!js) return Refuse(error);
  if (!Admit(joints_, js->utime, -1)) return;
  joints_utime_ = js->utime;
  clocks_->SetJointVelocities(m.velocity._length > 0);
  clocks_->PushJoints(js->utime, *js);
  const int64_t t = js->utime;
  Queue(t, std::move(*js));
}

void Ros2Input::OnImu(const dds::Imu& m) {
  health_.Received();
  const std::string frame = dds::FrameId(m.header);
  if (!s_.imu_frame.empty() && frame != s_.imu_frame)
    return Refuse(s_.imu_topic + ".header.frame_id: '" + frame + "' is not the cell's '" +
                  s_.imu_frame + "'");
  std::string error;
  auto imu = dds::FromRos(m, s_.ranges, s_.imu_topic, &error);
  if (!imu) return Refuse(error);
  const int source = clocks_->ImuSource();
  if (!Admit(imu_, imu->utime, source)) return;
  if (!mags_.empty()) {
    // The reading nearest in time (stamps increase: binary search).
    const auto it =
        std::lower_bound(mags_.begin(), mags_.end(), imu->utime,
                         [](const dds::MagReading& r, int64_t u) { return r.utime < u; });
    const dds::MagReading* best = nullptr;
    if (it != mags_.end()) best = &*it;
    if (it != mags_.begin() &&
        (!best || imu->utime - std::prev(it)->utime < best->utime - imu->utime))
      best = &*std::prev(it);
    if (std::abs(best->utime - imu->utime) <= std::llround(s_.mag_pairing * 1e6)) {
      imu->has_mag = true;
      imu->m_B = best->m_S;
      ++mag_paired_;
    }
  }
  clocks_->PushGyro(source, imu->utime, imu->gyro_B);
  imu->utime -= std::llround(clocks_->Offset(source) * 1e6);
  const int64_t t = imu->utime;
  Queue(t, *imu);
}

void Ros2Input::OnMagneticField(const dds::MagneticField& m) {
  health_.Received();
  std::string error;
  auto b = dds::FromRos(m, s_.ranges, s_.mag_topic, &error);
  if (!b) return Refuse(error);
  // The IMU driver's clock: its restart resets the source through the IMU stream (not twice).
  if (!Admit(mag_, b->utime, -1)) return;
  if (!mags_.empty() && b->utime < mags_.back().utime) mags_.clear();  // re-synchronised
  mags_.push_back(*b);
  // Kept for kMagRetention behind the newest: IMU samples of a backlog still find theirs.
  constexpr int64_t kMagRetention = 5'000'000;  // [µs]
  while (mags_.size() > 1 && mags_.front().utime < b->utime - kMagRetention) mags_.pop_front();
  if (mags_.size() > 8192) mags_.pop_front();
}

void Ros2Input::OnPosition(size_t i, std::optional<transport::PositionSample> p,
                           const std::string& frame_id, const std::string& error) {
  const auto& spec = s_.positions[i];
  if (!p) return Refuse(error);
  if (!spec.frame_id.empty() && frame_id != spec.frame_id)
    return Refuse(spec.topic + ".header.frame_id: '" + frame_id + "' is not the cell's '" +
                  spec.frame_id + "'");
  const int source = clocks_->PositionSource(i);
  if (!Admit(positions_[i], p->utime, source)) return;
  clocks_->PushMarker(source, p->utime, p->p);
  p->utime -= std::llround(clocks_->Offset(source) * 1e6);
  const int64_t t = p->utime;
  Queue(t, *p);
}

void Ros2Input::OnPose(size_t i, const dds::PoseStamped& m) {
  health_.Received();
  if (i >= s_.positions.size() || !s_.positions[i].pose)
    return Refuse("ros2_input: PoseStamped on a topic that is not one");
  std::string error;
  auto p = dds::FromRos(m, s_.positions[i].marker, s_.position_covariance, s_.ranges,
                        s_.positions[i].topic, &error);
  OnPosition(i, std::move(p), dds::FrameId(m.header), error);
}

void Ros2Input::OnPoint(size_t i, const dds::PointStamped& m) {
  health_.Received();
  if (i >= s_.positions.size() || s_.positions[i].pose)
    return Refuse("ros2_input: PointStamped on a topic that is not one");
  std::string error;
  auto p = dds::FromRos(m, s_.positions[i].marker, s_.position_covariance, s_.ranges,
                        s_.positions[i].topic, &error);
  OnPosition(i, std::move(p), dds::FrameId(m.header), error);
}

bool Ros2Input::OnTemperature(const dds::Temperature& m) {
  health_.Received();
  std::string error;
  const bool ok = Conditions(dds::FromRos(m, s_.temperature_topic, &error), temperature_, error);
  temperatures_ += ok;
  return ok;
}

bool Ros2Input::OnPayload(const dds::InertiaStamped& m) {
  health_.Received();
  std::string error;
  const bool ok = Conditions(dds::FromRos(m, s_.payload_topic, &error), payload_, error);
  payloads_ += ok;
  return ok;
}

bool Ros2Input::Conditions(std::optional<transport::ArmConditions> c, Stream& st,
                           const std::string& error) {
  if (!c) return Refuse(error), false;
  if (!Admit(st, c->utime, -1)) return false;
  // Under `none` the gate has put the driver's own stamps in order.
  if (s_.estimate_clock_offsets) {
    if (joints_utime_ == 0)
      return Refuse(st.name +
                    ": a report before the arm's first joints (no arm time to stamp it "
                    "with)"),
             false;
    // Its clock against the joints': the median of its recent arrival lags (file comment).
    st.lags.push_back(joints_utime_ - c->utime);
    if (st.lags.size() > kConditionsLags) st.lags.pop_front();
    c->utime += UpperMedian(std::vector<int64_t>(st.lags.begin(), st.lags.end()));
  }
  if (c->utime < released_) {
    // Later than the reorder delay: not dropped (a payload change lost would stand wrong until
    // the next report), published at its time (or just after the last report), counted: the
    // samples of its time have left, and still_window waits for the conditions of a window.
    ++conditions_late_;
    health_.Error(st.name + ": a report at " + std::to_string(c->utime) +
                  " µs (joints' clock) came after " + std::to_string(released_) +
                  " µs had been published (later than the reorder delay)");
  }
  // Not the newest: the samples alone set the pace of the buffer (a report stamped far ahead
  // would release them all at once and make the next ones late).
  queue_.emplace(std::pair{c->utime, sequence_++}, *c);
  return true;
}

std::vector<ClockStatus> Ros2Input::Clocks() const {
  return clocks_->status();
}

clock_offset_t Ros2Input::ClockMessage(int64_t utime) const {
  clock_offset_t m;
  m.utime = utime;
  for (const ClockStatus& c : clocks_->status()) {
    m.source.push_back(c.source);
    m.state.push_back(static_cast<int8_t>(c.state));
    m.offset.push_back(c.offset);
    m.sigma.push_back(c.sigma);
    m.resets.push_back(c.resets);
  }
  m.num_sources = static_cast<int32_t>(m.source.size());
  return m;
}

}  // namespace rcal::ros2
