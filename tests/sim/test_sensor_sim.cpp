// Sensor-level simulation against independent truth: the finite-difference velocities and rates
// against the analytic joint Jacobian, the acceleration against differences of that velocity,
// the IMU at rest against gravity and the earth field, the streams' determinism.
#include "rcal/sim/sensor_sim.hpp"

#include <gtest/gtest.h>

#include <numbers>

#include "rcal/geometry/so3.hpp"
#include "rcal/sim/effects.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::sim {
namespace {

constexpr double kPi = std::numbers::pi;

// GRB3016 (NOTES.md Table 1) with the set-up frames of a real cell.
kinematics::KinematicModel Cell() {
  kinematics::ModelBuilder b("grb3016");
  auto j = [](const char* n) {
    return kinematics::Joint{n, kinematics::JointType::kRevolute, -3, 3};
  };
  b.BaseFrame(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero());
  b.DhLink(0.150, -kPi / 2, 0.250, 0, j("j1"));
  b.DhLink(0.570, -kPi, 0, -kPi / 2, j("j2"));
  b.DhLink(0.150, kPi / 2, 0, 0, j("j3"));
  b.DhLink(0, -kPi / 2, 0.645, 0, j("j4"));
  b.DhLink(0, kPi / 2, 0, -kPi / 2, j("j5"));
  b.DhLink(0, 0, -0.200, 0, j("j6"));
  b.MarkerOffset(Eigen::Vector3d(0.03, 0, 0.12));
  b.ImuMounting(Eigen::Vector3d::Zero());
  b.EarthFrame(Eigen::Vector3d::Zero());
  return b.Build();
}

Eigen::VectorXd Truth(const kinematics::KinematicModel& m) {
  Eigen::VectorXd x = Table3Errors(m);
  x(m.FindParameter("base_x")) = 1.2;
  x(m.FindParameter("base_rz")) = 0.6;
  x(m.FindParameter("earth_rz")) = 0.9;
  x(m.FindParameter("earth_ry")) = 0.02;
  x(m.FindParameter("imu_rz")) = 0.3;
  return x;
}

JointTrajectory Program(const kinematics::KinematicModel& m, int stops, unsigned seed) {
  Rng rng(seed);
  return JointTrajectory(SampleJoints(m, stops, rng));
}

TEST(ToolMotionTruth, DerivativesMatchTheJointJacobian) {
  const auto m = Cell();
  const Eigen::VectorXd x = Truth(m);
  const ToolMotionTruth truth(m, x, Program(m, 4, 3));
  const Eigen::Matrix3d R_EW = geometry::FromRpy(Eigen::Vector3d(0, 0.02, 0.9));
  EXPECT_LT((truth.R_EW() - R_EW).norm(), 1e-12);
  int checked = 0;
  for (double t = 0.05; t < truth.trajectory().duration(); t += 0.173) {
    const ToolState s = truth.At(t);
    Eigen::VectorXd q, qd, qdd;
    truth.trajectory().Sample(t, q, &qd, &qdd);
    if (qd.norm() < 1e-3) continue;
    const Eigen::MatrixXd J = m.JointJacobian(q, x);  // world frame, tool (marker) origin
    const Eigen::Vector3d v = J.topRows(3) * qd;
    const Eigen::Vector3d w_W = J.bottomRows(3) * qd;
    const Eigen::Matrix3d R_WI = R_EW.transpose() * s.R_EI;
    EXPECT_LT((s.v_WM_W - v).norm(), 1e-5 * (1 + v.norm())) << t;
    EXPECT_LT((s.omega_I - R_WI.transpose() * w_W).norm(), 1e-5 * (1 + w_W.norm())) << t;
    // Acceleration: central difference of the closed-form velocity, a different step.
    const double h = 1e-4;
    Eigen::VectorXd qa, qda, qb, qdb;
    truth.trajectory().Sample(t + h, qa, &qda);
    truth.trajectory().Sample(t - h, qb, &qdb);
    const Eigen::Vector3d a =
        (m.JointJacobian(qa, x).topRows(3) * qda - m.JointJacobian(qb, x).topRows(3) * qdb) /
        (2 * h);
    EXPECT_LT((s.a_WM_W - a).norm(), 1e-3 * (1 + a.norm())) << t;
    // IMU truth: earth-frame quantities.
    const ImuTruth u = truth.Imu(s);
    EXPECT_LT((u.a_W - R_EW * s.a_WM_W).norm(), 1e-12);
    EXPECT_LT((u.R_WI - s.R_EI).norm(), 1e-12);
    ++checked;
  }
  EXPECT_GT(checked, 5);
}

// The IMU 13 cm from the marker (r_IM_I): its acceleration is the rigid body's at its own point,
// a_I = a_M − α × r_W − ω × (ω × r_W), r_W = R_WI r_IM_I, with ω, α and a_M from the closed-form
// joint Jacobian (another route than the truth's second differences of positions); without a
// lever arm the IMU's acceleration is the marker's, bit for bit.
TEST(ToolMotionTruth, AnImuOffTheMarkerFeelsTheRigidBodyAccelerationAtItsPoint) {
  const auto m = Cell();
  const Eigen::VectorXd x = Truth(m);
  ToolMotionTruth truth(m, x, Program(m, 4, 3));
  const ToolMotionTruth at_marker(m, x, Program(m, 4, 3));
  const Eigen::Vector3d r_IM_I(0.1, -0.05, 0.08);
  truth.set_imu_to_marker_I(r_IM_I);
  const Eigen::Matrix3d& R_EW = truth.R_EW();
  int checked = 0;
  double largest_lever_m_s2 = 0;
  for (double t = 0.05; t < truth.trajectory().duration(); t += 0.173) {
    const ToolState s = truth.At(t), s0 = at_marker.At(t);
    EXPECT_EQ(s0.a_WI_W, s0.a_WM_W);
    EXPECT_EQ(s0.p_WI_W, s0.p_WM_W);
    Eigen::VectorXd q, qd;
    truth.trajectory().Sample(t, q, &qd);
    if (qd.norm() < 1e-3) continue;
    const Eigen::Matrix3d R_WI = R_EW.transpose() * s.R_EI;
    const Eigen::Vector3d r_W = R_WI * r_IM_I;
    EXPECT_LT((s.p_WI_W - (s.p_WM_W - r_W)).norm(), 1e-12);
    const double h = 1e-4;
    Eigen::VectorXd qa, qda, qb, qdb;
    truth.trajectory().Sample(t + h, qa, &qda);
    truth.trajectory().Sample(t - h, qb, &qdb);
    const Eigen::MatrixXd Ja = m.JointJacobian(qa, x), Jb = m.JointJacobian(qb, x);
    const Eigen::Vector3d a_M = (Ja.topRows(3) * qda - Jb.topRows(3) * qdb) / (2 * h);
    const Eigen::Vector3d alpha_W = (Ja.bottomRows(3) * qda - Jb.bottomRows(3) * qdb) / (2 * h);
    const Eigen::Vector3d w_W = m.JointJacobian(q, x).bottomRows(3) * qd;
    const Eigen::Vector3d lever = alpha_W.cross(r_W) + w_W.cross(w_W.cross(r_W));
    const Eigen::Vector3d a_I = a_M - lever;
    largest_lever_m_s2 = std::max(largest_lever_m_s2, lever.norm());
    EXPECT_LT((s.a_WI_W - a_I).norm(), 1e-3 * (1 + a_I.norm())) << t;
    EXPECT_LT((truth.Imu(s).a_W - R_EW * s.a_WI_W).norm(), 1e-12);
    EXPECT_LT((truth.Imu(s).p_W - R_EW * s.p_WI_W).norm(), 1e-12);
    ++checked;
  }
  EXPECT_GT(checked, 5);
  EXPECT_GT(largest_lever_m_s2, 0.05);  // the lever arm's terms are there to be found
}

// An arm that grows with time (thermal by time, ρ [1/s], t_ref 0): every length scales by
// 1 + ρ t, so at a still stop the marker moves along a straight line at a constant rate (the
// position is affine in the scale): equal steps over equal times, the velocity that rate, no
// acceleration; at t = 0 it is the geometric arm. A model that is not the truth's is refused.
TEST(ToolMotionTruth, AnArmGrowingWithTimeDriftsStraightAtAStillStop) {
  const auto m = Cell();
  const Eigen::VectorXd x = Truth(m);
  const ToolMotionTruth plain(m, x, Program(m, 4, 3));
  ToolMotionTruth grows = plain;
  const EffectTruth et = MakeEffectTruth(m, {ParseEffectSpec("thermal:time=1e-5", m)});
  grows.set_effects(et.model, et.e, [](double t) {
    kinematics::EffectContext c;
    c.time_s = t;
    return c;
  });
  const auto [t_in, t_out] = grows.trajectory().StillInterval(2);
  ASSERT_GT(t_out - t_in, 0.6);
  const double t1 = t_in + 0.1, dt = 0.2;
  const ToolState s1 = grows.At(t1), s2 = grows.At(t1 + dt), s3 = grows.At(t1 + 2 * dt);
  const Eigen::Vector3d step = s2.p_WM_W - s1.p_WM_W;
  EXPECT_GT(step.norm(), 2e-7);  // 1e-5/s × ~0.5 m × 0.2 s
  EXPECT_LT((s3.p_WM_W - s2.p_WM_W - step).norm(), 1e-12);
  EXPECT_LT((s2.v_WM_W - step / dt).norm(), 1e-9);
  EXPECT_LT(s2.a_WM_W.norm(), 1e-6);
  EXPECT_LT(s2.omega_I.norm(), 1e-9);  // lengths grow, angles stay
  // Grown by ρ t against the geometric arm: the drift since t = 0 is t/dt steps.
  EXPECT_LT((s2.p_WM_W - plain.At(t1 + dt).p_WM_W - step * (t1 + dt) / dt).norm(), 1e-9);
  const ToolState g0 = grows.At(0.0), p0 = plain.At(0.0);
  EXPECT_EQ(g0.p_WM_W, p0.p_WM_W);
  // A model of other parameters, or an effect vector of the wrong size, is refused.
  ToolMotionTruth other = plain;
  EXPECT_THROW(other.set_effects(et.model, Eigen::VectorXd::Zero(2),
                                 [](double) { return kinematics::EffectContext{}; }),
               std::invalid_argument);
  EXPECT_THROW(other.set_effects(et.model, et.e, nullptr), std::invalid_argument);
}

TEST(SensorSim, ImuAtRestReadsGravityAndTheFieldAndStreamsAreDeterministic) {
  const auto m = Cell();
  const Eigen::VectorXd x = Truth(m);
  const ToolMotionTruth truth(m, x, Program(m, 3, 5));
  SensorSimSettings s;
  SensorSim a(truth, s, 42), b(truth, s, 42), c(truth, s, 43);
  Eigen::Vector3d f_sum = Eigen::Vector3d::Zero(), m_sum = Eigen::Vector3d::Zero(),
                  f_exp = Eigen::Vector3d::Zero(), m_exp = Eigen::Vector3d::Zero();
  int n = 0, positions = 0;
  bool differs = false;
  while (auto fa = a.Next()) {
    const auto fb = b.Next();
    const auto fc = c.Next();
    ASSERT_TRUE(fb && fc);
    EXPECT_EQ(fa->imu.gyro_S, fb->imu.gyro_S);
    EXPECT_EQ(fa->imu.accel_S, fb->imu.accel_S);
    ASSERT_EQ(fa->position.has_value(), fb->position.has_value());
    if (fa->position) {
      EXPECT_EQ(fa->position->p_M, fb->position->p_M);
      ++positions;
    }
    differs |= fa->imu.gyro_S != fc->imu.gyro_S;
    if (truth.trajectory().StillAt(fa->t) == 1) {
      const Eigen::Matrix3d R_IE = fa->truth.R_EI.transpose();
      f_sum += fa->imu.accel_S;
      m_sum += fa->imu.mag_S;
      f_exp += -R_IE * s.imu.g_W;
      m_exp += R_IE * s.imu.m_W;
      ++n;
    }
  }
  EXPECT_FALSE(b.Next());
  EXPECT_TRUE(differs);
  EXPECT_EQ(positions, a.num_ticks());  // 100 Hz position sensor on a 100 Hz clock
  ASSERT_GT(n, 100);
  // Means of white noise: σ/√n (accelerometer 5.9e-3 m/s², magnetometer 0.2 µT per sample).
  EXPECT_LT((f_sum - f_exp).norm() / n, 5 * 5.9e-3 / std::sqrt(n));
  EXPECT_LT((m_sum - m_exp).norm() / n, 5 * 0.2 / std::sqrt(n));
}

// The gyro reports the mean rate over the interval that ends at each tick, which the filters'
// interval rule q_k = q_{k−1} Exp(ω_k Δt) integrates onto the truth's attitude (noise off); the
// truth's rate at the instant of each tick (ToolState::omega_I) integrated the same way drifts.
TEST(SensorSim, TheGyroIsTheMeanRateOverEachSampleInterval) {
  const auto m = Cell();
  const ToolMotionTruth truth(m, Truth(m), Program(m, 4, 9));
  SensorSimSettings s;
  s.imu.white_noise = false;
  SensorSim sensors(truth, s, 1);
  auto f = sensors.Next();
  ASSERT_TRUE(f);
  Eigen::Matrix3d R_interval = f->truth.R_EI, R_instant = R_interval;
  double err_interval = 0.0, err_instant = 0.0, max_rate = 0.0;
  while ((f = sensors.Next())) {
    R_interval = R_interval * geometry::Exp(f->imu.gyro_S * 0.01);
    R_instant = R_instant * geometry::Exp(f->truth.omega_I * 0.01);
    err_interval =
        std::max(err_interval, geometry::Log(f->truth.R_EI.transpose() * R_interval).norm());
    err_instant =
        std::max(err_instant, geometry::Log(f->truth.R_EI.transpose() * R_instant).norm());
    max_rate = std::max(max_rate, f->truth.omega_I.norm());
  }
  EXPECT_GT(max_rate, 0.5);       // [rad/s]
  EXPECT_LT(err_interval, 1e-9);  // [rad] rounding
  EXPECT_GT(err_instant, 20 * err_interval + 1e-5);
}

// An encoder swapped mid-run: from t_s on, joint 2 reads 1 mrad less than where the arm stands.
// Independent truth: the model at the truth errors with θ2 1 mrad larger, evaluated at the
// readings, is where the arm is (to rounding); before t_s the readings are the truth's joints.
TEST(SensorSim, AnOffsetStepMovesTheReadingsNotTheArm) {
  const auto m = Cell();
  const Eigen::VectorXd x = Truth(m);
  const ToolMotionTruth truth(m, x, Program(m, 4, 3));
  SensorSimSettings s;
  const double t_s = truth.trajectory().StillInterval(1).second;  // leaving stop 1
  s.offset_steps.push_back({t_s, 1, 1e-3});
  SensorSim sim(truth, s, 7);
  Eigen::VectorXd x_after = x;
  x_after(m.FindParameter("theta2")) += 1e-3;
  int before = 0, after = 0;
  while (const auto f = sim.Next()) {
    if (f->t < t_s) {
      EXPECT_EQ(f->q, f->truth.q) << f->t;
      ++before;
      continue;
    }
    EXPECT_NEAR(f->truth.q(1) - f->q(1), 1e-3, 1e-15);
    EXPECT_LT((TrueJoints(f->q, f->t, s.offset_steps) - f->truth.q).norm(), 1e-15);
    const kinematics::ToolPose read = m.Forward(f->q, x_after);
    EXPECT_LT((read.p_WM_W - f->truth.p_WM_W).norm(), 1e-12) << f->t;
    EXPECT_LT((read.R_EI - f->truth.R_EI).norm(), 1e-12) << f->t;
    // The model before the step, at the readings, misses by about 1 mrad times the reach.
    EXPECT_GT((m.Forward(f->q, x).p_WM_W - f->truth.p_WM_W).norm(), 2e-4) << f->t;
    ++after;
  }
  EXPECT_GT(before, 100);
  EXPECT_GT(after, 100);
}

// A cell that picks its next stop while it runs (issue 16): the truth retargeted while the arm
// stands at stop 1 streams exactly what a simulation programmed with that stop streams (same seed,
// so the same noise), including the longer run.
TEST(SensorSim, ARetargetedStopStreamsAsTheProgramWrittenWithIt) {
  const auto m = Cell();
  const Eigen::VectorXd x = Truth(m);
  Rng rng(5);
  std::vector<Eigen::VectorXd> w = SampleJoints(m, 4, rng);
  ToolMotionTruth live(m, x, JointTrajectory(w));
  const Eigen::VectorXd q2 = SampleJoints(m, 1, rng)[0];
  w[2] = q2;
  const ToolMotionTruth written(m, x, JointTrajectory(w));
  const SensorSimSettings s;
  SensorSim a(live, s, 9), b(written, s, 9);
  const double t_retarget = live.trajectory().StillInterval(1).first;  // standing at stop 1
  bool retargeted = false;
  int64_t n = 0;
  while (auto fa = a.Next()) {
    if (!retargeted && fa->t >= t_retarget) {
      live.Retarget(2, q2);
      retargeted = true;
    }
    const auto fb = b.Next();
    ASSERT_TRUE(fb);
    EXPECT_EQ(fa->q, fb->q) << fa->t;
    EXPECT_EQ(fa->imu.gyro_S, fb->imu.gyro_S) << fa->t;
    EXPECT_EQ(fa->imu.accel_S, fb->imu.accel_S) << fa->t;
    ++n;
  }
  EXPECT_FALSE(b.Next());
  EXPECT_EQ(n, b.num_ticks());
  EXPECT_EQ(a.num_ticks(), b.num_ticks());
}

TEST(SensorSim, MagneticDisturbanceOnlyAtChosenStops) {
  const auto m = Cell();
  const ToolMotionTruth truth(m, Truth(m), Program(m, 20, 9));
  SensorSimSettings s;
  s.imu.white_noise = false;
  s.mag_disturbance = true;
  s.mag_disturbance_fraction = 0.5;
  SensorSim sim(truth, s, 1);
  ASSERT_FALSE(sim.disturbed_stops().empty());
  while (auto f = sim.Next()) {
    const Eigen::Vector3d clean = f->truth.R_EI.transpose() * s.imu.m_W;
    const int k = truth.trajectory().StillAt(f->t);
    const bool disturbed =
        k >= 0 && std::count(sim.disturbed_stops().begin(), sim.disturbed_stops().end(), k) > 0;
    if (disturbed)
      EXPECT_NEAR((f->imu.mag_S - clean).norm(), s.mag_disturbance_uT, 1e-9);
    else
      EXPECT_LT((f->imu.mag_S - clean).norm(), 1e-9);
  }
}

}  // namespace
}  // namespace rcal::sim
