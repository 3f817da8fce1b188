// PositionKfBank: the weights against the filters' own likelihoods (closed form), and on an
// analytic truth whose accelerometer is good, then bad: the bank follows the better model in each
// phase.
#include "rcal/estimation/position_kf_bank.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>
#include <vector>

#include "rcal/geometry/so3.hpp"
#include "rcal/sim/draw.hpp"
#include "swinging_tool.hpp"

namespace rcal::estimation {
namespace {

constexpr double kG = 9.81;

// A level marker pushed along x while it oscillates in z (NED): its position p_WM_W [m] at t [s]
// and the accelerometer's specific force f = a − g_E [m/s²] (g_E = +g·down; the filter removes it,
// PositionKf::WorldAcceleration) with 0.05 m/s² of white noise drawn from N.
struct PushedMarker {
  Eigen::Vector3d p_WM_W, f_B;
};
PushedMarker Pushed(double t, std::normal_distribution<double>& N, std::mt19937_64& rng) {
  const Eigen::Vector3d a_W(0.6, 0.0, -0.45 * std::sin(3.0 * t));
  return {Eigen::Vector3d(0.3 * t * t, -0.1 * t, 0.05 * std::sin(3.0 * t)),
          a_W - Eigen::Vector3d(0.0, 0.0, kG) + 0.05 * sim::Draw3(N, rng)};
}

// Two copies of one model: equal evidence, equal weights, and the mixture is the filter's own
// estimate; with μ_min 0 (no bound on the evidence) the weights follow L_i ← e^{−Δt/τ} L_i + ℓ_i
// exactly (recomputed from the filters' reported log-likelihoods).
TEST(PositionKfBank, WeightsAreTheFadedLikelihoodsOfEachFiltersInnovations) {
  PositionKfSettings a, b;
  a.position_gate_chi2 = b.position_gate_chi2 = 0.0;
  b.accel_sigma = 3.0;  // a different model: different predictions, different evidence
  PositionKfBankSettings s;
  s.models = {a, a};
  s.evidence_tau = 0.5;
  s.min_probability = 0.0;
  PositionKfBank same(s);
  s.models = {a, b};
  PositionKfBank bank(s);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> N(0.0, 1.0);
  double L0 = 0.0, L1 = 0.0;
  for (int k = 0; k < 60; ++k) {
    const double t = 0.01 * k;
    const PushedMarker m = Pushed(t, N, rng);
    ASSERT_TRUE(same.UpdateAccel(t, m.f_B, Eigen::Matrix3d::Identity()).ok());
    ASSERT_TRUE(bank.UpdateAccel(t, m.f_B, Eigen::Matrix3d::Identity()).ok());
    if (k % 5 != 0) continue;
    const Eigen::Vector3d z = m.p_WM_W + 1e-3 * sim::Draw3(N, rng);
    ASSERT_TRUE(same.UpdatePosition(t, z).ok());
    ASSERT_TRUE(bank.UpdatePosition(t, z).ok());
    EXPECT_NEAR(same.probabilities()[0], 0.5, 1e-15);
    EXPECT_NEAR((same.p_WM_W() - same.filters()[0].p_WM_W()).norm(), 0.0, 1e-15);
    if (k == 0) continue;  // the first sample initialises: no evidence
    const double fade = std::exp(-0.05 / 0.5);
    L0 = fade * L0 + bank.filters()[0].last_position_log_likelihood();
    L1 = fade * L1 + bank.filters()[1].last_position_log_likelihood();
    const double mu1 = 1.0 / (1.0 + std::exp(L0 - L1));
    EXPECT_NEAR(bank.probabilities()[1], mu1, 1e-12) << "sample " << k;
    const Eigen::Vector3d mix =
        (1.0 - mu1) * bank.filters()[0].p_WM_W() + mu1 * bank.filters()[1].p_WM_W();
    EXPECT_NEAR((bank.p_WM_W() - mix).norm(), 0.0, 1e-12);
  }
  EXPECT_GT(std::abs(L0 - L1), 1.0);  // the two models were told apart
}

// With μ_min > 0 the evidence is a Markov-switching prior's: before each sample's ℓ, no model's
// faded evidence may lie more than ln(1/μ_min) below the best's (each model keeps a prior weight
// of μ_min, as a model that may become the right one must), so a leader that starts failing is
// left after the samples it fails, however long it led. Recomputed here from the filters'
// log-likelihoods; the run is long enough that the lead of the fading sum alone passes the bound.
TEST(PositionKfBank, NoModelFallsFurtherBehindThanItsPriorWeightAllows) {
  PositionKfSettings a, b;
  a.position_gate_chi2 = b.position_gate_chi2 = 0.0;
  b.accel_sigma = 3.0;
  PositionKfBankSettings s;
  s.models = {a, b};
  s.evidence_tau = 0.5;
  s.min_probability = 1e-3;
  PositionKfBank bank(s);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> N(0.0, 1.0);
  double L[2] = {}, free_lead = 0.0, largest_free_lead = 0.0;
  const double fade = std::exp(-0.05 / 0.5), bound = std::log(1.0 / s.min_probability);
  for (int k = 0; k < 600; ++k) {
    const double t = 0.01 * k;
    const PushedMarker m = Pushed(t, N, rng);
    ASSERT_TRUE(bank.UpdateAccel(t, m.f_B, Eigen::Matrix3d::Identity()).ok());
    if (k % 5 != 0) continue;
    ASSERT_TRUE(bank.UpdatePosition(t, m.p_WM_W + 1e-3 * sim::Draw3(N, rng)).ok());
    if (k == 0) continue;  // the first sample initialises: no evidence
    double l[2];
    for (int i = 0; i < 2; ++i) l[i] = bank.filters()[i].last_position_log_likelihood();
    const double top = std::max(fade * L[0], fade * L[1]);
    for (int i = 0; i < 2; ++i) L[i] = std::max(fade * L[i], top - bound) + l[i];
    free_lead = fade * free_lead + (l[0] - l[1]);  // the fading sums' lead without the bound
    largest_free_lead = std::max(largest_free_lead, std::abs(free_lead));
    const double best = std::max(L[0], L[1]);
    const double w0 = std::max(std::exp(L[0] - best), s.min_probability),
                 w1 = std::max(std::exp(L[1] - best), s.min_probability);
    EXPECT_NEAR(bank.probabilities()[1], w1 / (w0 + w1), 1e-12) << "sample " << k;
    EXPECT_LE(std::abs(L[0] - L[1]), bound + std::abs(l[0] - l[1]) + 1e-12);
  }
  EXPECT_GT(largest_free_lead, 1.5 * bound);  // the bound was what held the lead (seen: 11.8)
}

// The evidence itself against a closed form: right after the sample that initialised a filter,
// P_pp = σ² I, so a second sample at the same time has S = 2σ² I and
// ℓ = −½ (|y|²/(2σ²) + 3 ln(2σ²) + 3 ln 2π), whatever the motion model.
TEST(PositionKfBank, TheEvidenceIsTheInnovationsGaussianLogLikelihood) {
  PositionKfSettings s;
  s.position_sigma = 2e-3;
  s.position_gate_chi2 = 0.0;
  for (const PositionKfSettings& m : DefaultBankModels(s)) {
    PositionKf kf(m);
    ASSERT_TRUE(kf.UpdatePosition(1.0, Eigen::Vector3d(0.1, 0.2, 0.3)).ok());
    EXPECT_EQ(kf.last_position_log_likelihood(), 0.0);
    const Eigen::Vector3d y(3e-3, -1e-3, 4e-3);
    ASSERT_TRUE(kf.UpdatePosition(1.0, Eigen::Vector3d(0.1, 0.2, 0.3) + y).ok());
    const double v = 2.0 * s.position_sigma * s.position_sigma;
    const double expected =
        -0.5 * (y.squaredNorm() / v + 3.0 * std::log(v) + 3.0 * std::log(2.0 * std::numbers::pi));
    EXPECT_NEAR(kf.last_position_log_likelihood(), expected, 1e-9 * std::abs(expected));
  }
}

// The default models take what belongs to the IMU and the cell from the base settings (a lag or a
// lever arm given to position_kf reaches both models), and their motion noise from their own.
TEST(PositionKfBank, EveryDefaultModelTakesTheImusLagFrameAndLeverArm) {
  PositionKfSettings base;
  base.earth = EarthFrame::kEnu;
  base.gravity = 9.80;
  base.position_sigma = 2e-4;
  base.accel_delay = 3e-3;
  base.lever_arm_B = Eigen::Vector3d(0.01, -0.02, 0.03);
  base.estimate_lever_arm = true;
  base.accel_sigma = 7.0;  // a motion noise: not the models'
  const std::vector<PositionKfSettings> models = DefaultBankModels(base);
  ASSERT_EQ(models.size(), 2u);
  for (const PositionKfSettings& m : models) {
    EXPECT_EQ(m.earth, base.earth);
    EXPECT_EQ(m.gravity, base.gravity);
    EXPECT_EQ(m.position_sigma, base.position_sigma);
    EXPECT_EQ(m.accel_delay, base.accel_delay);
    EXPECT_EQ(m.lever_arm_B, base.lever_arm_B);
    EXPECT_TRUE(m.estimate_lever_arm);
    EXPECT_NE(m.accel_sigma, base.accel_sigma);
  }
}

// A bank of one filter is that filter, bit for bit (position_kf's single-model mode runs as one).
TEST(PositionKfBank, ABankOfOneIsItsFilter) {
  PositionKfSettings s;
  s.accel_noise_adaptation_tau = 0.1;
  PositionKf kf(s);
  PositionKfBank bank(s);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> N(0.0, 1.0);
  for (int k = 0; k < 200; ++k) {
    const double t = 0.01 * k;
    const Eigen::Vector3d f = Eigen::Vector3d(0.3, 0.0, -kG) + 0.05 * sim::Draw3(N, rng);
    ASSERT_TRUE(kf.UpdateAccel(t, f, Eigen::Matrix3d::Identity()).ok());
    ASSERT_TRUE(bank.UpdateAccel(t, f, Eigen::Matrix3d::Identity()).ok());
    if (k % 5 != 0) continue;
    const Eigen::Vector3d z = Eigen::Vector3d(0.15 * t * t, 0.0, 0.0) + 1e-3 * sim::Draw3(N, rng);
    ASSERT_TRUE(kf.UpdatePosition(t, z).ok());
    ASSERT_TRUE(bank.UpdatePosition(t, z).ok());
    ASSERT_EQ(bank.probabilities()[0], 1.0);
    ASSERT_EQ(bank.p_WM_W(), kf.p_WM_W());
    ASSERT_EQ(bank.v_W(), kf.v_W());
    ASSERT_EQ(bank.position_velocity_covariance(), kf.position_velocity_covariance());
  }
  // [p; v]'s covariance is the state covariance's p and V entries (Eq. 27 order per axis).
  const Eigen::Matrix<double, 9, 9> P = kf.P();
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      EXPECT_EQ(kf.position_velocity_covariance()(a, b), P(3 * a, 3 * b));
      EXPECT_EQ(kf.position_velocity_covariance()(a, 3 + b), P(3 * a, 3 * b + 1));
      EXPECT_EQ(kf.position_velocity_covariance()(3 + a, 3 + b), P(3 * a + 1, 3 * b + 1));
    }
}

// The mixture's [p; v] mean and covariance against samples drawn from the mixture itself (pick a
// filter with its weight, draw from its Gaussian): 400 000 draws, seeded. Two models that disagree
// (the accelerometer-driven one told a biased accelerometer), so the spread of the means counts.
TEST(PositionKfBank, TheMixturesCovarianceIsThatOfDrawsFromTheMixture) {
  PositionKfSettings base;
  base.position_sigma = 1e-4;
  PositionKfBankSettings bs;
  bs.models = DefaultBankModels(base);
  for (PositionKfSettings& m : bs.models) {
    m.accel_noise_adaptation_tau = 0.0;  // constant noise: the driven model keeps its error
    m.accel_bias_walk = 0.0;
    m.position_gate_chi2 = 0.0;
  }
  bs.min_probability = 0.2;  // both weights well inside (0, 1), so both components are drawn
  PositionKfBank bank(bs);
  for (int k = 0; k < 100; ++k) {
    const double t = 0.01 * k;
    // 2 m/s² of accelerometer error the position does not show.
    ASSERT_TRUE(
        bank.UpdateAccel(t, Eigen::Vector3d(2.0, 0.0, -kG), Eigen::Matrix3d::Identity()).ok());
    if (k % 5 == 0) {
      ASSERT_TRUE(bank.UpdatePosition(t, Eigen::Vector3d(0.2, 0.1, 0.3)).ok());
    }
  }
  const std::vector<double>& mu = bank.probabilities();
  ASSERT_GT(std::min(mu[0], mu[1]), 0.1);
  Eigen::Matrix<double, 6, 1> mean_i[2];
  Eigen::Matrix<double, 6, 6> L_i[2];
  for (int i = 0; i < 2; ++i) {
    const PositionKf& f = bank.filters()[static_cast<size_t>(i)];
    mean_i[i] << f.p_WM_W(), f.v_W();
    L_i[i] = f.position_velocity_covariance().llt().matrixL();
  }
  // The components' means differ: the spread-of-means term d dᵀ is a good part of the covariance.
  const Eigen::Matrix<double, 6, 6> within =
      mu[0] * bank.filters()[0].position_velocity_covariance() +
      mu[1] * bank.filters()[1].position_velocity_covariance();
  ASSERT_GT((bank.position_covariance() - within.topLeftCorner<3, 3>()).norm(),
            0.3 * bank.position_covariance().norm());
  std::mt19937_64 rng(11);
  std::normal_distribution<double> N(0.0, 1.0);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const int n = 400'000;
  Eigen::Matrix<double, 6, 1> sum = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 6> sum2 = Eigen::Matrix<double, 6, 6>::Zero();
  for (int k = 0; k < n; ++k) {
    const int i = U(rng) < mu[0] ? 0 : 1;
    Eigen::Matrix<double, 6, 1> w;
    for (int a = 0; a < 6; ++a) w(a) = N(rng);
    const Eigen::Matrix<double, 6, 1> x = mean_i[i] + L_i[i] * w;
    sum += x;
    sum2 += x * x.transpose();
  }
  const Eigen::Matrix<double, 6, 1> mean = sum / n;
  const Eigen::Matrix<double, 6, 6> cov = sum2 / n - mean * mean.transpose();
  const Eigen::Matrix<double, 6, 6> C = bank.position_velocity_covariance();
  Eigen::Matrix<double, 6, 1> expected_mean;
  expected_mean << bank.p_WM_W(), bank.v_W();
  for (int a = 0; a < 6; ++a) {
    // Sampling error of a mean: σ/√n; of a variance: about √2 σ²/√n (and more for a mixture).
    EXPECT_NEAR(mean(a), expected_mean(a), 5.0 * std::sqrt(C(a, a) / n)) << a;
    EXPECT_NEAR(cov(a, a), C(a, a), 0.03 * C(a, a)) << a;
  }
  EXPECT_NEAR((cov - C).norm() / C.norm(), 0.0, 0.03);
  EXPECT_EQ(bank.position_covariance(), (C.topLeftCorner<3, 3>()));
}

TEST(PositionKfBank, RefusesSettingsThatCannotWeigh) {
  PositionKfBankSettings s;
  s.evidence_tau = 0.0;
  EXPECT_THROW(PositionKfBank{s}, std::invalid_argument);
  s.evidence_tau = std::nan("");
  EXPECT_THROW(PositionKfBank{s}, std::invalid_argument);
  s.evidence_tau = 1.0;
  s.min_probability = 1.0;
  EXPECT_THROW(PositionKfBank{s}, std::invalid_argument);
  s.min_probability = 1e-3;
  EXPECT_EQ(PositionKfBank{s}.filters().size(), 2u);  // the default models
}

// A tool swaying smoothly (sinusoids, up to 1.2 m/s²) while it turns (swinging_tool.hpp).
swing::SwingState SwayingTool(double t) {
  return swing::SwingingTool(t, Eigen::Vector3d(0.3, 0.2, 0.15));
}

// The swaying tool under a wandering 7 mrad orientation error,
// navigation-grade accelerometer, 20 Hz tracker with 0.5 mm per axis; from 20 s to 30 s the
// accelerometer has 3 m/s² more white error (vibration). In the calm phases the
// accelerometer-driven model is well ahead of the paper's (0.81 against 1.16 mm) and the bank
// gives it nearly all the weight; in the bad one the two are close (2.52 against 2.69 mm; the
// paper's was ahead until the driven model integrated the accelerometer by the trapezoid) and the
// bank, on the evidence of the innovations, spreads its weight (0.57 on the driven model) and
// is closer than either. Within 10 % of the better filter in every phase, better than either
// over the whole run. 5 seeds; against the simulated truth.
TEST(PositionKfBank, FollowsTheBetterModelAsTheAccelerometerChanges) {
  PositionKfSettings base;
  base.earth = EarthFrame::kEnu;
  base.position_sigma = 5e-4;
  PositionKfBankSettings bs;
  bs.models = DefaultBankModels(base);
  // [phase][0 bank, 1 paper, 2 driven] squared errors; phases: calm (10–20 s), bad (20–30 s),
  // calm again (35–45 s); the driven model's weight per phase.
  double se[3][3] = {}, weight[3] = {};
  int n[3] = {};
  for (std::uint64_t seed = 1; seed <= 5; ++seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> N(0.0, 1.0);
    PositionKfBank bank(bs);
    Eigen::Vector3d dtheta = 7e-3 * sim::Draw3(N, rng);
    for (int k = 0; k < 4500; ++k) {
      const double t = k * 0.01;
      const swing::SwingState s = SwayingTool(t);
      const auto& [p, a, R_EB] = s;
      const double phi = std::exp(-0.01 / 2.0);
      dtheta = phi * dtheta + 7e-3 * std::sqrt(1 - phi * phi) * sim::Draw3(N, rng);
      Eigen::Vector3d f_B = swing::Accelerometer(s, k, false, 6e-3, N, rng);
      if (t >= 20.0 && t < 30.0) f_B += 3.0 * sim::Draw3(N, rng);
      ASSERT_TRUE(bank.UpdateAccel(t, f_B, geometry::Exp(dtheta) * R_EB).ok());
      if (k % 5 == 0) {
        ASSERT_TRUE(bank.UpdatePosition(t, p + 5e-4 * sim::Draw3(N, rng)).ok());
      }
      const int ph = t >= 10.0 && t < 20.0 ? 0 : t >= 20.0 && t < 30.0 ? 1 : t >= 35.0 ? 2 : -1;
      if (ph < 0 || !bank.initialized()) continue;
      se[ph][0] += (bank.p_WM_W() - p).squaredNorm();
      se[ph][1] += (bank.filters()[0].p_WM_W() - p).squaredNorm();
      se[ph][2] += (bank.filters()[1].p_WM_W() - p).squaredNorm();
      weight[ph] += bank.probabilities()[1];
      ++n[ph];
    }
  }
  double whole[3] = {};
  for (int ph = 0; ph < 3; ++ph) {
    for (int m = 0; m < 3; ++m) whole[m] += se[ph][m];
    const double bank = std::sqrt(se[ph][0] / n[ph]) * 1e3,
                 paper = std::sqrt(se[ph][1] / n[ph]) * 1e3,
                 driven = std::sqrt(se[ph][2] / n[ph]) * 1e3;
    std::printf(
        "phase %d: RMSE bank %.3f mm, paper's model %.3f mm, accelerometer-driven %.3f mm; "
        "weight of the driven %.2f\n",
        ph, bank, paper, driven, weight[ph] / n[ph]);
    EXPECT_LT(bank, 1.1 * std::min(paper, driven)) << "phase " << ph;
    if (ph != 1) {
      EXPECT_LT(driven, 0.8 * paper) << "calm phase " << ph;  // the premise
      EXPECT_GT(weight[ph] / n[ph], 0.9) << "phase " << ph;
    } else {
      EXPECT_LT(std::abs(driven / paper - 1.0), 0.1);  // the premise: close
      EXPECT_LT(bank, std::min(paper, driven));
      EXPECT_LT(weight[ph] / n[ph], 0.75);  // the evidence moved
    }
  }
  EXPECT_LT(whole[0], whole[1]);
  EXPECT_LT(whole[0], whole[2]);
}

// The default models carry the accelerometer gate kBankAccelGateChi2 and take back what the
// positions show wrong (accel_rollback_span): taps (one 100 Hz sample of 60 m/s² on one axis every
// 2 s, as BROAD's tapping trial) on the swaying tool are refused by the gate at once, each counted,
// and the bank stays with the marker. Taking back alone (ungated) holds too, less close: it acts
// only at the next position sample; with neither, every tap pushes the bank off. 3 seeds; against
// the simulated truth and a tracker of 0.5 mm per axis at 20 Hz.
TEST(PositionKfBank, TheDefaultModelsTakeBackTapsTheMotionCannotHave) {
  PositionKfSettings base;
  base.earth = EarthFrame::kEnu;
  base.position_sigma = 5e-4;
  PositionKfBankSettings banks[3];  // the default, taking back alone (ungated), neither
  for (PositionKfBankSettings& b : banks) b.models = DefaultBankModels(base);
  for (const PositionKfSettings& m : banks[0].models) {
    EXPECT_EQ(m.accel_gate_chi2, kBankAccelGateChi2);
    EXPECT_GT(m.accel_rollback_span, 0.0);
  }
  for (PositionKfSettings& m : banks[1].models) m.accel_gate_chi2 = 0.0;
  for (PositionKfSettings& m : banks[2].models) {
    m.accel_gate_chi2 = 0.0;
    m.accel_rollback_span = 0.0;
  }
  double se[3] = {}, se_tracker = 0;
  int n = 0, n_tracker = 0;
  std::int64_t taps = 0, rollbacks[2] = {}, refused[2] = {};
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> N(0.0, 1.0);
    std::vector<PositionKfBank> bank;
    for (const PositionKfBankSettings& b : banks) bank.emplace_back(b);
    for (int k = 0; k < 3000; ++k) {
      const double t = k * 0.01;
      const swing::SwingState s = SwayingTool(t);
      const auto& [p, a, R_EB] = s;
      const Eigen::Vector3d f_B = swing::Accelerometer(s, k, true, 6e-3, N, rng);
      taps += swing::IsTap(k);
      for (PositionKfBank& b : bank) ASSERT_TRUE(b.UpdateAccel(t, f_B, R_EB).ok());
      if (k % 5 == 0) {
        const Eigen::Vector3d z = p + 5e-4 * sim::Draw3(N, rng);
        for (PositionKfBank& b : bank) ASSERT_TRUE(b.UpdatePosition(t, z).ok());
        if (t >= 5.0) {
          se_tracker += (z - p).squaredNorm();
          ++n_tracker;
        }
      }
      if (t < 5.0) continue;
      for (int i = 0; i < 3; ++i) se[i] += (bank[i].p_WM_W() - p).squaredNorm();
      ++n;
    }
    for (size_t i = 0; i < 2; ++i) {
      refused[i] += bank[0].filters()[i].counters().accel_rejected;
      rollbacks[i] += bank[1].filters()[i].counters().accel_rollbacks;
      EXPECT_EQ(bank[1].filters()[i].counters().accel_rejected, 0);
      EXPECT_EQ(bank[2].filters()[i].counters().accel_rollbacks, 0);
    }
  }
  double mm[3];
  for (int i = 0; i < 3; ++i) mm[i] = std::sqrt(se[i] / n) * 1e3;
  const double tracker_mm = std::sqrt(se_tracker / n_tracker) * 1e3;
  std::printf(
      "taps of 60 m/s^2: bank RMSE %.3f mm by default (refused %lld and %lld), %.3f mm taking "
      "back alone (%lld and %lld times), %.3f mm with neither; tracker %.3f mm; %lld taps\n",
      mm[0], static_cast<long long>(refused[0]), static_cast<long long>(refused[1]), mm[1],
      static_cast<long long>(rollbacks[0]), static_cast<long long>(rollbacks[1]), mm[2], tracker_mm,
      static_cast<long long>(taps));
  EXPECT_LT(mm[0], tracker_mm);        // closer than the tracker it fuses…
  EXPECT_LT(mm[1], 1.5 * tracker_mm);  // …taking back alone within half as much again…
  EXPECT_GT(mm[2], 3.0 * tracker_mm);  // …where every tap pushes the bank off
  // The paper's model refuses every tap; the accelerometer-driven one nearly every: its
  // acceleration may leave the last sample by the jerk noise (50 m/s³/√Hz) times λ, so while λ is
  // above 12.7 (60²/11.34/(50² · 0.01 s)) a 60 m/s² tap is within what it predicts (seen at the
  // gate 11.34: 45 of 45 for both; at 16.27 the accelerometer-driven one let 2 through). Nothing
  // else is refused: the adaptive noise keeps the calm samples well inside the gate (seen: not one
  // of the 9 000 beyond the taps).
  EXPECT_GE(refused[0], taps);
  EXPECT_GE(refused[1], taps * 9 / 10);
  for (std::int64_t r : refused) EXPECT_LE(r, taps + 9);
  // Ungated, each model takes back each tap once, when the next position sample shows it.
  for (std::int64_t r : rollbacks) {
    EXPECT_GE(r, taps * 9 / 10);
    EXPECT_LE(r, 2 * taps);
  }
}

}  // namespace
}  // namespace rcal::estimation
