// Orientation KF against simulated truth (NEES/NIS consistency, bias, rejection), the Φ_ori
// erratum, bad input, and a real BROAD trial with the benchmark's scoring.
#include "rcal/estimation/orientation_kf.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

#include "rcal/geometry/so3.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::estimation {
namespace {

using geometry::QuatToMatrix;
constexpr double kG = 9.81;
constexpr double kDeg = std::numbers::pi / 180.0;

// Truth and noisy IMU at 100 Hz: smooth random rotation, no linear acceleration.
struct Sim {
  double dt = 0.01;
  double sigma_gyro = 2e-3;                                    // per sample [rad/s]
  double sigma_acc = 0.05;                                     // per sample [m/s²]
  double sigma_mag = 0.5;                                      // per sample [µT]
  Eigen::Vector3d bias = Eigen::Vector3d(0.01, -0.02, 0.015);  // [rad/s]
  Eigen::Vector3d m_E;                                         // earth field [µT]
  double mag_delay = 0.0;  // the magnetometer measures the field of this long ago [s]
  EarthFrame earth = EarthFrame::kNed;
  std::vector<double> t;
  std::vector<Eigen::Matrix3d> R_EB;
  std::vector<Eigen::Vector3d> gyro, acc, mag;

  void Run(int n, std::uint64_t seed, double rate_scale = 1.0) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> N(0.0, 1.0);
    const double dip = 60 * kDeg;
    m_E = 45.0 * (std::cos(dip) * MagneticNorth(earth) - std::sin(dip) * UpVector(earth));
    Eigen::Matrix3d R = geometry::FromRpy(0.2, -0.1, 1.0);
    Eigen::Vector3d phase = sim::Draw3(N, rng);
    for (int k = 0; k < n; ++k) {
      const double tk = k * dt;
      Eigen::Vector3d w_mean = Eigen::Vector3d::Zero();
      if (k > 0) {
        // Integrate the smooth rate over the interval in 10 substeps.
        Eigen::Matrix3d R0 = R;
        for (int s = 0; s < 10; ++s) {
          const double ts = tk - dt + (s + 0.5) * dt / 10;
          const Eigen::Vector3d w(std::sin(0.7 * ts + phase(0)),
                                  0.8 * std::sin(1.1 * ts + phase(1)),
                                  0.6 * std::cos(0.5 * ts + phase(2)));
          R = R * geometry::Exp(rate_scale * w * dt / 10);
        }
        w_mean = geometry::Log(R0.transpose() * R) / dt;
      }
      t.push_back(tk);
      R_EB.push_back(R);
      gyro.push_back(w_mean + bias + sigma_gyro * sim::Draw3(N, rng));
      acc.push_back(R.transpose() * (kG * UpVector(earth)) + sigma_acc * sim::Draw3(N, rng));
      // The body mag_delay ago: turned back by the interval's mean rate (exact to O(ω̇ δ²)).
      const Eigen::Matrix3d R_then = R * geometry::Exp(-w_mean * mag_delay);
      mag.push_back(R_then.transpose() * m_E + sigma_mag * sim::Draw3(N, rng));
    }
  }
};

// Settings whose noise model matches Sim exactly (raw samples, no low-pass), for consistency.
OrientationKfSettings MatchedSettings(const Sim& sim) {
  OrientationKfSettings s;
  s.earth = sim.earth;
  s.gyro_noise_density = sim.sigma_gyro * std::sqrt(sim.dt);
  s.tilt_sigma = sim.sigma_acc / kG;
  const double m_h = sim.m_E.head<2>().norm();
  s.heading_sigma = sim.sigma_mag / m_h;
  s.accel_lowpass_tau = 0.0;
  s.mag_lowpass_tau = 0.0;
  s.zero_rate_update = false;
  s.reject_accel = false;
  s.reject_mag = false;
  s.attitude_process_noise = 0.0;
  s.gyro_bias_random_walk = 1e-6;
  s.initial_bias_sigma = 0.05;
  // The simulated sensor never rests and has no linear acceleration: learning the bias and the
  // magnetic reference in motion is right here.
  s.learn_in_motion = true;
  return s;
}

Eigen::Vector3d AttitudeError(const OrientationKf& kf, const Eigen::Matrix3d& R_true) {
  return geometry::Log(R_true * kf.R_EB().transpose());  // δθ_E: R = Exp(δθ) R̂
}

