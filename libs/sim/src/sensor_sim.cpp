#include "rcal/sim/sensor_sim.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "rcal/geometry/so3.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::sim {

ToolMotionTruth::ToolMotionTruth(const kinematics::KinematicModel& model,
                                 const Eigen::VectorXd& x_true, JointTrajectory trajectory,
                                 double fd_step)
    : model_(model), x_true_(x_true), trajectory_(std::move(trajectory)), h_(fd_step) {
  if (x_true_.size() != model_.num_params())
    throw std::invalid_argument("ToolMotionTruth: x_true has the wrong size");
  if (!(h_ > 0)) throw std::invalid_argument("ToolMotionTruth: fd_step must be > 0");
  R_EW_.setIdentity();
  for (const auto& et : model_.ets(kinematics::Segment::kEarth)) {
    const double v = et.nominal + (et.param >= 0 ? x_true_(et.param) : 0.0);
    R_EW_ = R_EW_ * kinematics::EtTransform(et, v).linear();
  }
}

void ToolMotionTruth::set_effects(kinematics::ExtendedModel model, Eigen::VectorXd e,
                                  ContextAt context) {
  if (!context) throw std::invalid_argument("ToolMotionTruth::set_effects: no context");
  if (model.base().num_params() != model_.num_params() || e.size() != model.num_effect_params())
    throw std::invalid_argument(
        "ToolMotionTruth::set_effects: the effects' model is not this truth's model, or e has "
        "the wrong size");
  effects_ =
      std::make_shared<const Effects>(Effects{std::move(model), std::move(e), std::move(context)});
}

void ToolMotionTruth::set_backlash(Eigen::VectorXd b) {
  if (b.size() != model_.num_joints() || !b.allFinite())
    throw std::invalid_argument("ToolMotionTruth::set_backlash: " + std::to_string(b.size()) +
                                " values for " + std::to_string(model_.num_joints()) +
                                " joints, or one not finite");
  backlash_ = std::move(b);
}

Eigen::VectorXd ToolMotionTruth::BacklashOffset(const Eigen::VectorXd& q, double t) const {
  Eigen::VectorXd d = Eigen::VectorXd::Zero(q.size());
  if (backlash_.size() == 0) return d;
  // The stop the arm last arrived at, and the direction each joint came in from the stop before.
  // (Still intervals ascend: a binary search, as this runs three times per simulated tick.)
  const int n = trajectory_.num_waypoints();
  int a = 0;
  for (int hi = n - 1; a < hi;) {
    const int mid = (a + hi + 1) / 2;
    if (trajectory_.StillInterval(mid).first <= t)
      a = mid;
    else
      hi = mid - 1;
  }
  const auto sign = [](double v) { return static_cast<double>((v > 0) - (v < 0)); };
  const auto direction = [&](int k, int j) {
    return k < 1 ? 0.0 : sign(trajectory_.waypoint(k)(j) - trajectory_.waypoint(k - 1)(j));
  };
  const bool moving_on = a + 1 < n && t > trajectory_.StillInterval(a).second;
  for (int j = 0; j < q.size(); ++j) {
    const double b = backlash_(j), s_old = direction(a, j);
    if (b == 0.0) continue;
    double s = s_old;
    if (moving_on) {
      // Across the dead band over the motor's first 2|b| of travel (quintic smoothstep).
      const double s_new = direction(a + 1, j);
      const double u =
          std::min(1.0, std::abs(q(j) - trajectory_.waypoint(a)(j)) / (2.0 * std::abs(b)));
      s = s_old + (s_new - s_old) * u * u * u * (10.0 - 15.0 * u + 6.0 * u * u);
    }
    d(j) = b * s;
  }
  return d;
}

kinematics::ToolPose ToolMotionTruth::Pose(const Eigen::VectorXd& q_read, double t) const {
  // The joints stand off their readings by the backlash (set_backlash).
  const Eigen::VectorXd q =
      backlash_.size() == 0 ? q_read : Eigen::VectorXd(q_read + BacklashOffset(q_read, t));
  if (!effects_) return model_.Forward(q, x_true_);
  return effects_->model.Forward(q, effects_->context(t), x_true_, effects_->e);
}

ToolState ToolMotionTruth::At(double t) const {
  ToolState s;
  s.t = t;
  Eigen::VectorXd q_m, q_p;
  trajectory_.Sample(t, s.q);
  trajectory_.Sample(t - h_, q_m);
  trajectory_.Sample(t + h_, q_p);
  const kinematics::ToolPose pose = Pose(s.q, t);
  const kinematics::ToolPose pm = Pose(q_m, t - h_);
  const kinematics::ToolPose pp = Pose(q_p, t + h_);
  s.p_WM_W = pose.p_WM_W;
  s.R_EI = pose.R_EI;
  s.v_WM_W = (pp.p_WM_W - pm.p_WM_W) / (2 * h_);
  s.a_WM_W = (pp.p_WM_W - 2 * pose.p_WM_W + pm.p_WM_W) / (h_ * h_);
  s.omega_I = geometry::Log(pm.R_EI.transpose() * pp.R_EI) / (2 * h_);
  // The IMU point: p_WI = p_WM − R_WI r_IM_I (exactly p_WM for r = 0).
  const auto imu_point = [&](const kinematics::ToolPose& p) -> Eigen::Vector3d {
    return p.p_WM_W - R_EW_.transpose() * (p.R_EI * r_IM_I_);
  };
  const Eigen::Vector3d pi = imu_point(pose), pi_m = imu_point(pm), pi_p = imu_point(pp);
  s.p_WI_W = pi;
  s.a_WI_W = (pi_p - 2 * pi + pi_m) / (h_ * h_);
  return s;
}

