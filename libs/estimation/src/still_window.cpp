#include "rcal/estimation/still_window.hpp"

#include <Eigen/Eigenvalues>
#include <cmath>

#include "rcal/geometry/so3.hpp"

namespace rcal::estimation {

void StillDetector::Reset() {
  has_last_ = false;
  candidate_ = false;
  still_ = false;
  since_ = 0.0;
  q_last_.resize(0);
}

Result<bool> StillDetector::Update(double t, const std::optional<Eigen::VectorXd>& joints,
                                   const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B) {
  using R = Result<bool>;
  if (!std::isfinite(t)) return R::Error("still_detector: time t is not finite");
  if (has_last_ && !(t > t_last_)) return R::Error("still_detector: time t is not increasing");
  if (joints && !joints->allFinite()) return R::Error("still_detector: joints are not finite");
  if (joints && has_last_ && q_last_.size() > 0 && joints->size() != q_last_.size())
    return R::Error("still_detector: number of joints changed");
  if (!joints && (!gyro_B.allFinite() || !f_B.allFinite()))
    return R::Error("still_detector: gyro or accelerometer is not finite");

  bool now;
  if (joints) {
    now = has_last_ && q_last_.size() == joints->size() &&
          ((*joints - q_last_).cwiseAbs().maxCoeff() / (t - t_last_) <
           settings_.joint_rate_threshold);
    q_last_ = *joints;
  } else {
    now = gyro_B.norm() < settings_.gyro_threshold &&
          std::abs(f_B.norm() - settings_.gravity) < settings_.accel_threshold;
  }
  if (now && !candidate_) since_ = joints && has_last_ ? t_last_ : t;
  candidate_ = now;
  still_ = now && (t - since_) >= settings_.min_duration;
  has_last_ = true;
  t_last_ = t;
  return still_;
}

Status StillWindow::Add(double t, const Eigen::Vector3d& p_WM_W, const Eigen::Matrix3d& P_p,
                        const Eigen::Vector4d& q_EB, const Eigen::Matrix3d& P_theta) {
  if (!std::isfinite(t)) return Status::Error("still_window: time t is not finite");
  if (!p_WM_W.allFinite()) return Status::Error("still_window: position p_WM_W is not finite");
  if (!P_p.allFinite()) return Status::Error("still_window: covariance P_p is not finite");
  if (!q_EB.allFinite() || !(q_EB.norm() > 0.0))
    return Status::Error("still_window: orientation q_EB is not finite or zero");
  if (!P_theta.allFinite()) return Status::Error("still_window: covariance P_theta is not finite");
  samples_.push_back({t, p_WM_W, P_p, q_EB.normalized(), P_theta});
  return Status::Ok();
}

Result<WindowPose> StillWindow::Estimate() const {
  if (samples_.empty()) return Result<WindowPose>::Error("still_window: no samples");
  const double n = static_cast<double>(samples_.size());
  WindowPose w;
  w.samples = static_cast<int>(samples_.size());
  w.t_begin = samples_.front().t;
  w.t_end = samples_.back().t;
  Eigen::Matrix4d M = Eigen::Matrix4d::Zero();
  Eigen::Matrix3d P_p_mean = Eigen::Matrix3d::Zero(), P_th_mean = Eigen::Matrix3d::Zero();
  for (const auto& s : samples_) {
    w.p_WM_W += s.p / n;
    M += s.q * s.q.transpose();
    P_p_mean += s.P_p / n;
    P_th_mean += s.P_theta / n;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eig(M);
  Eigen::Vector4d q = eig.eigenvectors().col(3).normalized();
  if (q(0) < 0) q = -q;
  w.q_EB = q;
  const Eigen::Matrix3d R_mean = geometry::QuatToMatrix(q);
  Eigen::Matrix3d scatter_p = Eigen::Matrix3d::Zero(), scatter_th = Eigen::Matrix3d::Zero();
  for (const auto& s : samples_) {
    const Eigen::Vector3d dp = s.p - w.p_WM_W;
    const Eigen::Vector3d dth = geometry::Log(geometry::QuatToMatrix(s.q) * R_mean.transpose());
    scatter_p += dp * dp.transpose() / n;
    scatter_th += dth * dth.transpose() / n;
  }
  w.P_p = P_p_mean + scatter_p / n;
  w.P_theta = P_th_mean + scatter_th / n;
  w.P.topLeftCorner<3, 3>() = w.P_p;
  w.P.bottomRightCorner<3, 3>() = w.P_theta;
  return w;
}

}  // namespace rcal::estimation
