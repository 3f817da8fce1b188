// The pose pipeline on synthetic streams with a known truth: still stops at known poses joined
// by constant-rate moves (gyro consistent with the rotation), white sensor noise of an Xsens
// MTi-100 class IMU and a 0.5 mm position sensor. Checks: one pose per stop, its error against
// the truth consistent with its covariance (NEES, χ² band), bad input refused with a reason.
// And on the simulated cell's streams (minimum-jerk moves, the sensor level of the live
// pipeline): a pipeline started anywhere (a restarted still_window) gives, after its warm-up,
// the windows of the one that ran from the start.
#include "rcal/estimation/pose_pipeline.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <random>

#include "rcal/cell/sim_cell.hpp"
#include "rcal/estimation/fqa.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/sim/draw.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/sim/sensor_sim.hpp"
#include "rcal/sim/trajectory.hpp"

namespace rcal::estimation {
namespace {

struct Stop {
  Eigen::Matrix3d R_EI;
  Eigen::Vector3d p_W;
};

struct Outcome {
  std::vector<StillPose> poses;
  std::vector<Stop> stops;
  std::int64_t dropped = 0;  // windows dropped by the pipeline
  std::int64_t heading_disagreements = 0;
};

// χ²(k) quantile by Wilson–Hilferty, k (1 − 2/(9k) + z √(2/(9k)))³, z the standard normal
// quantile: relative error < 1e-3 for k ≥ 100 (this test links no rcal_identification).
double ChiSquareQuantileWh(double z, double k) {
  const double h = 2.0 / (9.0 * k);
  return k * std::pow(1.0 - h + z * std::sqrt(h), 3);
}

// `inject`, when given, is called after every regular sample (at its time t) to add bad input.
// `position_loss`: the fraction of position samples lost (independently, seeded).
// `accel_bias_walk` [m/s²/√s]: the accelerometer's bias walks from 0 at the first sample;
// `settings` the pipeline's.
Outcome Simulate(int num_stops, unsigned seed, double still_s = 1.5, double move_s = 1.0,
                 const std::function<void(PosePipeline&, double)>& inject = {},
                 double position_loss = 0.0, double accel_bias_walk = 0.0,
                 const PosePipelineSettings& settings = {},
                 const std::function<Eigen::Vector3d(int)>& mag_disturbance_E = {}) {
  std::mt19937_64 rng(seed), rng_loss(seed + 1000), rng_bias(seed + 2000);
  std::bernoulli_distribution lost(position_loss);
  std::normal_distribution<double> n(0, 1);
  auto n3 = [&] { return sim::Draw3(n, rng); };
  const double dt = 0.01;
  const Eigen::Vector3d g_E(0, 0, 9.81), m_E(20, 0, 44);
  const double sg = 0.01 * M_PI / 180 * 10, sa = 60e-6 * 9.81 * 10, sm = 0.02 * 10, sp = 5e-4;
  Outcome o;
  for (int k = 0; k < num_stops; ++k)
    o.stops.push_back({geometry::Exp(0.8 * n3()), Eigen::Vector3d(1, 0.2, 0.5) + 0.3 * n3()});
  PosePipeline pipe(settings);
  double t = 0;
  Eigen::Vector3d b_a = Eigen::Vector3d::Zero();  // accelerometer bias [m/s²]
  Eigen::Vector3d d_E = Eigen::Vector3d::Zero();  // field disturbance of the current stop [µT]
  auto sample = [&](const Eigen::Matrix3d& R, const Eigen::Vector3d& p, const Eigen::Vector3d& w_I,
                    const Eigen::VectorXd& q) {
    if (t > 0) b_a += accel_bias_walk * std::sqrt(dt) * sim::Draw3(n, rng_bias);
    ASSERT_TRUE(pipe.AddJoints(t, q));
    ASSERT_TRUE(pipe.AddImu(t, w_I + sg * n3(), -R.transpose() * g_E + sa * n3() + b_a,
                            R.transpose() * (m_E + d_E) + sm * n3()));
    const Eigen::Vector3d p_meas = p + sp * n3();
    if (!lost(rng_loss)) {
      ASSERT_TRUE(pipe.AddPosition(t, p_meas));
    }
    if (inject) inject(pipe, t);
    t += dt;
  };
  for (int k = 0; k < num_stops; ++k) {
    const Eigen::VectorXd q = Eigen::VectorXd::Constant(6, 0.1 * k);
    if (mag_disturbance_E) d_E = mag_disturbance_E(k);
    for (int i = 0; i < static_cast<int>(still_s / dt); ++i)
      sample(o.stops[k].R_EI, o.stops[k].p_W, Eigen::Vector3d::Zero(), q);
    d_E.setZero();
    if (k + 1 == num_stops) break;
    // Move: constant body rate to the next orientation, straight line in position. Sample i
    // of the move is the end of its i+1-th interval: the gyro reads the rate over the interval
    // ending at its sample (the filter's convention), so the first moving sample has already
    // turned by ω·dt and its joints have moved. (Sampling at i/steps made the first moving
    // sample read the rate while pose and joints were still those of the stop: the window took
    // it, the filter turned by ω·dt that the truth did not, and the window NEES read 9.4.)
    const Eigen::Vector3d w_I =
        geometry::Log(o.stops[k].R_EI.transpose() * o.stops[k + 1].R_EI) / move_s;
    const int steps = static_cast<int>(move_s / dt);
    for (int i = 0; i < steps; ++i) {
      const double s = static_cast<double>(i + 1) / steps;
      const Eigen::Matrix3d R = o.stops[k].R_EI * geometry::Exp(w_I * s * move_s);
      const Eigen::Vector3d p = (1 - s) * o.stops[k].p_W + s * o.stops[k + 1].p_W;
      sample(R, p, w_I, Eigen::VectorXd::Constant(6, 0.1 * k + 0.1 * s));
    }
  }
  pipe.Flush();
  o.poses = pipe.TakePoses();
  o.dropped = pipe.counters().windows_dropped;
  o.heading_disagreements = pipe.counters().heading_disagreements;
  return o;
}

// Window NEES over the poses of `o` against its stops, with its two-sided χ² band at a
// false-alarm rate of 1e-3 (see OnePosePerStopWithAConsistentCovariance).
struct NeesBand {
  double nees, lo, hi;
  double hotelling;  // the mean Hotelling factor of the windows' scatter covariances
};
NeesBand WindowNees(const Outcome& o) {
  double nees = 0, hotelling = 0;
  for (size_t k = 0; k < o.poses.size(); ++k) {
    const StillPose& p = o.poses[k];
    Eigen::Matrix<double, 6, 1> r;
    r.head<3>() = p.p_WM_W - o.stops[k + 1].p_W;
    r.tail<3>() = geometry::Log(p.R_EI * o.stops[k + 1].R_EI.transpose());
    nees += r.dot(p.covariance.ldlt().solve(r));
    const double mp = p.position_samples, mr = p.orientation_samples;
    hotelling += (3 * (mp - 1) / (mp - 5) + 3 * (mr - 1) / (mr - 5)) / 6;
  }
  const double n = static_cast<double>(o.poses.size());
  return {nees / n, ChiSquareQuantileWh(-3.2905, 6 * n) / n,
          hotelling / n * ChiSquareQuantileWh(3.2905, 6 * n) / n, hotelling / n};
}

// Half the position samples lost: the window is then ~40 raw positions, and its position must
// be their mean, the estimate the covariance (their scatter / N) describes. The position KF's
// mean over the window also weighs the end of the move, carried by the accelerometer, and that
// part grows as samples are lost while the raw scatter does not see it (that window NEES: 8.7
// for 6.3 in the sensor experiment's 50 % dropout runs; here 9.6, outside the band).
TEST(PosePipeline, ConsistentCovarianceWithHalfThePositionSamplesLost) {
  const Outcome o = Simulate(101, 7, 1.5, 1.0, {}, 0.5);
  ASSERT_EQ(o.poses.size() + 1, o.stops.size());
  const Outcome full = Simulate(101, 7);
  double kept = 0, all = 0;
  for (const StillPose& p : o.poses) kept += p.position_samples;
  for (const StillPose& p : full.poses) all += p.position_samples;
  EXPECT_NEAR(kept / all, 0.5, 0.02);
  const NeesBand b = WindowNees(o);
  std::printf("50 %% position loss: window NEES %.3f, band [%.3f, %.3f]\n", b.nees, b.lo, b.hi);
  EXPECT_GT(b.nees, b.lo);
  EXPECT_LT(b.nees, b.hi);
}

// The accelerometer bias's covariance is the FQA's own response to a bias: finite differences
// of the FQA (central, 1e-4 m/s²) at orientations drawn at random, in NED and ENU, against the
// closed form σ² A Aᵀ.
TEST(PosePipeline, TheAccelerometerBiasCovarianceIsTheFqasResponseToABias) {
  std::mt19937_64 rng(11);
  std::normal_distribution<double> n(0, 1);
  const double g = 9.81, dip = std::atan2(44.0, 20.0), sigma = 2e-3;
  for (EarthFrame earth : {EarthFrame::kNed, EarthFrame::kEnu}) {
    FqaSettings fs;
    fs.earth = earth;
    fs.m_ref_E = MagneticNorth(earth);
    const Eigen::Vector3d u = UpVector(earth), north = MagneticNorth(earth);
    const Eigen::Vector3d m_E = 20.0 * north - 44.0 * u;  // 20 µT north, 44 µT down
    for (int trial = 0; trial < 5; ++trial) {
      const Eigen::Matrix3d R_EB = geometry::Exp(1.5 * sim::Draw3(n, rng));
      const Eigen::Vector3d f_B = R_EB.transpose() * (g * u), m_B = R_EB.transpose() * m_E;
      const Eigen::Matrix3d R0 = geometry::QuatToMatrix(*Fqa(f_B, m_B, fs));
      ASSERT_LT(geometry::Log(R0 * R_EB.transpose()).norm(), 1e-9);
      Eigen::Matrix3d J;  // ∂δθ_E / ∂b_E
      const double h = 1e-4;
      for (int j = 0; j < 3; ++j) {
        const Eigen::Vector3d db_B = R_EB.transpose() * (h * Eigen::Vector3d::Unit(j));
        const Eigen::Matrix3d Rp = geometry::QuatToMatrix(*Fqa(f_B + db_B, m_B, fs));
        const Eigen::Matrix3d Rm = geometry::QuatToMatrix(*Fqa(f_B - db_B, m_B, fs));
        J.col(j) =
            (geometry::Log(Rp * R0.transpose()) - geometry::Log(Rm * R0.transpose())) / (2 * h);
      }
      const Eigen::Matrix3d C = AccelBiasOrientationCovariance(earth, g, dip, sigma);
      const Eigen::Matrix3d C_fd = sigma * sigma * J * J.transpose();
      EXPECT_LT((C - C_fd).norm(), 1e-6 * C_fd.norm()) << C << "\n\n" << C_fd;
      // The dip couples tilt into heading: the FQA's heading variance is tan²(dip) σ²/g² (4.8×
      // the tilt's; 0 if the coupling were missing).
      EXPECT_NEAR(C_fd(2, 2) * g * g / (sigma * sigma), std::pow(std::tan(dip), 2), 1e-3);
    }
  }
  // No magnetometer dip, no heading coupling: the heading row and column are zero.
  const Eigen::Matrix3d C0 = AccelBiasOrientationCovariance(EarthFrame::kNed, g, 0.0, sigma);
  EXPECT_EQ(C0.row(2).norm(), 0.0);
  EXPECT_NEAR(C0(0, 0), sigma * sigma / (g * g), 1e-15);
}

// An accelerometer bias walking at 2e-4 m/s²/√s (over the ~250 s of 101 stops, ~3e-3 m/s²: a
// tilt of 3e-4 rad against a window scatter of 6e-5 rad): the windows are consistent when the
// pipeline is told the walk, and beyond the band when it is not (the control).
// The band. Every window of a run shares one bias path, so a run's mean NEES is not χ²(6n)/n:
// its tilt part is, per horizontal axis, X = (1/n) Σ W(t_k)²/t_k for a Brownian W, E[X] = 1 and
// Var[X] = 2 ∫∫ min(s, t)²/(s t) = 1 (windows spread evenly in time). Over K independent runs the
// mean NEES has mean 6·(Hotelling factor) and variance (2 + 12/n)/K at most (bias dominating the
// tilt); the band is that ± 3.29 σ (false-alarm rate 1e-3).
TEST(PosePipeline, ConsistentCovarianceUnderAnAccelerometerBiasWalk) {
  const double walk = 2e-4;
  const int runs = 8;
  PosePipelineSettings told;
  told.accel_bias_random_walk = walk;
  double nees = 0, control = 0, expected = 0, n = 0;
  for (int k = 0; k < runs; ++k) {
    const Outcome o = Simulate(101, 40 + k, 1.5, 1.0, {}, 0.0, walk, told);
    const NeesBand b = WindowNees(o);
    nees += b.nees / runs;
    expected += 6.0 * b.hotelling / runs;
    n = static_cast<double>(o.poses.size());
    control += WindowNees(Simulate(101, 40 + k, 1.5, 1.0, {}, 0.0, walk)).nees / runs;
  }
  const double half = 3.2905 * std::sqrt((2.0 + 12.0 / n) / runs);
  std::printf(
      "accelerometer bias walk: window NEES %.3f over %d runs (not told: %.3f), band "
      "[%.3f, %.3f]\n",
      nees, runs, control, expected - half, expected + half);
  EXPECT_GT(nees, expected - half);
  EXPECT_LT(nees, expected + half);
  EXPECT_GT(control, expected + half);
}

// A disturbance that turns the horizontal field by 0.7 rad at every fifth stop, its norm and dip
// unchanged (what the magnetometer's own tests cannot see): the windows stay consistent, their
// heading variance grown by the disagreement with the stop's start; without the check (the
// control) they are 0.7 rad off at a 1e-3 rad σ.
TEST(PosePipeline, ConsistentCovarianceUnderADisturbanceTheFieldTestsCannotSee) {
  const Eigen::Vector3d m_h(20, 0, 0);  // the simulation's horizontal field (north, µT)
  const Eigen::Vector3d d_E = geometry::Exp(Eigen::Vector3d(0, 0, 0.7)) * m_h - m_h;
  const auto disturbance = [&](int stop) { return stop % 5 == 2 ? d_E : Eigen::Vector3d::Zero(); };
  PosePipelineSettings off;
  off.heading_consistency_chi2 = 0.0;
  const Outcome o = Simulate(101, 7, 1.5, 1.0, {}, 0.0, 0.0, {}, disturbance);
  const Outcome control = Simulate(101, 7, 1.5, 1.0, {}, 0.0, 0.0, off, disturbance);
  const NeesBand b = WindowNees(o), c = WindowNees(control);
  std::printf(
      "heading disturbance at 20 stops: window NEES %.3f (check off: %.1f), band "
      "[%.3f, %.3f], %lld windows inflated\n",
      b.nees, c.nees, b.lo, b.hi, static_cast<long long>(o.heading_disagreements));
  EXPECT_GT(b.nees, b.lo);
  EXPECT_LT(b.nees, b.hi);
  EXPECT_GT(c.nees, c.hi);
  // Every disturbed window, and at a 1e-3 false-alarm rate hardly another (P(> 2 of 80) < 1e-4).
  EXPECT_GE(o.heading_disagreements, 20);
  EXPECT_LE(o.heading_disagreements, 22);
}

TEST(PosePipeline, OnePosePerStopWithAConsistentCovariance) {
  const Outcome o = Simulate(101, 7);
  // The first stop's window is the filters' warm-up (rest_from_joints): dropped, counted.
  ASSERT_EQ(o.poses.size() + 1, o.stops.size());
  EXPECT_EQ(o.dropped, 1);
  // No disturbance: the heading check (false-alarm rate 1e-3) widens hardly any window.
  EXPECT_LE(o.heading_disagreements, 2);
  double nees = 0, hotelling = 0;
  for (size_t k = 0; k < o.poses.size(); ++k) {
    const StillPose& p = o.poses[k];
    const Stop& stop = o.stops[k + 1];
    ASSERT_TRUE(p.has_orientation);
    ASSERT_EQ(p.covariance.rows(), 6);
    EXPECT_NEAR(p.q(0), 0.1 * (k + 1), 1e-12);
    Eigen::Matrix<double, 6, 1> r;
    r.head<3>() = p.p_WM_W - stop.p_W;
    r.tail<3>() = geometry::Log(p.R_EI * stop.R_EI.transpose());
    EXPECT_LT(r.head<3>().norm(), 5e-4);              // far below one sample's 0.5 mm
    EXPECT_LT(r.tail<3>().norm(), 0.2 * M_PI / 180);  // 0.2°
    nees += r.dot(p.covariance.ldlt().solve(r));
    // The covariance is estimated from the scatter of m raw samples per 3-dof block: the NEES
    // of a block is then Hotelling's T², mean 3 (m − 1)/(m − 5), not 3 (m ≈ 80: 5 % more).
    const double mp = p.position_samples, mr = p.orientation_samples;
    ASSERT_GT(std::min(mp, mr), 10);
    hotelling += (3 * (mp - 1) / (mp - 5) + 3 * (mr - 1) / (mr - 5)) / 6;
    // The identifier's measurement carries the window unchanged.
    const kinematics::PoseMeasurement z = p.ToMeasurement();
    EXPECT_EQ(z.q, p.q);
    EXPECT_EQ(z.p_WM_W, p.p_WM_W);
    EXPECT_EQ(z.R_EI, p.R_EI);
    EXPECT_EQ(z.covariance, p.covariance);
    EXPECT_EQ(z.dimension(), 6);
  }
  // With a known covariance, n·mean NEES ~ χ²(6n). Two-sided band at a false-alarm rate of
  // 1e-3 (z = ±3.2905): [χ²_0.0005(6n), χ²_0.9995(6n)]/n, the upper edge raised by the
  // Hotelling factor above (the window mean also averages the filters' memory of the 0.2 s
  // settle samples, so the honest mean lies between 6 and 6 × that factor; 6.17 over 1600
  // windows of 40 seeds). n = 100: [4.93, 7.59]; a covariance 1.6× too small (mean ≈ 9.9) or
  // too large (≈ 3.9) fails. The old band [3, 10] accepted 9.37 (40 windows, with the
  // move-sampling error in Simulate above).
  const double n = static_cast<double>(o.poses.size());
  nees /= n;
  hotelling /= n;
  const double lo = ChiSquareQuantileWh(-3.2905, 6 * n) / n,
               hi = hotelling * ChiSquareQuantileWh(3.2905, 6 * n) / n;
  std::printf("window NEES %.3f over %.0f windows, band [%.3f, %.3f] (Hotelling factor %.4f)\n",
              nees, n, lo, hi, hotelling);
  EXPECT_GT(nees, lo);
  EXPECT_LT(nees, hi);
}

// The simulated cell's sensor streams (as sensor_acquisition --source sim --level sensors
// publishes them, seed 1): home, then 20 stops of 1.5 s joined by minimum-jerk moves, 100 Hz.
const std::vector<sim::SensorFrame>& CellStream() {
  static const std::vector<sim::SensorFrame> frames = [] {
    const auto robot = io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
    const cell::Cell c = cell::MakeCell(robot.spec, 1);
    sim::Rng rng(1003);
    std::vector<Eigen::VectorXd> waypoints = {sim::SampleJoints(c.model, 1, rng).front()};
    for (const auto& q : sim::SampleJoints(c.model, 20, rng)) waypoints.push_back(q);
    sim::TrajectorySettings ts;
    ts.still_time = 1.5;
    static const sim::ToolMotionTruth truth(c.model, c.x_true, sim::JointTrajectory(waypoints, ts));
    sim::SensorSim sensors(truth, sim::SensorSimSettings{}, 1);
    std::vector<sim::SensorFrame> out;
    while (auto f = sensors.Next()) out.push_back(*f);
    return out;
  }();
  return frames;
}

// Windows of a pipeline fed the cell stream from `start_s` on.
std::vector<StillPose> CellWindows(double start_s, const PosePipelineSettings& settings = {}) {
  PosePipeline pipe(settings);
  for (const auto& f : CellStream()) {
    if (f.t < start_s) continue;
    EXPECT_TRUE(pipe.AddJoints(f.t, f.q));
    EXPECT_TRUE(pipe.AddImu(f.t, f.imu.gyro_S, f.imu.accel_S, f.imu.mag_S));
    if (f.position) {
      EXPECT_TRUE(pipe.AddPosition(f.position->t, f.position->p_M));
    }
  }
  pipe.Flush();
  return pipe.TakePoses();
}

// The largest difference, in units of the window's own σ, between the windows of a pipeline
// started at each of `starts` and the same stops' windows of one started at 0 (position or
// orientation, whichever is larger); also checks that each started pipeline misses only the
// stop it started in (its warm-up) and the one in progress.
double WorstRestartDifference(const std::vector<double>& starts,
                              const PosePipelineSettings& settings) {
  const auto ref = CellWindows(0.0, settings);
  double worst = 0;
  for (const double start : starts) {
    const auto got = CellWindows(start, settings);
    size_t later = 0;
    for (const auto& r : ref) later += r.t_begin > start;
    EXPECT_GE(got.size() + 2, later) << "started at " << start << " s";
    for (const auto& w : got) {
      const StillPose* r = nullptr;
      for (const auto& c : ref)
        if ((c.q - w.q).norm() < 1e-3) r = &c;
      if (r == nullptr) {
        ADD_FAILURE() << "started at " << start << " s: window at " << w.t_end << " s is none "
                      << "of the uninterrupted pipeline's";
        continue;
      }
      const kinematics::PoseMeasurement z = r->ToMeasurement();
      const Eigen::Vector3d dp = w.p_WM_W - r->p_WM_W;
      for (int a = 0; a < 3; ++a)
        worst = std::max(worst, std::abs(dp(a)) / std::sqrt(z.covariance(a, a)));
      const double sigma_th = std::sqrt(z.covariance.bottomRightCorner<3, 3>().trace() / 3);
      worst = std::max(worst, geometry::Log(w.R_EI * r->R_EI.transpose()).norm() / sigma_th);
    }
  }
  return worst;
}

// Every 3.7 s over the programme's first ~110 s: in moves, at their starts and ends, in stops.
std::vector<double> RestartTimes() {
  std::vector<double> t;
  for (double s = 10.0; s < 120.0; s += 3.7) t.push_back(s);
  return t;
}

// A pipeline started anywhere (a still_window restarted by its supervisor) publishes, after its
// warm-up, the windows the uninterrupted one publishes: the same samples through filters that
// started from another state and converged at rest. Measured: 0.034 σ at worst over 380 start
// times. Bound 0.25 σ: a deterministic difference, not a draw. Before rest_from_joints (the
// control below) a start at the beginning of a move took the move's first 0.2 s for rest,
// learned a gyro bias of 0.03 rad/s and gave windows up to 5 σ off in heading (and 340 σ when
// the magnetic dip was learned in the move); the live kill test of still_window failed on it.
TEST(PosePipeline, StartedAnywhereItsWindowsAfterTheWarmUpAreTheUninterruptedOnes) {
  const double worst = WorstRestartDifference(RestartTimes(), {});
  std::printf("started at %zu times: worst window difference %.3f sigma\n", RestartTimes().size(),
              worst);
  EXPECT_LT(worst, 0.25);
}

TEST(PosePipeline, ControlRestFromTheImuAloneGivesBiasedWindowsAfterARestart) {
  PosePipelineSettings imu_rest;
  imu_rest.rest_from_joints = false;
  imu_rest.orientation.learn_in_motion = true;
  const double worst = WorstRestartDifference(RestartTimes(), imu_rest);
  std::printf("control (rest from the IMU, learning in motion): worst %.3f sigma\n", worst);
  EXPECT_GT(worst, 1.0);
}

TEST(PosePipeline, DeterministicForTheSameInput) {
  const Outcome a = Simulate(5, 3), b = Simulate(5, 3);
  ASSERT_EQ(a.poses.size(), b.poses.size());
  for (size_t k = 0; k < a.poses.size(); ++k) {
    EXPECT_EQ(a.poses[k].p_WM_W, b.poses[k].p_WM_W);
    EXPECT_EQ(a.poses[k].covariance, b.poses[k].covariance);
  }
}

// Issue 11: one IMU sample with a gyro of 1e300 rad/s made the orientation KF NaN for good and
// the pipeline produced no pose after it. Refused (beyond the sensor range), it changes nothing:
// the same poses, bit for bit, as without it.
TEST(PosePipeline, AGyroBeyondItsRangeIsRefusedAndChangesNoPose) {
  const Outcome clean = Simulate(6, 7);
  int refused = 0;
  const Outcome poisoned = Simulate(6, 7, 1.5, 1.0, [&](PosePipeline& pipe, double t) {
    if (std::abs(t - 4.0) > 1e-9 && std::abs(t - 6.3) > 1e-9) return;
    const Status s = pipe.AddImu(t, Eigen::Vector3d(1e300, 0, 0), Eigen::Vector3d(0, 0, 9.81),
                                 Eigen::Vector3d(20, 0, 44));
    EXPECT_FALSE(s);
    EXPECT_NE(s.error().find("gyro is beyond the sensor range"), std::string::npos) << s.error();
    ++refused;
  });
  EXPECT_EQ(refused, 2);
  ASSERT_EQ(poisoned.poses.size(), clean.poses.size());
  ASSERT_GE(clean.poses.size(), 4u);
  for (size_t i = 0; i < clean.poses.size(); ++i) {
    EXPECT_EQ(poisoned.poses[i].p_WM_W, clean.poses[i].p_WM_W) << i;
    EXPECT_EQ(poisoned.poses[i].covariance, clean.poses[i].covariance) << i;
  }
}

TEST(PosePipeline, RefusesBadInputNamingTheFieldAndKeepsGoing) {
  PosePipeline pipe;
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(6);
  ASSERT_TRUE(pipe.AddJoints(1.0, q));
  Status s = pipe.AddJoints(0.5, q);
  EXPECT_FALSE(s);
  EXPECT_NE(s.error().find("joints.t"), std::string::npos) << s.error();
  s = pipe.AddJoints(1.1, Eigen::VectorXd::Zero(5));
  EXPECT_NE(s.error().find("joints.q"), std::string::npos) << s.error();
  s = pipe.AddImu(1.1, Eigen::Vector3d(NAN, 0, 0), Eigen::Vector3d(0, 0, -9.81),
                  Eigen::Vector3d(20, 0, 44));
  EXPECT_NE(s.error().find("imu.gyro"), std::string::npos) << s.error();
  s = pipe.AddPosition(1.1, Eigen::Vector3d(0, INFINITY, 0));
  EXPECT_NE(s.error().find("position.p_WM_W"), std::string::npos) << s.error();
  EXPECT_EQ(pipe.counters().input_rejected, 4);
  EXPECT_TRUE(pipe.AddImu(1.1, Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, -9.81),
                          Eigen::Vector3d(20, 0, 44)));
  pipe.Reset();
  EXPECT_EQ(pipe.counters().input_rejected, 0);
  EXPECT_TRUE(pipe.AddJoints(0.0, q));  // time restarts after Reset
}

TEST(PosePipeline, StopsShorterThanDetectionAndSettlingGiveNoPose) {
  const Outcome o = Simulate(4, 11, /*still_s=*/0.6);  // 0.5 s detection + 0.2 s settle > 0.6 s
  EXPECT_TRUE(o.poses.empty());
}

}  // namespace
}  // namespace rcal::estimation