// The largest metric(δθ_E) [rad] of a filter with settings s over sim from sample `from` on.
template <class Metric>
double WorstErrorAfter(const Sim& sim, const OrientationKfSettings& s, size_t from, Metric metric) {
  OrientationKf kf(s);
  double worst = 0;
  for (size_t k = 0; k < sim.t.size(); ++k) {
    EXPECT_TRUE(kf.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
    if (k >= from) worst = std::max(worst, metric(AttitudeError(kf, sim.R_EB[k])));
  }
  return worst;
}

// The RMS tilt error [rad] (the horizontal part of δθ_E) of a filter with settings s over sim
// from sample `from` on.
double RmsTiltAfter(const Sim& sim, const OrientationKfSettings& s, size_t from) {
  OrientationKf kf(s);
  double sum = 0;
  size_t n = 0;
  for (size_t k = 0; k < sim.t.size(); ++k) {
    EXPECT_TRUE(kf.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
    if (k < from) continue;
    sum += AttitudeError(kf, sim.R_EB[k]).head<2>().squaredNorm();
    ++n;
  }
  return std::sqrt(sum / static_cast<double>(n));
}

// ratio(seed) for seeds 1..n, sorted, and their median: a claim about a filter setting is judged
// over many trajectories, never on one.
template <class Ratio>
std::vector<double> SortedOverSeeds(int n, Ratio ratio) {
  std::vector<double> r;
  for (int seed = 1; seed <= n; ++seed) r.push_back(ratio(seed));
  std::sort(r.begin(), r.end());
  return r;
}
double Median(const std::vector<double>& sorted) {
  const size_t n = sorted.size();
  return n % 2 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
}

TEST(PaperPhiOri, Row2ErratumMatchesFiniteDifferenceOfQuaternionKinematics) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> N(0.0, 1.0);
  const double dt = 0.01;
  for (int i = 0; i < 20; ++i) {
    const Eigen::Vector4d q = sim::Draw4(N, rng).normalized();
    const Eigen::Vector3d w = sim::Draw3(N, rng);
    // One Euler step of q̇ = ½ q ⊗ [0, ω]; Φ's columns 5–7 are its derivative in ω.
    auto step = [&](const Eigen::Vector3d& ww) {
      return Eigen::Vector4d(
          q + 0.5 * dt * geometry::QuatMultiply(q, Eigen::Vector4d(0, ww(0), ww(1), ww(2))));
    };
    const Eigen::Matrix<double, 7, 7> Phi = PaperPhiOri(q, dt);
    for (int j = 0; j < 3; ++j) {
      const double h = 1e-6;
      Eigen::Vector3d wp = w, wm = w;
      wp(j) += h;
      wm(j) -= h;
      const Eigen::Vector4d fd = (step(wp) - step(wm)) / (2 * h);
      for (int r = 0; r < 4; ++r)
        EXPECT_NEAR(Phi(r, 4 + j), fd(r), 1e-9) << "row " << r << " col " << 4 + j;
    }
    // The printed row 2 has +q3 in the ω_y column; the erratum is −q3.
    EXPECT_DOUBLE_EQ(Phi(1, 5), -q(3) * dt / 2);
    EXPECT_TRUE((Phi.block<4, 4>(0, 0).isIdentity(0.0)));
    EXPECT_TRUE((Phi.block<3, 3>(4, 4).isIdentity(0.0)));
    EXPECT_TRUE((Phi.block<3, 4>(4, 0).isZero(0.0)));
  }
}

class OrientationKfFrames : public ::testing::TestWithParam<EarthFrame> {};

TEST_P(OrientationKfFrames, ConsistentNeesAndNisOnSimulatedTruth) {
  double nees_sum = 0.0, tilt_nis = 0.0, head_nis = 0.0;
  long n_nees = 0, n_tilt = 0, n_head = 0;
  double worst_deg = 0.0;
  for (std::uint64_t seed = 1; seed <= 4; ++seed) {
    Sim sim;
    sim.earth = GetParam();
    sim.Run(6000, seed);
    OrientationKf kf(MatchedSettings(sim));
    for (size_t k = 0; k < sim.t.size(); ++k) {
      ASSERT_TRUE(kf.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
      if (k < 2000) continue;  // after the bias has converged
      const Eigen::Vector3d e = AttitudeError(kf, sim.R_EB[k]);
      worst_deg = std::max(worst_deg, e.norm() / kDeg);
      nees_sum += e.dot(kf.attitude_covariance().ldlt().solve(e));
      ++n_nees;
      if (std::isfinite(kf.last_tilt_nis())) {
        tilt_nis += kf.last_tilt_nis();
        ++n_tilt;
      }
      if (std::isfinite(kf.last_heading_nis())) {
        head_nis += kf.last_heading_nis();
        ++n_head;
      }
    }
    EXPECT_LT((kf.bias_B() - sim.bias).norm(), 2e-3);
  }
  const double nees = nees_sum / n_nees;
  // 3 dof: a consistent filter averages 3; accept the usual ±50 % for a linearised filter.
  EXPECT_GT(nees, 1.5);
  EXPECT_LT(nees, 4.5);
  EXPECT_NEAR(tilt_nis / n_tilt, 2.0, 0.5);
  EXPECT_NEAR(head_nis / n_head, 1.0, 0.3);
  EXPECT_LT(worst_deg, 1.0);
}

INSTANTIATE_TEST_SUITE_P(Frames, OrientationKfFrames,
                         ::testing::Values(EarthFrame::kNed, EarthFrame::kEnu));

TEST(OrientationKf, GyroBiasStateMatters) {
  Sim sim;
  sim.sigma_acc = 0.3;  // heavier noise: the gyro carries the estimate
  sim.Run(6000, 11);
  auto rmse = [&](bool estimate_bias) {
    auto s = MatchedSettings(sim);
    s.estimate_gyro_bias = estimate_bias;
    OrientationKf kf(s);
    double sum = 0;
    for (size_t k = 0; k < sim.t.size(); ++k) {
      EXPECT_TRUE(kf.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
      sum += AttitudeError(kf, sim.R_EB[k]).squaredNorm();
    }
    return std::sqrt(sum / sim.t.size());
  };
  EXPECT_LT(rmse(true), 0.7 * rmse(false));
}

TEST(OrientationKf, RejectsAccelerationBurstsAndMagneticDisturbance) {
  Sim sim;
  sim.Run(6000, 5);
  // 1 s bursts of 4 m/s² linear acceleration, and a disturbance field of 30 µT for 5 s.
  for (int k = 2000; k < 6000; k += 1000)
    for (int i = 0; i < 100; ++i)
      sim.acc[k + i] += sim.R_EB[k + i].transpose() * Eigen::Vector3d(0.0, 3.0, 3.0);
  for (int k = 4500; k < 5000; ++k)
    sim.mag[k] += sim.R_EB[k].transpose() * Eigen::Vector3d(0, 30.0, 0);
  OrientationKfSettings s = MatchedSettings(sim);
  s.reject_accel = s.reject_mag = true;
  OrientationKf kf(s);
  double worst_tilt = 0, worst = 0;
  for (size_t k = 0; k < sim.t.size(); ++k) {
    ASSERT_TRUE(kf.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
    if (k < 1000) continue;
    const Eigen::Vector3d e = AttitudeError(kf, sim.R_EB[k]);
    worst_tilt = std::max(worst_tilt, e.head<2>().norm());
    worst = std::max(worst, e.norm());
  }
  EXPECT_GE(kf.counters().accel_rejected, 300);
  EXPECT_GE(kf.counters().mag_rejected, 400);
  EXPECT_LT(worst_tilt, 1.0 * kDeg);
  EXPECT_LT(worst, 3.0 * kDeg);
  // Without rejection the same data pulls the estimate away.
  s.reject_accel = s.reject_mag = false;
  OrientationKf naive(s);
  double worst_naive = 0;
  for (size_t k = 0; k < sim.t.size(); ++k) {
    ASSERT_TRUE(naive.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
    if (k >= 1000) worst_naive = std::max(worst_naive, AttitudeError(naive, sim.R_EB[k]).norm());
  }
  EXPECT_GT(worst_naive, 2.0 * worst);
}

// Started in motion (a linear acceleration bends the accelerometer's gravity by ~8.7°), then at
// rest by the caller's word (at_rest, as the pose pipeline passes the joints' rest): by default
// the filter learns neither the gyro bias nor the magnetic reference until the rest, then both
// right; learning in motion (the control) takes the bent gravity into the dip.
TEST(OrientationKf, LearnsBiasAndMagneticReferenceAtRestOnly) {
  std::mt19937_64 rng(17);
  std::normal_distribution<double> N(0.0, 1.0);
  auto n3 = [&] { return sim::Draw3(N, rng); };
  const EarthFrame earth = EarthFrame::kNed;
  const double dip = 60 * kDeg;
  const Eigen::Vector3d m_E =
      45.0 * (std::cos(dip) * MagneticNorth(earth) - std::sin(dip) * UpVector(earth));
  const Eigen::Matrix3d R = geometry::FromRpy(0.2, -0.1, 1.0);
  const Eigen::Vector3d bias(0.004, -0.003, 0.002), a_E(1.5, 0, 0);  // [rad/s], [m/s²]
  struct Run {
    double dip_after_motion, dip_after_rest, bias_error_after_motion, bias_error_after_rest;
  };
  auto run = [&](bool learn_in_motion) {
    OrientationKfSettings s;
    s.earth = earth;
    s.learn_in_motion = learn_in_motion;
    OrientationKf kf(s);
    Run r{};
    for (int k = 0; k < 400; ++k) {
      const bool moving = k < 200;  // 2 s accelerating, then 2 s at rest
      const Eigen::Vector3d f_E = kG * UpVector(earth) + (moving ? a_E : Eigen::Vector3d::Zero());
      EXPECT_TRUE(kf.Update(0.01 * k, bias + 2e-3 * n3(), R.transpose() * f_E + 0.02 * n3(),
                            R.transpose() * m_E + 0.2 * n3(), /*at_rest=*/!moving)
                      .ok());
      if (k == 199) {
        r.dip_after_motion = kf.mag_ref_dip();
        r.bias_error_after_motion = (kf.bias_B() - bias).norm();
      }
    }
    r.dip_after_rest = kf.mag_ref_dip();
    r.bias_error_after_rest = (kf.bias_B() - bias).norm();
    return r;
  };
  const Run at_rest = run(false), in_motion = run(true);
  // Default: nothing learned in the move (reference 0 = not yet; bias still its start, 0).
  EXPECT_EQ(at_rest.dip_after_motion, 0.0);
  EXPECT_NEAR(at_rest.bias_error_after_motion, bias.norm(), 1e-12);
  // After 2 s at rest: the dip to 0.3° (100 samples of 0.2 µT noise on 45 µT: ~0.03°), the bias
  // from its start 5.4e-3 rad/s off to 1e-3 (the mean of 200 samples of 2e-3 rad/s gyro noise is
  // good to 2.4e-4; the filter converges from its prior over the rest).
  EXPECT_NEAR(at_rest.dip_after_rest, dip, 0.3 * kDeg);
  EXPECT_LT(at_rest.bias_error_after_rest, 1e-3);
  // Control: learned in the move, the dip is off by the bent gravity (atan(1.5/9.81) = 8.7°).
  EXPECT_GT(std::abs(in_motion.dip_after_rest - dip), 3 * kDeg);
}

TEST(OrientationKf, QuaternionSignStaysContinuousThroughFullTurns) {
  Sim sim;
  sim.Run(3000, 9, 4.0);  // fast: several full turns
  OrientationKf kf(MatchedSettings(sim));
  Eigen::Vector4d last = Eigen::Vector4d::Zero();
  for (size_t k = 0; k < sim.t.size(); ++k) {
    ASSERT_TRUE(kf.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
    if (k > 0) {
      EXPECT_GT(kf.q_EB().dot(last), 0.5) << k;
    }
    last = kf.q_EB();
    EXPECT_NEAR(kf.q_EB().norm(), 1.0, 1e-12);
  }
}

TEST(OrientationKf, RefusesBadInputWithoutChangingState) {
  OrientationKf kf;
  const Eigen::Vector3d w(0.01, 0, 0), f(0, 0, -kG), m(20, 0, 40);
  ASSERT_TRUE(kf.Update(0.0, w, f, m).ok());
  ASSERT_TRUE(kf.Update(0.01, w, f, m).ok());
  const Eigen::Vector4d q = kf.q_EB();
  const auto P = kf.P();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  auto expect = [&](const Status& s, const std::string& field) {
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().find(field), std::string::npos) << s.error();
    EXPECT_EQ(kf.q_EB(), q);
    EXPECT_EQ(kf.P(), P);
  };
  expect(kf.Update(0.02, Eigen::Vector3d(nan, 0, 0), f, m), "gyro");
  expect(kf.Update(0.02, w, Eigen::Vector3d(0, nan, 0), m), "accelerometer");
  expect(kf.Update(0.02, w, f, Eigen::Vector3d(0, 0, nan)), "magnetometer");
  expect(kf.Update(0.01, w, f, m), "time");
  expect(kf.Update(0.005, w, f, m), "time");
  expect(kf.Update(nan, w, f, m), "time");
  EXPECT_EQ(kf.counters().input_rejected, 6);
  EXPECT_TRUE(kf.Update(0.02, w, f, m).ok());
  // An uninitialised filter refuses a sample the FQA cannot use.
  OrientationKf fresh;
  const Status s0 = fresh.Update(0.0, w, Eigen::Vector3d::Zero(), m);
  ASSERT_FALSE(s0.ok());
  EXPECT_NE(s0.error().find("accelerometer"), std::string::npos) << s0.error();
  EXPECT_FALSE(fresh.initialized());
  kf.Reset();
  EXPECT_FALSE(kf.initialized());
  EXPECT_EQ(kf.counters().samples, 0);
}

// Issue 11: one gyro sample of 1e300 rad/s (finite) made every later estimate NaN. Values beyond
// the sensor's range are refused naming the field, and the state is unchanged.
// last_mag_B: the field the heading row used (aided_ins.hpp levels it with its own tilt): at rest
// with a steady field, the field itself (its low-pass of a constant); NaN for a sample the gate
// refuses (the norm doubled: a magnet).
TEST(OrientationKf, LastMagBIsTheFieldTheHeadingRowUsed) {
  OrientationKf kf;
  const Eigen::Vector3d w = Eigen::Vector3d::Zero(), f(0, 0, -kG), m(20, 0, 40);
  double t = 0.0;
  for (int k = 0; k < 300; ++k, t += 0.01) ASSERT_TRUE(kf.Update(t, w, f, m).ok());
  ASSERT_TRUE(kf.last_mag_used());
  EXPECT_LT((kf.last_mag_B() - m).norm(), 1e-6 * m.norm()) << kf.last_mag_B().transpose();
  ASSERT_TRUE(kf.Update(t, w, f, 2.0 * m).ok());
  EXPECT_FALSE(kf.last_mag_used());
  EXPECT_FALSE(kf.last_mag_B().allFinite());
}

TEST(OrientationKf, RefusesValuesBeyondTheSensorRange) {
  OrientationKf kf;
  const Eigen::Vector3d w(0.01, 0, 0), f(0, 0, -kG), m(20, 0, 40);
  ASSERT_TRUE(kf.Update(0.0, w, f, m).ok());
  ASSERT_TRUE(kf.Update(0.01, w, f, m).ok());
  const Eigen::Vector4d q = kf.q_EB();
  Status s = kf.Update(0.02, Eigen::Vector3d(1e300, 0, 0), f, m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("gyro is beyond the sensor range"), std::string::npos) << s.error();
  s = kf.Update(0.02, w, Eigen::Vector3d(0, 0, -400.0), m);  // 41 g, range 320 m/s²
  EXPECT_NE(s.error().find("accelerometer is beyond the sensor range"), std::string::npos)
      << s.error();
  EXPECT_EQ(kf.q_EB(), q);
  // At the range itself a sample is still taken.
  EXPECT_TRUE(kf.Update(0.02, Eigen::Vector3d(0, 0, 0.01), Eigen::Vector3d(0, 0, -kG), m).ok());
  for (int k = 3; k < 100; ++k) ASSERT_TRUE(kf.Update(0.01 * k, w, f, m).ok());
  EXPECT_TRUE(kf.q_EB().allFinite());
  EXPECT_EQ(kf.counters().input_rejected, 2);
}

// A state that goes non-finite is never kept: here a process noise of 1e300 (a degenerate
// setting) overflows P on the first step. The filter resets, says so, counts it, and its
// accessors never return NaN.
TEST(OrientationKf, ResetsWhenTheStateGoesNonFinite) {
  OrientationKfSettings st;
  st.attitude_process_noise = 1e300;
  st.angular_accel_noise = 1e300;
  OrientationKf kf(st);
  const Eigen::Vector3d w(0.01, 0, 0), f(0, 0, -kG), m(20, 0, 40);
  ASSERT_TRUE(kf.Update(0.0, w, f, m).ok());
  const Status s = kf.Update(0.01, w, f, m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("non-finite"), std::string::npos) << s.error();
  EXPECT_FALSE(kf.initialized());
  EXPECT_EQ(kf.counters().resets, 1);
  EXPECT_TRUE(kf.q_EB().allFinite());
  EXPECT_TRUE(kf.P().allFinite());
  // It initialises again at the next sample.
  EXPECT_TRUE(kf.Update(0.02, w, f, m).ok());
  EXPECT_TRUE(kf.initialized());
  EXPECT_EQ(kf.counters().resets, 1);
}

// The IMU falls silent for 1 s while the sensor turns at about 1 rad/s (8 trajectories; the
// filter matched to the sensor). Across the silence the filter can only extrapolate its rate, and
// the rate changed: 2 s after it the attitude is still 6–17° off (worst), beyond what the
// linearised update takes back. Starting again from the FQA of the first sample after the silence
// (max_step), with the bias kept, it is within 0.1–0.2°, as without a silence.
TEST(OrientationKf, StartsAgainFromTheSensorsAfterAnImuSilence) {
  constexpr size_t kSilentFrom = 1500, kSilentTo = 1600, kScoredFrom = 1800;  // samples, 100 Hz
  EXPECT_EQ(OrientationKfSettings{}.max_step, 0.1);
  for (int seed = 1; seed <= 8; ++seed) {
    Sim sim;
    sim.Run(3000, static_cast<std::uint64_t>(seed));
    // The worst attitude error [rad] from kScoredFrom on, with max_step, the IMU silent over
    // [kSilentFrom, kSilentTo) or not; the filter's counters and whether its bias was kept.
    struct Run {
      double worst = 0.0;
      OrientationKf::Counters counters;
      double bias_change = 0.0;  // |b̂ just after the silence − b̂ just before| [rad/s]
    };
    const auto run = [&](double max_step, bool silent) {
      OrientationKfSettings s = MatchedSettings(sim);
      s.max_step = max_step;
      OrientationKf kf(s);
      Run r;
      Eigen::Vector3d bias_before = Eigen::Vector3d::Zero();
      for (size_t k = 0; k < sim.t.size(); ++k) {
        if (silent && k >= kSilentFrom && k < kSilentTo) continue;
        EXPECT_TRUE(kf.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
        if (k + 1 == kSilentFrom) bias_before = kf.bias_B();
        if (k == kSilentTo) {
          r.bias_change = (kf.bias_B() - bias_before).norm();
          // Restarted: no heading row this sample, so no field for another filter to level.
          if (silent && max_step > 0.0) {
            EXPECT_FALSE(kf.last_mag_B().allFinite());
          }
        }
        if (k >= kScoredFrom) r.worst = std::max(r.worst, AttitudeError(kf, sim.R_EB[k]).norm());
      }
      r.counters = kf.counters();
      return r;
    };
    const Run reinitialised = run(0.1, true), extrapolated = run(0.0, true),
              uninterrupted = run(0.1, false);
    std::printf(
        "seed %d: worst attitude error from 2 s after a 1 s silence %.2f° (extrapolated "
        "%.2f°; no silence %.2f°)\n",
        seed, reinitialised.worst / kDeg, extrapolated.worst / kDeg, uninterrupted.worst / kDeg);
    EXPECT_EQ(reinitialised.counters.reinitialised, 1);
    EXPECT_EQ(extrapolated.counters.reinitialised, 0);
    EXPECT_EQ(uninterrupted.counters.reinitialised, 0);
    EXPECT_EQ(reinitialised.bias_change, 0.0);
    EXPECT_GT(extrapolated.worst, 5.0 * kDeg);
    EXPECT_LT(reinitialised.worst, 0.2 * extrapolated.worst);
    EXPECT_LT(reinitialised.worst, 2.0 * uninterrupted.worst + 0.1 * kDeg);
  }
}

// An IMU slower than 1/max_step: every step would be a silence. MaxStepForRate gives three of its
// periods instead, so a 5 Hz stream is filtered, not re-initialised at every sample.
TEST(OrientationKf, ASlowImuIsNotTakenForASilentOne) {
  EXPECT_EQ(MaxStepForRate(100.0), 0.1);
  EXPECT_EQ(MaxStepForRate(10.0), 0.3);
  EXPECT_EQ(MaxStepForRate(5.0), 0.6);
  EXPECT_EQ(MaxStepForRate(0.0), 0.1);
  EXPECT_EQ(MaxStepForRate(std::nan("")), 0.1);
  EXPECT_EQ(MaxStepForRate(1000.0, 0.25), 0.25);
  Sim sim;
  sim.Run(3000, 1);
  for (const double max_step : {0.1, MaxStepForRate(5.0)}) {
    OrientationKfSettings s = MatchedSettings(sim);
    s.max_step = max_step;
    OrientationKf kf(s);
    for (size_t k = 0; k < sim.t.size(); k += 20)  // 5 Hz
      EXPECT_TRUE(kf.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
    EXPECT_EQ(kf.counters().reinitialised, max_step == 0.1 ? 149 : 0);
  }
}

// 60 s of the simulated motion (with the gyro bias, or none) with linear accelerations of
// 3.6 m/s² at 1 Hz from 10 s on, one period on, one off, bending the measured gravity.
Sim LinearlyAccelerated(int seed, bool gyro_bias) {
  Sim sim;
  if (!gyro_bias) sim.bias.setZero();
  sim.Run(6000, seed);
  for (int k = 1000; k < 6000; ++k)
    if ((k / 100) % 2 == 0)
      sim.acc[k] += sim.R_EB[k].transpose() * Eigen::Vector3d(3.0, -2.0, 0.0) *
                    std::sin(k * sim.dt * 2.0 * std::numbers::pi);
  return sim;
}

// BROAD trial 02 (real IMU, optical truth) with the default settings, scored as the benchmark
// scores. Thresholds: the published Madgwick figures for this trial (1.50 / 1.26 / 0.80°).
// Issue 17: the accelerometer weighted by motion, σ_tilt inflated by |f_B − f̄_B| (the raw
// specific force's departure from its low-pass). Linear accelerations of 3.6 m/s² (one 1 Hz period
// on, one off) bend the measured gravity. Over 16 trajectories the weighting does not keep the
// tilt closer to the truth than the same filter trusting every sample alike: what the update uses
// is the low-passed force, which a 3 s low-pass already holds near gravity, and the weighting
// takes trust away exactly while the raw force swings. This is why the default leaves it off and
// why `rcal fuse-loo` (leave-one-trial-out on BROAD) leaves it off too. An earlier version of this
// test claimed a gain on one trajectory (seed 11: 2.54° → 2.00° worst) that was the exception:
// clang, drawing that seed's noise in another order, read 1.79° → 3.86°.
TEST(OrientationKf, MotionWeightedAccelerometerDoesNotBeatTrustingEverySample) {
  EXPECT_EQ(OrientationKfSettings{}.tilt_motion_accel, 0.0);
  const auto ratios = SortedOverSeeds(16, [](int seed) {
    const Sim sim = LinearlyAccelerated(seed, true);
    OrientationKfSettings s = MatchedSettings(sim);
    s.accel_lowpass_tau = 3.0;
    const double plain = RmsTiltAfter(sim, s, 1000);
    s.tilt_motion_accel = 0.3;
    return RmsTiltAfter(sim, s, 1000) / plain;
  });
  const double median = Median(ratios);
  std::printf(
      "RMS tilt weighted by motion / trusting every sample, 16 seeds: median %.3f, "
      "best %.3f, worst %.3f\n",
      median, ratios.front(), ratios.back());
  // Measured: median 1.23, 0.83–3.49 (gcc and clang alike; 1.26 over 24 seeds).
  EXPECT_GT(median, 1.0);
}

// The accelerometer's low-pass of second order (a Butterworth, accel_lowpass_order = 2, VQF's)
// against the first-order one of the same τ = 3 s (the same delay at low frequencies): linear
// accelerations of 3.6 m/s² at 1 Hz, one period on, one off, bend the measured gravity; the
// second-order filter keeps (f_c/f)² of them, ~0.6 % at 1 Hz, where the first-order one keeps
// f_c/f, ~5 %. With the gyro bias known (none, not estimated) the tilt is closer to the truth on
// every one of 16 trajectories. With the bias learned in motion, which these filters do from the
// same low-passed tilt, it is farther on every one: the low-pass sits inside the loop that
// learns the bias (a tilt innovation moves the bias, which turns the strapdown frame the
// accelerometer is low-passed in), and the second order's extra phase lag there costs more than
// its rejection gains. So it is off by default (BROAD, README: mixed as well).
TEST(OrientationKf, ASecondOrderLowPassHelpsOnlyWhereTheBiasIsNotLearnedThroughIt) {
  EXPECT_EQ(OrientationKfSettings{}.accel_lowpass_order, 1);
  for (const bool learn_bias : {false, true}) {
    const auto ratios = SortedOverSeeds(16, [&](int seed) {
      const Sim sim = LinearlyAccelerated(seed, learn_bias);
      OrientationKfSettings s = MatchedSettings(sim);
      s.accel_lowpass_tau = 3.0;
      s.estimate_gyro_bias = learn_bias;
      const double first = RmsTiltAfter(sim, s, 1000);
      s.accel_lowpass_order = 2;
      return RmsTiltAfter(sim, s, 1000) / first;
    });
    std::printf(
        "RMS tilt, second-order low-pass / first-order, bias %s, 16 seeds: median %.3f, best "
        "%.3f, worst %.3f\n",
        learn_bias ? "learned in motion" : "known", Median(ratios), ratios.front(), ratios.back());
    if (learn_bias) {
      EXPECT_GT(ratios.front(), 1.0);  // measured: median 3.0, 1.65–10
    } else {
      EXPECT_LT(ratios.back(), 1.0);  // measured: median 0.78, 0.70–0.82
      EXPECT_LT(Median(ratios), 0.9);
    }
  }
}

// Issue 17: a field disturbed within the rejection gate (3 µT east and 3 µT down in NED: the
// norm moves by ~2.6 µT of 45, 58 % of the 10 % tolerance; the dip by ~1.9° of 4.6°) turns the
// horizontal field by 7.6°; weighting each accepted sample down by its disturbance evidence
// (its departure from the reference in units of the tolerance) keeps heading closer, on every one
// of 16 trajectories.
TEST(OrientationKf, DisturbanceEvidenceWeightsTheMagnetometerDown) {
  auto heading = [](const Eigen::Vector3d& e) { return std::abs(e.z()); };
  const auto ratios = SortedOverSeeds(16, [&](int seed) {
    Sim sim;
    sim.Run(6000, seed);
    for (int k = 3000; k < 4500; ++k)
      sim.mag[k] += sim.R_EB[k].transpose() * Eigen::Vector3d(0.0, 3.0, 3.0);
    OrientationKfSettings s = MatchedSettings(sim);
    s.reject_mag = true;
    s.mag_norm_tolerance = 0.1;
    s.mag_dip_tolerance = 0.08;
    const double plain = WorstErrorAfter(sim, s, 1000, heading);
    s.mag_evidence_inflation = 100.0;
    return WorstErrorAfter(sim, s, 1000, heading) / plain;
  });
  const double median = Median(ratios);
  std::printf(
      "worst heading weighted by evidence / plain, 16 seeds: median %.3f, best %.3f, "
      "worst %.3f\n",
      median, ratios.front(), ratios.back());
  // Measured: median 0.133, 0.098–0.147 (about 6° → 0.8° worst on every seed).
  EXPECT_LT(median, 0.25);
  EXPECT_LT(ratios.back(), 0.4);
}

// A magnetometer 15 ms behind the gyro (BROAD's Xsens MTi lags by about that much), in fast
// rotation (up to ~4 rad/s): uncompensated its field is up to 3.4° off, its dip fails the gate and
// its heading pulls the estimate; turned to the gyro's time by the rate (mag_delay), it is used
// and the heading error drops. Truth: the simulated attitude; 16 seeds.
TEST(OrientationKf, ADelayedMagnetometerIsTurnedToTheGyrosTime) {
  auto heading = [](const Eigen::Vector3d& e) { return std::abs(e.z()); };
  std::vector<double> ratios;
  std::int64_t rejected_plain = 0, rejected_turned = 0;
  for (int seed = 1; seed <= 16; ++seed) {
    Sim sim;
    sim.mag_delay = 0.015;
    sim.Run(4000, seed, 4.0);
    OrientationKfSettings s = MatchedSettings(sim);
    s.reject_mag = true;
    s.mag_norm_tolerance = 0.1;
    s.mag_dip_tolerance = 0.04;
    OrientationKf plain(s);
    s.mag_delay = 0.015;
    OrientationKf turned(s);
    double worst_plain = 0, worst_turned = 0;
    for (size_t k = 0; k < sim.t.size(); ++k) {
      ASSERT_TRUE(plain.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
      ASSERT_TRUE(turned.Update(sim.t[k], sim.gyro[k], sim.acc[k], sim.mag[k]).ok());
      if (k < 1000) continue;
      worst_plain = std::max(worst_plain, heading(AttitudeError(plain, sim.R_EB[k])));
      worst_turned = std::max(worst_turned, heading(AttitudeError(turned, sim.R_EB[k])));
    }
    ratios.push_back(worst_turned / worst_plain);
    rejected_plain += plain.counters().mag_rejected;
    rejected_turned += turned.counters().mag_rejected;
  }
  std::sort(ratios.begin(), ratios.end());
  std::printf(
      "worst heading turned / as stamped, 16 seeds: median %.3f, %.3f–%.3f; magnetometer "
      "samples refused %lld as stamped, %lld turned\n",
      Median(ratios), ratios.front(), ratios.back(), static_cast<long long>(rejected_plain),
      static_cast<long long>(rejected_turned));
  EXPECT_LT(Median(ratios), 0.5);
  EXPECT_LT(ratios.back(), 1.0);
  EXPECT_LT(rejected_turned, rejected_plain / 4);
}

TEST(OrientationKf, BeatsMadgwickOnBroadTrial02) {
  const auto T =
      io::CsvTable::Load(std::string(RCAL_SHARED_DIR) + "/data/broad/broad_02_100hz.csv");
  OrientationKfSettings s;
  s.earth = EarthFrame::kEnu;
  OrientationKf kf(s);
  double tot = 0, head = 0, incl = 0;
  long n = 0;
  for (int k = 0; k < T.rows(); ++k) {
    ASSERT_TRUE(kf.Update(T.At(k, "t_s"), {T.At(k, "gyr_x"), T.At(k, "gyr_y"), T.At(k, "gyr_z")},
                          {T.At(k, "acc_x"), T.At(k, "acc_y"), T.At(k, "acc_z")},
                          {T.At(k, "mag_x"), T.At(k, "mag_y"), T.At(k, "mag_z")})
                    .ok());
    const Eigen::Vector4d q_truth(T.At(k, "q_w"), T.At(k, "q_x"), T.At(k, "q_y"), T.At(k, "q_z"));
    if (T.At(k, "movement") < 0.5 || !q_truth.allFinite()) continue;
    const Eigen::Vector4d e =
        geometry::QuatMultiply(kf.q_EB(), geometry::QuatConjugate(q_truth.normalized()));
    const double a = 2 * std::acos(std::min(1.0, std::abs(e(0))));
    const double h = 2 * std::atan(std::abs(e(3) / e(0)));
    const double i = 2 * std::acos(std::min(1.0, std::sqrt(e(0) * e(0) + e(3) * e(3))));
    tot += a * a, head += h * h, incl += i * i, ++n;
  }
  ASSERT_GT(n, 10000);
  EXPECT_LT(std::sqrt(tot / n) / kDeg, 1.50);
  EXPECT_LT(std::sqrt(head / n) / kDeg, 1.26);
  EXPECT_LT(std::sqrt(incl / n) / kDeg, 0.80);
}

}  // namespace
}  // namespace rcal::estimation