ImuTruth ToolMotionTruth::Imu(const ToolState& s) const {
  ImuTruth u;
  u.t = s.t;
  u.R_WI = s.R_EI;
  u.omega_I = s.omega_I;
  u.a_W = R_EW_ * s.a_WI_W;
  u.p_W = R_EW_ * s.p_WI_W;
  return u;
}

ImuTruth ToolMotionTruth::Imu(const ToolState& s, double interval_s) const {
  ImuTruth u = Imu(s);
  Eigen::VectorXd q_before;
  trajectory_.Sample(s.t - interval_s, q_before);
  const Eigen::Matrix3d R_EI_before = Pose(q_before, s.t - interval_s).R_EI;
  u.omega_I = geometry::Log(R_EI_before.transpose() * s.R_EI) / interval_s;
  return u;
}

namespace {
ImuModelSettings WithRate(ImuModelSettings s, double rate) {
  s.rate_hz = rate;
  return s;
}
}  // namespace

Eigen::VectorXd JointsAsRead(const Eigen::VectorXd& q_true, double t,
                             const std::vector<JointOffsetStep>& steps) {
  Eigen::VectorXd q = q_true;
  for (const JointOffsetStep& s : steps)
    if (t >= s.t_s && s.joint >= 0 && s.joint < q.size()) q(s.joint) -= s.delta;
  return q;
}

Eigen::VectorXd TrueJoints(const Eigen::VectorXd& q_read, double t,
                           const std::vector<JointOffsetStep>& steps) {
  Eigen::VectorXd q = q_read;
  for (const JointOffsetStep& s : steps)
    if (t >= s.t_s && s.joint >= 0 && s.joint < q.size()) q(s.joint) += s.delta;
  return q;
}

SensorSim::SensorSim(const ToolMotionTruth& truth, const SensorSimSettings& settings,
                     std::uint64_t seed)
    : truth_(truth),
      settings_(settings),
      imu_(WithRate(settings.imu, settings.rate_hz), seed * 7919 + 11),
      position_(settings.position, seed * 7919 + 13) {
  if (!(settings_.rate_hz > 0)) throw std::invalid_argument("SensorSim: rate_hz must be > 0");
  const int n = truth_.trajectory().num_waypoints();
  disturbance_E_.assign(n, Eigen::Vector3d::Zero());
  if (settings_.mag_disturbance) {
    std::mt19937_64 rng(seed * 7919 + 17);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::normal_distribution<double> normal(0.0, 1.0);
    for (int k = 0; k < n; ++k) {
      const bool on = u(rng) < settings_.mag_disturbance_fraction;
      const Eigen::Vector3d d = Draw3(normal, rng);
      if (!on) continue;
      disturbed_.push_back(k);
      disturbance_E_[k] = settings_.mag_disturbance_uT * d.normalized();
    }
  }
}

std::int64_t SensorSim::num_ticks() const {
  return static_cast<std::int64_t>(std::floor(truth_.trajectory().duration() * settings_.rate_hz)) +
         1;
}

std::optional<SensorFrame> SensorSim::Next() {
  if (k_ >= num_ticks()) return std::nullopt;
  SensorFrame f;
  f.t = static_cast<double>(k_) / settings_.rate_hz;
  ++k_;
  f.truth = truth_.At(f.t);
  f.q = JointsAsRead(f.truth.q, f.t, settings_.offset_steps);
  if (settings_.joint_resolution > 0)
    for (int i = 0; i < f.q.size(); ++i)
      f.q(i) = settings_.joint_resolution * std::round(f.q(i) / settings_.joint_resolution);
  f.imu = imu_.Sample(truth_.Imu(f.truth, 1.0 / settings_.rate_hz));
  const int stop = truth_.trajectory().StillAt(f.t);
  if (stop >= 0 && settings_.mag_disturbance) {
    const Eigen::Matrix3d R_SI =
        settings_.imu.mounting ? settings_.imu.R_SI : Eigen::Matrix3d::Identity();
    f.imu.mag_S += R_SI * f.truth.R_EI.transpose() * disturbance_E_[stop];
  }
  f.position = position_.Sample(f.t, f.truth.p_WM_W);
  return f;
}

}  // namespace rcal::sim
