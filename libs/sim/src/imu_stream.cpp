#include "rcal/sim/imu_stream.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "rcal/geometry/so3.hpp"

namespace rcal::sim {
namespace {

constexpr int kHarmonics = 3;

struct Harmonics {
  std::array<std::array<double, kHarmonics>, 3> amp{}, freq{}, phase{};
  Eigen::Vector3d At(double s) const {
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) {
      double sum = 0.0;
      for (int j = 0; j < kHarmonics; ++j)
        sum += amp[i][j] * std::sin(2.0 * std::numbers::pi * freq[i][j] * s + phase[i][j]);
      v(i) = sum;
    }
    return v;
  }
};

Harmonics Draw(double total_amplitude, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> f(0.2, 1.2), ph(0.0, 2.0 * std::numbers::pi), a(0.3, 1.0);
  Harmonics h;
  for (int i = 0; i < 3; ++i) {
    double sum = 0.0;
    for (int j = 0; j < kHarmonics; ++j) {
      h.freq[i][j] = f(rng);
      h.phase[i][j] = ph(rng);
      h.amp[i][j] = a(rng);
      sum += h.amp[i][j];
    }
    for (int j = 0; j < kHarmonics; ++j) h.amp[i][j] *= total_amplitude / sum;
  }
  return h;
}

Eigen::Vector4d QuatExp(const Eigen::Vector3d& phi) {
  const double a = phi.norm();
  if (a < 1e-12)
    return Eigen::Vector4d(1.0, 0.5 * phi.x(), 0.5 * phi.y(), 0.5 * phi.z()).normalized();
  const Eigen::Vector3d v = std::sin(0.5 * a) / a * phi;
  return Eigen::Vector4d(std::cos(0.5 * a), v.x(), v.y(), v.z());
}

class Motion {
 public:
  Motion(const ImuStreamSettings& s, bool linear, double linear_accel, std::mt19937_64& rng)
      : s_(s) {
    for (int k = 0; k < s.motion_segments; ++k) {
      rot_.push_back(Draw(s.max_rate, rng));
      acc_.push_back(Draw(linear ? linear_accel : 0.0, rng));
      // c = (2/T) ∫₀ᵀ w(s) Σ B sin(…) ds (Simpson): no net velocity change over the segment.
      constexpr int kSteps = 4000;
      const double hs = s.motion_s / kSteps;
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (int i = 0; i <= kSteps; ++i) {
        const double weight = (i == 0 || i == kSteps) ? 1.0 : (i % 2 ? 4.0 : 2.0);
        sum += weight * Window(i * hs) * acc_.back().At(i * hs);
      }
      acc_offset_.push_back(2.0 / s.motion_s * sum * hs / 3.0);
    }
  }
  // Motion segment k and the time s into it, or −1 at rest.
  int Segment(double t, double* s) const {
    const double period = s_.rest_s + s_.motion_s;
    if (t < s_.rest_s) return -1;
    const int k = static_cast<int>(std::floor((t - s_.rest_s) / period));
    if (k >= s_.motion_segments) return -1;
    const double u = t - s_.rest_s - k * period;
    if (u >= s_.motion_s) return -1;
    *s = u;
    return k;
  }
  double Window(double s) const {
    const double w = std::sin(std::numbers::pi * s / s_.motion_s);
    return w * w;
  }
  Eigen::Vector3d Omega(double t) const {
    double s = 0.0;
    const int k = Segment(t, &s);
    return k < 0 ? Eigen::Vector3d::Zero() : Eigen::Vector3d(Window(s) * rot_[k].At(s));
  }
  Eigen::Vector3d Accel(double t) const {
    double s = 0.0;
    const int k = Segment(t, &s);
    return k < 0 ? Eigen::Vector3d::Zero()
                 : Eigen::Vector3d(Window(s) * (acc_[k].At(s) - acc_offset_[k]));
  }

 private:
  const ImuStreamSettings& s_;
  std::vector<Harmonics> rot_, acc_;
  std::vector<Eigen::Vector3d> acc_offset_;  // c per segment [m/s²]
};

}  // namespace

