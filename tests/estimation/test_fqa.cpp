// FQA against the golden file (../shared/data/fqa, NED) and round trips in NED and ENU.
#include "rcal/estimation/fqa.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "rcal/geometry/so3.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::estimation {
namespace {

constexpr double kG = 9.81;

// Rotation angle [rad] between two quaternions, sign-blind.
double QuatAngle(const Eigen::Vector4d& a, const Eigen::Vector4d& b) {
  const double d = std::abs(a.normalized().dot(b.normalized()));
  return 2.0 * std::acos(std::min(1.0, d));
}

Eigen::Matrix3d RandomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Vector4d q = sim::Draw4(n, rng);
  return geometry::QuatToMatrix(q.normalized());
}

TEST(Fqa, MatchesGoldenFileNed) {
  const auto table =
      io::CsvTable::Load(std::string(RCAL_SHARED_DIR) + "/data/fqa/fqa_golden_ned.csv");
  ASSERT_EQ(table.rows(), 497);
  int counts[4] = {0, 0, 0, 0};
  double worst_kind3 = 0.0;
  for (int i = 0; i < table.rows(); ++i) {
    const Eigen::Vector3d f(table.At(i, "acc_x"), table.At(i, "acc_y"), table.At(i, "acc_z"));
    const Eigen::Vector3d m(table.At(i, "mag_x"), table.At(i, "mag_y"), table.At(i, "mag_z"));
    FqaSettings s;
    s.m_ref_E = {table.At(i, "mref_n"), table.At(i, "mref_e"), table.At(i, "mref_d")};
    const Eigen::Vector4d expected(table.At(i, "q_w"), table.At(i, "q_x"), table.At(i, "q_y"),
                                   table.At(i, "q_z"));
    const int kind = static_cast<int>(table.At(i, "kind"));
    ASSERT_GE(kind, 0);
    ASSERT_LE(kind, 3);
    ++counts[kind];
    const auto q = Fqa(f, m, s);
    ASSERT_TRUE(q.ok()) << "row " << i << ": " << q.error();
    EXPECT_GE((*q)(0), 0.0);
    EXPECT_NEAR(q->norm(), 1.0, 1e-12);
    const double err = QuatAngle(*q, expected);
    if (kind <= 2) {
      EXPECT_LT(err, 1e-6) << "row " << i << " kind " << kind << " got " << q->transpose()
                           << " expected " << expected.transpose();
    } else {
      worst_kind3 = std::max(worst_kind3, err);
    }
  }
  EXPECT_EQ(counts[0], 300);
  EXPECT_EQ(counts[1], 6);
  EXPECT_EQ(counts[2], 4);
  EXPECT_EQ(counts[3], 187);
  // Real readings: the reference output is another implementation of the same definition.
  EXPECT_LT(worst_kind3, 1e-6);
}

class FqaRoundTrip : public ::testing::TestWithParam<EarthFrame> {};

TEST_P(FqaRoundTrip, RecoversRandomAttitudes) {
  const EarthFrame frame = GetParam();
  std::mt19937_64 rng(42);
  FqaSettings s;
  s.earth = frame;
  // A field with dip 65° and declination 0 (magnetic north), in µT.
  const Eigen::Vector3d m_E =
      45.0 * (std::cos(65.0 * std::numbers::pi / 180) * MagneticNorth(frame) -
              std::sin(65.0 * std::numbers::pi / 180) * UpVector(frame));
  s.m_ref_E = m_E;
  const Eigen::Vector3d f_E = kG * UpVector(frame);  // specific force at rest points up
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Matrix3d R_EB = RandomRotation(rng);
    const auto q = Fqa(R_EB.transpose() * f_E, R_EB.transpose() * m_E, s);
    ASSERT_TRUE(q.ok()) << q.error();
    EXPECT_LT(geometry::AngleBetween(geometry::QuatToMatrix(*q), R_EB), 1e-9);
  }
}

