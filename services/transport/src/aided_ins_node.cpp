#include "rcal/transport/aided_ins_node.hpp"

#include <algorithm>
#include <stdexcept>

#include "rcal/transport/adapters.hpp"

namespace rcal::transport {
namespace {

void Put3(const Eigen::Vector3d& v, double* out) {
  for (int i = 0; i < 3; ++i) out[i] = v(i);
}

// What became of the positions the INS did not simply take: refused, shocks, re-anchored.
std::array<int64_t, 3> PositionCounters(const estimation::AidedIns& ins) {
  const auto& c = ins.counters();
  return {c.position_rejected, c.shocks_taken, c.reanchored};
}

}  // namespace

orientation_estimate_t ToOrientationEstimate(const estimation::AidedIns& ins, int64_t utime) {
  orientation_estimate_t m;
  m.utime = utime;
  for (int i = 0; i < 4; ++i) m.q_EI[i] = ins.q_EB()(i);
  // The attitude error's block: the first three states (δθ_E, left, earth frame).
  Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(m.covariance) =
      ins.P().topLeftCorner<3, 3>();
  Put3(ins.state().b_g_B, m.gyro_bias);
  return m;
}

tool_position_estimate_t ToToolPositionEstimate(const estimation::AidedIns& ins, int64_t utime) {
  tool_position_estimate_t m;
  m.utime = utime;
  Put3(ins.p_WM_W(), m.p);
  Put3(ins.v_WM_W(), m.v);
  Eigen::Map<Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(m.covariance) = ins.marker_covariance();
  return m;
}

AidedInsNode::AidedInsNode(Transport& t, const estimation::OrientationKfSettings& orientation,
                           const estimation::AidedInsSettings& ins, Options options)
    : MergingNode(t, options.name, options.health_channel),
      o_(std::move(options)),
      okf_(orientation),
      ins_(ins),
      imu_gate_(o_.time),
      position_gate_(o_.time) {
  auto undecodable = [this](const std::string& e) { OnUndecodable(e); };
  t_.Subscribe<imu_sample_t>(
      o_.imu_channel, [this](const imu_sample_t& m) { OnImu(m); }, undecodable);
  t_.Subscribe<position_sample_t>(
      o_.position_channel, [this](const position_sample_t& m) { OnPosition(m); }, undecodable);
  frame_known_ = o_.world_from_earth_known;
  frame_fixed_ = frame_known_ && o_.world_from_earth_covariance.isZero();
  if (frame_known_) {
    if (const auto st = ins_.SetWorldFromEarth(o_.world_from_earth, o_.world_from_earth_covariance);
        !st)
      throw std::invalid_argument("Options::world_from_earth: " + st.error());
  } else if (!o_.model || !o_.model->has_earth()) {
    throw std::invalid_argument(
        "Options::world_from_earth_known: false needs a model with an earth frame (the "
        "identifier's estimate of it)");
  }
  if (o_.model && o_.model->has_earth())
    t_.Subscribe<kinematic_params_t>(
        o_.kinematic_params_channel, [this](const kinematic_params_t& m) { OnKinematicParams(m); },
        undecodable);
  SayActivity();
}

void AidedInsNode::SayActivity() {
  std::string a;
  if (frame_estimates_ > 0)
    a = "R_WE: the identifier's (" + std::to_string(frame_estimates_) +
        (frame_estimates_ == 1 ? " estimate" : " estimates") + "; " +
        std::to_string(positions_awaiting_frame_) + " positions unused before)";
  else if (frame_known_)
    a = frame_fixed_ ? "R_WE: fixed" : "R_WE: the cell's prior, learned";
  else
    a = "R_WE: awaiting the identifier's (" + std::to_string(positions_awaiting_frame_) +
        " positions unused)";
  said_positions_ = position_totals_;
  const auto [gated, shocks, reanchored] = said_positions_;
  if (gated > 0 || shocks > 0 || reanchored > 0)
    a += "; positions: " + std::to_string(gated) + " refused by the χ² gate, " +
         std::to_string(shocks) + " taken as the accelerometer's shock, " +
         std::to_string(reanchored) + " re-anchored";
  if (silences_ > 0) a += "; " + ImuSilencesActivity(silences_, ins_.settings().max_step);
  health_.Activity(std::move(a));
}

void AidedInsNode::StartOver() {
  // The tracker's frame as told stays in the INS.
  okf_.Reset();
  ins_.Reset();
  pending_imu_.clear();
  pending_position_.clear();
  last_stepped_.reset();
  last_imu_ = imu_gate_.last();
  last_position_ = position_gate_.last();
  latest_ = std::max(last_imu_.value_or(0), last_position_.value_or(0));
}

int64_t AidedInsNode::Watermark() const {
  if (!last_imu_) return INT64_MIN;
  int64_t w = last_position_ ? std::min(*last_imu_, *last_position_) : INT64_MIN;
  const bool stopped = !last_position_arrival_us_ ||
                       o_.steady_now_us() - *last_position_arrival_us_ > o_.position_timeout_us;
  if (stopped) w = std::max(w, *last_imu_ - o_.position_wait_us);
  return w;
}

void AidedInsNode::OnImu(const imu_sample_t& msg) {
  health_.Received();
  if (msg.sensor_id != o_.sensor_id) return;
  std::string error;
  const auto s = ImuFromMessage(msg, &error, o_.ranges);
  if (!s) return Reject(error);
  if (!s->has_mag)
    return Reject("imu_sample.has_mag: false (the INS's heading source needs the magnetometer)");
  if (!Admit(imu_gate_, msg.utime, "imu_sample.utime")) return;
  last_imu_ = msg.utime;
  latest_ = std::max(latest_, msg.utime);
  pending_imu_[msg.utime] = *s;
  while (pending_imu_.size() > o_.max_pending) {
    health_.Gap(1);  // a sample the filters never used: counted as missing
    pending_imu_.erase(pending_imu_.begin());
  }
  Flush();
}

void AidedInsNode::OnPosition(const position_sample_t& msg) {
  health_.Received();
  if (msg.marker_id != o_.marker_id) return;
  std::string error;
  const auto s = PositionFromMessage(msg, &error, o_.ranges);
  if (!s) return Reject(error);
  if (!Admit(position_gate_, msg.utime, "position_sample.utime")) return;
  last_position_ = msg.utime;
  last_position_arrival_us_ = o_.steady_now_us();
  latest_ = std::max(latest_, msg.utime);
  if (!frame_known_) {
    ++positions_awaiting_frame_;
    SayActivity();
    health_.Tick(latest_, t_, o_.health_channel);
    return;
  }
  if (last_stepped_ && msg.utime <= *last_stepped_) {
    // Late for the queue: the INS takes it if it is within the step it has reached (it names
    // the step otherwise).
    ApplyPosition(msg.utime, s->p);
  } else {
    pending_position_.emplace(msg.utime, s->p);
    while (pending_position_.size() > o_.max_pending) {
      health_.Gap(1);
      pending_position_.erase(pending_position_.begin());
    }
  }
  Flush();
}

void AidedInsNode::OnKinematicParams(const kinematic_params_t& msg) {
  health_.Received();
  // Another model's estimate (a pose-level identifier on the same bus), or a frame the cell fixes.
  if (msg.model_id != ModelId(*o_.model) || frame_fixed_) {
    ++ignored_params_;
    return;
  }
  std::string error;
  const auto frame = WorldFromEarthFromMessage(msg, *o_.model, &error);
  if (!frame) return Reject(error);
  // Until the INS has started, each estimate is the frame it starts from; then each adds the
  // information it gained since the one before (AidedIns::UpdateWorldFromEarth).
  const bool started = ins_.initialized();
  const auto s = started ? ins_.UpdateWorldFromEarth(frame->R_WE, frame->covariance)
                         : ins_.SetWorldFromEarth(frame->R_WE, frame->covariance);
  if (!s) {
    if (!started) {  // a position already taken, the heading not yet: the next one comes soon
      ++ignored_params_;
      return;
    }
    return Reject("kinematic_params.values: the earth frame's " + s.error());
  }
  frame_known_ = true;
  ++frame_estimates_;
  SayActivity();
}

void AidedInsNode::Failed(const std::string& reason, int64_t resets_before) {
  if (ins_.counters().resets != resets_before) health_.FilterReset(reason);
  Reject(reason);
}

void AidedInsNode::Publish(int64_t utime, bool attitude) {
  if (!ins_.initialized()) return;
  if (attitude) {
    const orientation_estimate_t q = ToOrientationEstimate(ins_, utime);
    // Belt and braces: the INS resets on a non-finite state, so these never refuse.
    if (Eigen::Map<const Eigen::Vector4d>(q.q_EI).allFinite() &&
        Eigen::Map<const Eigen::Matrix<double, 9, 1>>(q.covariance).allFinite() &&
        Eigen::Map<const Eigen::Vector3d>(q.gyro_bias).allFinite() &&
        t_.Publish(o_.orientation_channel, q))
      health_.Published();
  }
  const tool_position_estimate_t p = ToToolPositionEstimate(ins_, utime);
  if (Eigen::Map<const Eigen::Vector3d>(p.p).allFinite() &&
      Eigen::Map<const Eigen::Vector3d>(p.v).allFinite() &&
      Eigen::Map<const Eigen::Matrix<double, 36, 1>>(p.covariance).allFinite() &&
      t_.Publish(o_.tool_position_channel, p))
    health_.Published();
}

void AidedInsNode::StepImu(int64_t utime, const ImuSample& s) {
  const double t = SensorSeconds(utime);
  if (const auto st = okf_.Update(t, s.gyro_B, s.f_B, s.m_B); !st)
    return Reject("imu_sample: " + st.error());
  const int64_t resets = ins_.counters().resets;
  const int64_t reinitialised = ins_.counters().reinitialised;
  if (const auto st =
          estimation::StepAfterOrientationKf(ins_, okf_, t, s.gyro_B, s.f_B, o_.heading_from_kf);
      !st)
    return Failed("imu_sample: " + st.error(), resets);
  if (ins_.counters().reinitialised != reinitialised) {
    ++silences_;
    SayActivity();
  }
  last_stepped_ = utime;
  Publish(utime, true);
  health_.Tick(utime, t_, o_.health_channel);
}

void AidedInsNode::ApplyPosition(int64_t utime, const Eigen::Vector3d& p_WM_W) {
  const int64_t resets = ins_.counters().resets;
  const auto before = PositionCounters(ins_);
  const auto st = ins_.UpdatePosition(SensorSeconds(utime), p_WM_W);
  // Added to the node's totals: what this sample added, or all the INS counts if it reset.
  const auto after = PositionCounters(ins_);
  for (int i = 0; i < 3; ++i) position_totals_[i] += CounterAdded(before[i], after[i]);
  if (!st) return Failed("position_sample: " + st.error(), resets);
  if (position_totals_ != said_positions_) SayActivity();
  // Published at the state's time, the IMU's last sample's.
  Publish(*last_stepped_, false);
}

void AidedInsNode::Flush() {
  const int64_t watermark = Watermark();
  while (!pending_imu_.empty() && pending_imu_.begin()->first <= watermark) {
    const auto [utime, sample] = *pending_imu_.begin();
    pending_imu_.erase(pending_imu_.begin());
    StepImu(utime, sample);
    // Every position the tracker took up to this sample: within the step that ended here, or
    // older (a tracker sample that waited for none: refused by the INS, naming its step).
    while (!pending_position_.empty() && pending_position_.begin()->first <= utime) {
      const auto [pt, p] = *pending_position_.begin();
      pending_position_.erase(pending_position_.begin());
      if (last_stepped_)
        ApplyPosition(pt, p);
      else
        Reject("position_sample.utime: " + std::to_string(pt) +
               " precedes every IMU sample the filters took");
    }
  }
}

}  // namespace rcal::transport