std::vector<ImuStreamSample> SimulateImuStream(const ImuStreamSettings& settings,
                                               const ImuStreamEffects& effects,
                                               std::mt19937_64& rng) {
  if (!(settings.rate_hz > 0.0) || settings.motion_segments < 0 || !(settings.rest_s > 0.0) ||
      !(settings.motion_s > 0.0) || settings.substeps < 1)
    throw std::invalid_argument("SimulateImuStream: rate_hz, rest_s, motion_s must be > 0");
  const Motion motion(settings, effects.linear_accel != 0.0, effects.linear_accel, rng);

  const double dt = 1.0 / settings.rate_hz;
  const double duration =
      settings.rest_s + settings.motion_segments * (settings.rest_s + settings.motion_s);
  const auto n = static_cast<long>(std::floor(duration * settings.rate_hz));
  const double tau = effects.time_offset_s;
  const double delta = effects.accel_delay_s;
  if (!std::isfinite(tau) || !std::isfinite(delta))
    throw std::invalid_argument(
        "SimulateImuStream: time_offset_s and accel_delay_s must be finite");

  // Orientation on a fine grid from t_min, by exact exponential steps with the midpoint rate.
  const double h = dt / settings.substeps;
  const double t_min = -std::abs(tau) - std::abs(delta) - 2.0 * dt;
  const double t_max = duration + std::abs(tau) + std::abs(delta) + 2.0 * dt;
  const auto grid = static_cast<long>(std::ceil((t_max - t_min) / h)) + 1;
  std::vector<Eigen::Vector4d> q(grid);
  q[0] = settings.q0_WI.normalized();
  for (long i = 1; i < grid; ++i)
    q[i] = geometry::QuatMultiply(q[i - 1], QuatExp(motion.Omega(t_min + (i - 0.5) * h) * h))
               .normalized();
  // Position and velocity on the same grid: midpoint velocity, trapezoid position.
  std::vector<Eigen::Vector3d> v(grid, Eigen::Vector3d::Zero()), p(grid, Eigen::Vector3d::Zero());
  for (long i = 1; i < grid; ++i) {
    v[i] = v[i - 1] + h * motion.Accel(t_min + (i - 0.5) * h);
    p[i] = p[i - 1] + 0.5 * h * (v[i - 1] + v[i]);
  }
  auto p_at = [&](double t) -> Eigen::Vector3d {
    const long i = std::clamp(static_cast<long>(std::floor((t - t_min) / h)), 0L, grid - 2);
    const double u = t - (t_min + i * h);
    return p[i] + u * v[i] + 0.5 * u * u * motion.Accel(t_min + i * h + 0.5 * u);
  };
  auto q_at = [&](double t) -> Eigen::Vector4d {
    const long i = std::clamp(static_cast<long>(std::floor((t - t_min) / h)), 0L, grid - 2);
    const double delta = t - (t_min + i * h);
    return geometry::QuatMultiply(q[i], QuatExp(motion.Omega(t_min + i * h + 0.5 * delta) * delta))
        .normalized();
  };

  ImuModelSettings imu_settings = settings.imu;
  imu_settings.rate_hz = settings.rate_hz;
  imu_settings.g_W = Eigen::Vector3d(0.0, 0.0, -settings.gravity);
  imu_settings.m_W = settings.m_W_uT;
  ImuModel imu(imu_settings, rng());
  std::normal_distribution<double> normal(0.0, 1.0);

  std::vector<ImuStreamSample> out;
  out.reserve(n);
  Eigen::Vector3d b_rw = Eigen::Vector3d::Zero();
  for (long k = 0; k < n; ++k) {
    const double t = k * dt;
    const double t_imu = t - tau;  // the truth time the IMU sample measures
    ImuTruth truth;
    truth.t = t;
    truth.R_WI = geometry::QuatToMatrix(q_at(t_imu));
    // The gyro's rate is the mean over the sample interval ending at t_imu (sim::ImuTruth).
    const Eigen::Matrix3d R_WI_before = geometry::QuatToMatrix(q_at(t_imu - dt));
    truth.omega_I = geometry::Log(R_WI_before.transpose() * truth.R_WI) / dt;
    truth.a_W = motion.Accel(t_imu);
    ImuSample m = imu.Sample(truth);
    if (delta != 0.0) {  // the accelerometer reads the specific force of t_imu − δ
      const Eigen::Matrix3d R_late = geometry::QuatToMatrix(q_at(t_imu - delta));
      const Eigen::Vector3d f_late =
          R_late.transpose() * (motion.Accel(t_imu - delta) - imu_settings.g_W);
      const Eigen::Vector3d f_now = truth.R_WI.transpose() * (truth.a_W - imu_settings.g_W);
      m.accel_S += imu_settings.R_SI * (f_late - f_now);
    }
    if (k > 0)
      for (int i = 0; i < 3; ++i)
        b_rw(i) += effects.gyro_bias_random_walk(i) * std::sqrt(dt) * normal(rng);
    m.gyro_S += b_rw;
    if (effects.mag_disturbance && t_imu >= effects.mag_disturbance_start_s &&
        t_imu < effects.mag_disturbance_end_s)
      m.mag_S += imu_settings.R_SI * truth.R_WI.transpose() * effects.mag_disturbance_uT;
    ImuStreamSample s;
    s.t = t;
    s.gyro = m.gyro_S;
    s.accel = m.accel_S;
    s.mag_uT = m.mag_S;
    s.q_WI = q_at(t);
    if (s.q_WI(0) < 0) s.q_WI = -s.q_WI;
    double u = 0.0;
    s.movement = motion.Segment(t, &u) >= 0 ? 1 : 0;
    s.gyro_bias = imu.gyro_bias() + b_rw;
    s.p_W = p_at(t);
    out.push_back(s);
  }
  return out;
}

}  // namespace rcal::sim