TEST_P(FqaRoundTrip, SpecialAttitudes) {
  const EarthFrame frame = GetParam();
  FqaSettings s;
  s.earth = frame;
  const Eigen::Vector3d m_E = 20.0 * MagneticNorth(frame) - 40.0 * UpVector(frame);
  s.m_ref_E = m_E;
  const Eigen::Vector3d f_E = kG * UpVector(frame);
  const double pi = std::numbers::pi;
  for (double pitch : {pi / 2, -pi / 2, pi / 2 - 1e-9, -pi / 2 + 1e-7, pi / 2 - 0.01, 0.0}) {
    for (double yaw : {0.0, pi, -pi + 1e-12, pi / 3, pi - 1e-9}) {
      for (double roll : {0.0, pi, 0.3, -pi + 1e-9}) {
        const Eigen::Matrix3d R_EB = geometry::FromRpy(roll, pitch, yaw);
        const auto q = Fqa(R_EB.transpose() * f_E, R_EB.transpose() * m_E, s);
        ASSERT_TRUE(q.ok()) << q.error();
        EXPECT_LT(geometry::AngleBetween(geometry::QuatToMatrix(*q), R_EB), 1e-8)
            << "roll " << roll << " pitch " << pitch << " yaw " << yaw;
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Frames, FqaRoundTrip,
                         ::testing::Values(EarthFrame::kNed, EarthFrame::kEnu));

TEST(Fqa, MagnetometerDoesNotChangeTilt) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n(0.0, 30.0);
  const Eigen::Vector3d f_B(1.0, -2.0, -9.3);
  const Eigen::Vector3d up_N(0, 0, -1);
  for (int i = 0; i < 500; ++i) {
    const Eigen::Vector3d m_B = sim::Draw3(n, rng);
    const auto q = Fqa(f_B, m_B);
    if (!q.ok()) continue;
    // The measured gravity direction must map exactly onto the vertical, whatever m_B is.
    const Eigen::Vector3d up_B = geometry::QuatToMatrix(*q).transpose() * up_N;
    EXPECT_LT((up_B - f_B.normalized()).norm(), 1e-12);
  }
}

TEST(Fqa, HeadingFollowsMagnetometerAboutVertical) {
  // Rotating the magnetometer's horizontal part by α about the body's vertical must change the
  // heading by −α and nothing else.
  const Eigen::Vector3d f_B(0, 0, -kG);
  const auto q0 = Fqa(f_B, Eigen::Vector3d(20, 0, 40));
  ASSERT_TRUE(q0.ok());
  for (double alpha : {0.5, 2.0, std::numbers::pi}) {
    const Eigen::Vector3d m_B = geometry::Rz(alpha) * Eigen::Vector3d(20, 0, 40);
    const auto q = Fqa(f_B, m_B);
    ASSERT_TRUE(q.ok());
    EXPECT_LT(geometry::AngleBetween(geometry::QuatToMatrix(*q), geometry::Rz(-alpha)), 1e-12);
  }
}

TEST(Fqa, RejectsBadInputNamingTheField) {
  const Eigen::Vector3d f(0, 0, -kG), m(20, 0, 40);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  auto expect_error = [](const Result<Eigen::Vector4d>& r, const std::string& field) {
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().find(field), std::string::npos) << r.error();
  };
  expect_error(Fqa(Eigen::Vector3d(nan, 0, -kG), m), "accelerometer");
  expect_error(Fqa(Eigen::Vector3d(0, inf, -kG), m), "accelerometer");
  expect_error(Fqa(Eigen::Vector3d::Zero(), m), "accelerometer");
  expect_error(Fqa(f, Eigen::Vector3d(nan, 0, 0)), "magnetometer");
  expect_error(Fqa(f, Eigen::Vector3d::Zero()), "magnetometer");
  expect_error(Fqa(f, Eigen::Vector3d(0, 0, 40)), "magnetometer");  // parallel to gravity
  FqaSettings s;
  s.m_ref_E = {0, 0, 40};
  expect_error(Fqa(f, m, s), "reference");
  s.m_ref_E = {nan, 0, 0};
  expect_error(Fqa(f, m, s), "reference");
  // Tiny but valid inputs still work (no absolute thresholds on the scale).
  const auto q = Fqa(1e-20 * f, 1e-20 * m);
  ASSERT_TRUE(q.ok()) << q.error();
  EXPECT_LT(geometry::AngleBetween(geometry::QuatToMatrix(*q), Eigen::Matrix3d::Identity()), 1e-12);
}

}  // namespace
}  // namespace rcal::estimation
