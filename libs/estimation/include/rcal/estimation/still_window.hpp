// Still-window detection and the pose measurement over a still window: what the identifier
// consumes after each robot move (NOTES.md, "Static data").
//
// Detection. From joints when available: still while max_i |q_i,k − q_i,k−1| / Δt <
// joint_rate_threshold [rad/s]. Otherwise from the IMU: |ω_meas| < gyro_threshold [rad/s] and
// ||f_B| − g| < accel_threshold [m/s²]. The window opens after min_duration [s] of continuous
// stillness and closes at the first moving sample.
//
// Pose over the window (samples i = 1..N of the filters' outputs, earth frame E):
//   p̄_WM_W = (1/N) Σ p_i,
//   q̄_EB   = the unit eigenvector of the largest eigenvalue of Σ q_i q_iᵀ (Markley's average;
//            q and −q count the same),
//   covariances: the mean of the filters' covariances (1/N) Σ P_i, plus the scatter of the
//   samples about the mean divided by N. The filters' outputs at consecutive samples are
//   strongly correlated, so their covariance is not divided by N: the result is conservative.
//   The orientation covariance is that of the left earth-frame error δθ_E:
//   R_EB = Exp(δθ_E) R̄_EB, as OrientationKf.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "rcal/estimation/result.hpp"

namespace rcal::estimation {

struct StillDetectorSettings {
  double joint_rate_threshold = 1e-3;  ///< [rad/s], max over joints
  double gyro_threshold = 0.02;        ///< [rad/s], |ω_meas| (bias-corrected if you can)
  double accel_threshold = 0.3;        ///< [m/s²], ||f_B| − g|
  double gravity = 9.81;               ///< [m/s²]
  double min_duration = 0.5;           ///< [s] of continuous stillness before still() is true
};

class StillDetector {
 public:
  explicit StillDetector(const StillDetectorSettings& settings = {}) : settings_(settings) {}
  void Reset();
  /// One sample at t [s]. `joints` [rad] (any length, same each call) take precedence over the
  /// IMU when given. Returns still(). Bad input (non-finite, non-increasing t, joint count
  /// change) is refused with an error naming the field; the state is unchanged.
  Result<bool> Update(double t, const std::optional<Eigen::VectorXd>& joints,
                      const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B);
  bool still() const { return still_; }
  /// Start time [s] of the current still stretch (valid when still()).
  double still_since() const { return since_; }

 private:
  StillDetectorSettings settings_;
  bool has_last_ = false;
  double t_last_ = 0.0;
  Eigen::VectorXd q_last_;
  bool candidate_ = false;
  double since_ = 0.0;
  bool still_ = false;
};

/// The pose measurement over one still window.
struct WindowPose {
  Eigen::Vector3d p_WM_W = Eigen::Vector3d::Zero();    ///< mean marker position [m], frame E
  Eigen::Matrix3d P_p = Eigen::Matrix3d::Zero();       ///< its covariance [m²]
  Eigen::Vector4d q_EB = Eigen::Vector4d(1, 0, 0, 0);  ///< mean orientation, body → E, w ≥ 0
  Eigen::Matrix3d P_theta = Eigen::Matrix3d::Zero();   ///< covariance of δθ_E [rad²]
  /// 6×6 block-diagonal covariance of [δp, δθ_E] (the filters give no cross terms).
  Eigen::Matrix<double, 6, 6> P = Eigen::Matrix<double, 6, 6>::Zero();
  int samples = 0;
  double t_begin = 0.0, t_end = 0.0;  ///< [s]
};

class StillWindow {
 public:
  void Reset() { samples_.clear(); }
  /// Adds one filter output at t [s]: position p_WM_W [m] with covariance P_p [m²], orientation
  /// q_EB [w,x,y,z] with the covariance P_theta [rad²] of δθ_E. Non-finite input is refused.
  Status Add(double t, const Eigen::Vector3d& p_WM_W, const Eigen::Matrix3d& P_p,
             const Eigen::Vector4d& q_EB, const Eigen::Matrix3d& P_theta);
  int size() const { return static_cast<int>(samples_.size()); }
  /// The pose over the samples added since Reset(); an error when there are none.
  Result<WindowPose> Estimate() const;

 private:
  struct Sample {
    double t;
    Eigen::Vector3d p;
    Eigen::Matrix3d P_p;
    Eigen::Vector4d q;
    Eigen::Matrix3d P_theta;
  };
  std::vector<Sample> samples_;
};

}  // namespace rcal::estimation
