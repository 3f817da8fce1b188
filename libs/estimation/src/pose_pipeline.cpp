#include "rcal/estimation/pose_pipeline.hpp"

#include <cmath>
#include <string>

#include "rcal/estimation/fqa.hpp"
#include "rcal/geometry/so3.hpp"

namespace rcal::estimation {

namespace {
bool Finite(const Eigen::VectorXd& v) {
  return v.allFinite();
}
}  // namespace

Eigen::Matrix3d AccelBiasOrientationCovariance(EarthFrame earth, double gravity, double dip,
                                               double sigma_ba) {
  // The FQA levels with f + b: the estimated up turns by the bias's horizontal part, δθ_t =
  // (b_E × u)/g = −[u]× b_E / g. Levelled with that tilt, the field gains an east component
  // −m_v (n̂·δθ_t), which the heading cancels by turning about u by −tan(dip) (n̂·δθ_t) =
  // tan(dip) (ê·b_E)/g (n̂·(b × u) = b·(u × n̂) = −ê·b).
  const Eigen::Vector3d u = UpVector(earth);
  const Eigen::Vector3d n = MagneticNorth(earth);
  const Eigen::Vector3d n_h = (n - n.dot(u) * u).normalized();
  const Eigen::Vector3d e = n_h.cross(u);
  Eigen::Matrix3d A = -geometry::Skew(u) + std::tan(dip) * u * e.transpose();
  A /= gravity;
  return sigma_ba * sigma_ba * A * A.transpose();
}

PosePipeline::PosePipeline(const PosePipelineSettings& settings)
    : settings_(settings),
      ori_(settings.orientation),
      pos_(settings.position),
      detector_(settings.still) {}

void PosePipeline::Reset() {
  ori_.Reset();
  pos_.Reset();
  detector_.Reset();
  window_.Reset();
  counters_ = {};
  ready_.clear();
  has_t_ = false;
  t_last_ = 0.0;
  num_joints_ = -1;
  still_ = open_ = gap_ = false;
  filters_started_ = window_in_start_stop_ = false;
  t_filters_started_ = 0.0;
  q_count_ = 0;
  raw_p_.clear();
  raw_R_.clear();
  t_imu0_.reset();
  carried_.reset();
}

Status PosePipeline::Refuse(const std::string& reason) {
  ++counters_.input_rejected;
  counters_.last_error = reason;
  return Status::Error(reason);
}

Status PosePipeline::CheckTime(double t, const char* stream) {
  if (!std::isfinite(t)) return Refuse(std::string(stream) + ".t: not finite");
  if (has_t_ && t < t_last_)
    return Refuse(std::string(stream) + ".t: " + std::to_string(t) +
                  " s is before the last sample (" + std::to_string(t_last_) +
                  " s): streams must come in sensor-time order");
  return Status::Ok();
}

Status PosePipeline::AddJoints(double t, const Eigen::VectorXd& q) {
  if (Status s = CheckTime(t, "joints"); !s) return s;
  if (q.size() == 0 || !Finite(q)) return Refuse("joints.q: empty or not finite");
  if (num_joints_ >= 0 && q.size() != num_joints_)
    return Refuse("joints.q: " + std::to_string(q.size()) + " joints, expected " +
                  std::to_string(num_joints_));
  const Result<bool> still = detector_.Update(t, q, Eigen::Vector3d::Zero(),
                                              Eigen::Vector3d(0, 0, -settings_.still.gravity));
  if (!still) return Refuse("joints: " + still.error());
  num_joints_ = static_cast<int>(q.size());
  has_t_ = true;
  t_last_ = t;
  ++counters_.joint_samples;
  still_ = *still;

  if (open_ && !still_) CloseWindow();
  if (!open_ && still_ &&
      t >= detector_.still_since() + settings_.still.min_duration + settings_.settle_time) {
    open_ = true;
    gap_ = false;
    t_open_ = t;
    window_in_start_stop_ = filters_started_ && detector_.still_since() <= t_filters_started_;
    t_first_ = t_last_imu_ = t;
    window_.Reset();
    q_sum_ = Eigen::VectorXd::Zero(q.size());
    q_count_ = 0;
    raw_p_.clear();
    raw_R_.clear();
  }
  if (open_) {
    q_sum_ += q;
    ++q_count_;
  }
  return Status::Ok();
}

Status PosePipeline::AddImu(double t, const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B,
                            const Eigen::Vector3d& m_B) {
  if (Status s = CheckTime(t, "imu"); !s) return s;
  if (!gyro_B.allFinite()) return Refuse("imu.gyro: not finite");
  if (!f_B.allFinite()) return Refuse("imu.accel: not finite");
  if (!m_B.allFinite()) return Refuse("imu.mag: not finite");
  if (!t_imu0_) t_imu0_ = t;
  if (settings_.rest_from_joints && !filters_started_) {
    if (!still_) {
      has_t_ = true;
      t_last_ = t;
      ++counters_.imu_before_rest;
      return Status::Ok();
    }
    filters_started_ = true;
    t_filters_started_ = t;
  }
  const std::optional<bool> at_rest =
      settings_.rest_from_joints ? std::optional<bool>(still_) : std::nullopt;
  const std::int64_t resets = ori_.counters().resets;
  if (Status s = ori_.Update(t, gyro_B, f_B, m_B, at_rest); !s) {
    if (ori_.counters().resets != resets) FilterReset(t);
    return Refuse("imu: " + s.error());
  }
  has_t_ = true;
  t_last_ = t;
  ++counters_.imu_samples;
  if (!ori_.initialized()) return Status::Ok();
  // Acceleration into the position frame W (see the header): a_W = R_WE (R_EI f + g_E).
  const Eigen::Matrix3d R_EI = ori_.R_EB();
  const Eigen::Vector3d g_E_ori =
      -settings_.orientation.gravity * UpVector(settings_.orientation.earth);
  const Eigen::Vector3d g_E_pos = -settings_.position.gravity * UpVector(settings_.position.earth);
  const Eigen::Vector3d a_W = R_WE_ * (R_EI * f_B + g_E_ori);
  // Its refusals cannot happen here (time and values are checked above); a reset can.
  const std::int64_t pos_resets = pos_.counters().resets;
  if (Status s = pos_.UpdateAccel(t, a_W - g_E_pos, Eigen::Matrix3d::Identity());
      !s && pos_.counters().resets != pos_resets) {
    FilterReset(t);
    return Refuse("imu: " + s.error());
  }
  // The previous window carried by the gyro; across a gap the rotation is unseen: dropped.
  if (carried_ && t - carried_->t > settings_.max_gap) carried_.reset();
  if (carried_) {
    // Rate over (t_{k−1}, t_k] read at t_k (the filter's convention).
    const double dt = t - carried_->t;
    carried_->R_I0I = carried_->R_I0I * geometry::Exp((gyro_B - ori_.bias_B()) * dt);
    carried_->var_gyro += std::pow(settings_.orientation.gyro_noise_density, 2) * dt;
    carried_->duration += dt;
    carried_->t = t;
  }
  if (!open_ || !pos_.initialized()) return Status::Ok();
  if (t - t_last_imu_ > settings_.max_gap) gap_ = true;
  t_last_imu_ = t;
  window_.Add(t, pos_.p_WM_W(), pos_.position_covariance(), ori_.q_EB(),
              ori_.attitude_covariance());
  if (ori_.last_accel_used() && ori_.last_mag_used()) {
    FqaSettings fs;
    fs.earth = settings_.orientation.earth;
    fs.m_ref_E = MagneticNorth(fs.earth);
    const Result<Eigen::Vector4d> q = Fqa(f_B, m_B, fs);
    if (q) raw_R_.push_back(geometry::QuatToMatrix(*q));
  }
  return Status::Ok();
}

Status PosePipeline::AddPosition(double t, const Eigen::Vector3d& p_WM_W) {
  if (Status s = CheckTime(t, "position"); !s) return s;
  if (!p_WM_W.allFinite()) return Refuse("position.p_WM_W: not finite");
  const std::int64_t resets = pos_.counters().resets;
  if (Status s = pos_.UpdatePosition(t, p_WM_W); !s) {
    if (pos_.counters().resets != resets) FilterReset(t);
    return Refuse("position: " + s.error());
  }
  has_t_ = true;
  t_last_ = t;
  ++counters_.position_samples;
  if (open_ && pos_.last_position_accepted()) raw_p_.push_back(p_WM_W);
  return Status::Ok();
}

void PosePipeline::Flush() {
  if (open_) CloseWindow();
}

std::vector<StillPose> PosePipeline::TakePoses() {
  std::vector<StillPose> out;
  out.swap(ready_);
  return out;
}

void PosePipeline::FilterReset(double t) {
  // A filter whose state went non-finite has reset itself; the other one and the open window
  // were built with it. Start both again as at the start (at the next rest, that stop's window
  // being the warm-up), so no window mixes states from before and after the reset.
  ++counters_.filter_resets;
  ori_.Reset();
  pos_.Reset();
  filters_started_ = false;
  carried_.reset();  // the bias it was carried with is gone
  if (open_) {
    open_ = false;
    Drop("window at " + std::to_string(t_open_) + " s: a filter reset at " + std::to_string(t) +
         " s");
  }
}

void PosePipeline::Drop(const std::string& reason) {
  ++counters_.windows_dropped;
  counters_.last_error = reason;
}

void PosePipeline::CloseWindow() {
  open_ = false;
  const std::string when = "window at " + std::to_string(t_open_) + " s: ";
  if (window_in_start_stop_) return Drop(when + "warm-up: the filters started in this stop");
  if (window_.size() < settings_.min_window_samples)
    return Drop(when + std::to_string(window_.size()) + " IMU samples, need " +
                std::to_string(settings_.min_window_samples));
  if (gap_) return Drop(when + "IMU gap longer than max_gap");
  if (raw_p_.empty()) return Drop(when + "no accepted position sample");
  const Result<WindowPose> wp = window_.Estimate();
  if (!wp) return Drop(when + wp.error());

  StillPose pose;
  pose.q = q_sum_ / std::max(1, q_count_);
  pose.p_WM_W = wp->p_WM_W;
  pose.R_EI = geometry::QuatToMatrix(wp->q_EB);
  pose.has_orientation = settings_.use_orientation;
  pose.t_begin = wp->t_begin;
  pose.t_end = wp->t_end;
  pose.imu_samples = wp->samples;
  pose.position_samples = static_cast<int>(raw_p_.size());
  pose.orientation_samples = static_cast<int>(raw_R_.size());

  // Covariance of the window mean from the raw scatter (header).
  Eigen::Matrix3d C_p = wp->P_p;
  const int n_p = static_cast<int>(raw_p_.size());
  if (n_p >= std::max(2, settings_.min_raw_samples)) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : raw_p_) mean += p;
    mean /= n_p;
    Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
    for (const auto& p : raw_p_) S += (p - mean) * (p - mean).transpose();
    C_p = S / (n_p - 1) / n_p;
    // The covariance is that of the raw mean, so the raw mean is the window's position: the
    // position KF's outputs over the window also weigh the samples before it (the end of the
    // move, carried by the accelerometer), and when position samples are lost that part grows
    // while the raw scatter does not see it (window NEES 8.7 for 6.3 at 50 % dropout).
    pose.p_WM_W = mean;
  }
  Eigen::Matrix3d C_th = wp->P_theta;
  const int n_r = static_cast<int>(raw_R_.size());
  if (n_r >= std::max(2, settings_.min_raw_samples)) {
    std::vector<Eigen::Vector3d> d;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& R : raw_R_) {
      d.push_back(geometry::Log(R * pose.R_EI.transpose()));
      mean += d.back();
    }
    mean /= n_r;
    Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
    for (const auto& v : d) S += (v - mean) * (v - mean).transpose();
    C_th = S / (n_r - 1) / n_r;
  }
  const double s = settings_.covariance_scale;
  C_p = s * C_p + std::pow(settings_.position_floor_sigma, 2) * Eigen::Matrix3d::Identity();
  C_th = s * C_th + std::pow(settings_.orientation_floor_sigma, 2) * Eigen::Matrix3d::Identity();
  const double var_ba = std::pow(settings_.accel_bias_sigma, 2) +
                        std::pow(settings_.accel_bias_random_walk, 2) *
                            std::max(0.0, wp->t_end - t_imu0_.value_or(wp->t_end));
  if (var_ba > 0.0) {
    // The heading couples to the tilt through the field's dip (0 before the reference is
    // learned: no magnetometer reference, no coupling known).
    const double dip = ori_.mag_ref_norm() > 0.0 ? ori_.mag_ref_dip() : 0.0;
    C_th += AccelBiasOrientationCovariance(settings_.orientation.earth,
                                           settings_.orientation.gravity, dip, std::sqrt(var_ba));
  }
  const Eigen::Vector3d u = UpVector(settings_.orientation.earth);
  if (pose.has_orientation && carried_ && settings_.heading_consistency_chi2 > 0.0 &&
      ori_.mag_ref_norm() > 0.0) {
    // The previous window carried here by the gyro: a heading beyond the variances followed a
    // disturbed field (here, or, when the previous one was, that one's inflation widens this
    // test). The bias's error δb turns the carried heading by δb T.
    const Eigen::Matrix3d R_pred = carried_->R_EI * carried_->R_I0I;
    const double d_psi = u.dot(geometry::Log(pose.R_EI * R_pred.transpose()));
    const Eigen::Matrix3d P_b = ori_.P().bottomRightCorner<3, 3>();
    const double var =
        carried_->var_window + u.dot(C_th * u) + carried_->var_gyro +
        u.dot(pose.R_EI * P_b * pose.R_EI.transpose() * u) * std::pow(carried_->duration, 2);
    if (d_psi * d_psi > settings_.heading_consistency_chi2 * var) {
      C_th += d_psi * d_psi * u * u.transpose();
      ++counters_.heading_disagreements;
    }
  }
  if (pose.has_orientation) {
    carried_ =
        Carried{pose.R_EI, Eigen::Matrix3d::Identity(), u.dot(C_th * u), 0.0, 0.0, t_last_imu_};
    pose.covariance = Eigen::MatrixXd::Zero(6, 6);
    pose.covariance.topLeftCorner<3, 3>() = C_p;
    pose.covariance.bottomRightCorner<3, 3>() = C_th;
  } else {
    pose.covariance = C_p;
  }
  ++counters_.windows_emitted;
  ready_.push_back(std::move(pose));
}

}  // namespace rcal::estimation
