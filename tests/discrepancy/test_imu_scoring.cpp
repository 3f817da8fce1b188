// BROAD scoring (discrepancy/imu_scoring.hpp) against closed forms: an error e = Rz(ψ)·R_tilt(φ)
// in the earth frame, applied on the left of any truth, has heading |ψ|, inclination |φ| and
// total 2 acos(cos(ψ/2) cos(φ/2)); the quaternions are built with Eigen, not with rcal's own
// quaternion code. Sign and scale of the quaternions do not matter; half turns are finite.
#include "rcal/discrepancy/imu_scoring.hpp"
#include "rcal/sim/draw.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

namespace rcal::discrepancy {
namespace {

constexpr double kPi = std::numbers::pi;

Eigen::Vector4d Wxyz(const Eigen::Quaterniond& q) {
  return Eigen::Vector4d(q.w(), q.x(), q.y(), q.z());
}

// Earth-frame error: heading ψ about z after a tilt φ about the horizontal axis at angle β.
Eigen::Quaterniond Error(double psi, double phi, double beta) {
  const Eigen::Vector3d axis(std::cos(beta), std::sin(beta), 0.0);
  return Eigen::Quaterniond(Eigen::AngleAxisd(psi, Eigen::Vector3d::UnitZ())) *
         Eigen::Quaterniond(Eigen::AngleAxisd(phi, axis));
}

Eigen::Quaterniond RandomRotation(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  const Eigen::Vector4d q_wxyz = sim::Draw4(n, rng);
  return Eigen::Quaterniond(q_wxyz(0), q_wxyz(1), q_wxyz(2), q_wxyz(3)).normalized();
}

TEST(ImuScoring, HeadingInclinationAndTotalOfAnEarthFrameErrorMatchTheClosedForm) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> angle(-3.0, 3.0), dir(-kPi, kPi);
  for (int k = 0; k < 200; ++k) {
    const double psi = angle(rng), phi = angle(rng), beta = dir(rng);
    const Eigen::Quaterniond truth = RandomRotation(rng);
    const Eigen::Quaterniond est = Error(psi, phi, beta) * truth;
    const AngleErrors e = BroadErrors(Wxyz(est), Wxyz(truth));
    EXPECT_NEAR(e.heading, std::abs(psi), 1e-9) << psi << " " << phi;
    EXPECT_NEAR(e.inclination, std::abs(phi), 1e-9) << psi << " " << phi;
    EXPECT_NEAR(e.total, 2.0 * std::acos(std::abs(std::cos(psi / 2) * std::cos(phi / 2))), 1e-9);
    // The total error is the rotation angle between estimate and truth.
    EXPECT_NEAR(e.total, est.angularDistance(truth), 1e-9);
  }
}

TEST(ImuScoring, TheErrorIsTakenInTheEarthFrameNotTheBodyFrame) {
  // Truth tilted 90° about x: the body z axis is horizontal. A heading error of 0.3 rad about the
  // earth z is heading only; the same rotation about the body z is a tilt (inclination only).
  const Eigen::Quaterniond truth(Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitX()));
  const Eigen::Quaterniond rz(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  const AngleErrors earth = BroadErrors(Wxyz(rz * truth), Wxyz(truth));
  EXPECT_NEAR(earth.heading, 0.3, 1e-12);
  EXPECT_NEAR(earth.inclination, 0.0, 1e-7);
  const AngleErrors body = BroadErrors(Wxyz(truth * rz), Wxyz(truth));
  EXPECT_NEAR(body.heading, 0.0, 1e-12);
  EXPECT_NEAR(body.inclination, 0.3, 1e-12);
}

TEST(ImuScoring, SignAndScaleOfTheQuaternionsDoNotMatter) {
  std::mt19937 rng(3);
  for (int k = 0; k < 20; ++k) {
    const Eigen::Vector4d truth = Wxyz(RandomRotation(rng)), est = Wxyz(RandomRotation(rng));
    const AngleErrors a = BroadErrors(est, truth);
    for (const auto& [s_est, s_truth] : {std::pair{-1.0, 1.0}, {1.0, -1.0}, {-2.5, 0.3}}) {
      const AngleErrors b = BroadErrors(s_est * est, s_truth * truth);
      EXPECT_NEAR(a.total, b.total, 1e-12);
      EXPECT_NEAR(a.heading, b.heading, 1e-12);
      EXPECT_NEAR(a.inclination, b.inclination, 1e-12);
    }
  }
}

TEST(ImuScoring, HalfTurnsAreFinite) {
  const Eigen::Vector4d id(1, 0, 0, 0);
  // Half a turn about a horizontal axis: e_w = e_z = 0, a pure tilt of π.
  const AngleErrors tilt = BroadErrors(Eigen::Vector4d(0, 1, 0, 0), id);
  EXPECT_NEAR(tilt.total, kPi, 1e-12);
  EXPECT_NEAR(tilt.heading, 0.0, 1e-12);
  EXPECT_NEAR(tilt.inclination, kPi, 1e-12);
  const AngleErrors tilt_y = BroadErrors(Wxyz(Error(0.0, kPi, 0.7)), id);
  EXPECT_NEAR(tilt_y.heading, 0.0, 1e-9);
  EXPECT_NEAR(tilt_y.inclination, kPi, 1e-7);
  // Half a turn about the vertical: heading π, no tilt.
  const AngleErrors turn = BroadErrors(Eigen::Vector4d(0, 0, 0, 1), id);
  EXPECT_NEAR(turn.total, kPi, 1e-12);
  EXPECT_NEAR(turn.heading, kPi, 1e-12);
  EXPECT_NEAR(turn.inclination, 0.0, 1e-12);
  const AngleErrors none = BroadErrors(id, id);
  EXPECT_EQ(none.total, 0.0);
  EXPECT_EQ(none.heading, 0.0);
  EXPECT_EQ(none.inclination, 0.0);
}

TEST(ImuScoring, RmsAndScoreAccumulate) {
  Rms r;
  EXPECT_TRUE(std::isnan(r.value()));
  for (double v : {3.0, -4.0}) r.Add(v);
  EXPECT_EQ(r.n, 2);
  EXPECT_DOUBLE_EQ(r.value(), std::sqrt(12.5));
  OrientationScore s;
  s.Add({0.3, 0.1, 0.2});
  s.Add({0.4, 0.0, 0.0});
  EXPECT_DOUBLE_EQ(s.total.value(), std::sqrt((0.09 + 0.16) / 2));
  EXPECT_DOUBLE_EQ(s.heading.value(), std::sqrt(0.01 / 2));
  EXPECT_DOUBLE_EQ(s.inclination.value(), std::sqrt(0.04 / 2));
  EXPECT_EQ(s.total.n, 2);
}

TEST(ImuScoring, NonFiniteEstimatesScoreNaNNeverZero) {
  // A filter that published NaN was scored "total RMSE 0.00°": std::min(1, NaN) is 1, acos(1) 0.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Eigen::Vector4d truth(1, 0, 0, 0);
  const std::vector<Eigen::Vector4d> bads{
      Eigen::Vector4d(nan, nan, nan, nan), Eigen::Vector4d(1, nan, 0, 0),
      Eigen::Vector4d(std::numeric_limits<double>::infinity(), 0, 0, 0),
      Eigen::Vector4d(0, 0, 0, 0)};
  for (const Eigen::Vector4d& bad : bads) {
    for (const AngleErrors e : {BroadErrors(bad, truth), BroadErrors(truth, bad)}) {
      EXPECT_TRUE(std::isnan(e.total)) << bad.transpose();
      EXPECT_TRUE(std::isnan(e.heading)) << bad.transpose();
      EXPECT_TRUE(std::isnan(e.inclination)) << bad.transpose();
    }
  }
  // One NaN sample among good ones makes the RMSE NaN, so a report cannot show it as good.
  OrientationScore s;
  s.Add(BroadErrors(truth, truth));
  s.Add(BroadErrors(Eigen::Vector4d(nan, nan, nan, nan), truth));
  EXPECT_TRUE(std::isnan(s.total.value()));
}

}  // namespace
}  // namespace rcal::discrepancy
