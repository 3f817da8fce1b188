#include "rcal/kinematics/measurement.hpp"

#include <gtest/gtest.h>

#include "rcal/geometry/so3.hpp"
#include "test_robots.hpp"

namespace rcal::kinematics {
namespace {

using namespace testing;

PoseMeasurement Exact(const KinematicModel& m, const Eigen::VectorXd& q, const Eigen::VectorXd& x) {
  const ToolPose p = m.Forward(q, x);
  PoseMeasurement z;
  z.q = q;
  z.p_WM_W = p.p_WM_W;
  z.has_orientation = true;
  z.R_EI = p.R_EI;
  z.covariance = Eigen::MatrixXd::Identity(6, 6) * 1e-8;
  return z;
}

TEST(Measurement, ResidualIsZeroAtTheTruthAndLinearisesWithMinusJ) {
  const KinematicModel m = SevenJointSetup();
  std::mt19937 rng(3);
  for (int t = 0; t < 10; ++t) {
    const Eigen::VectorXd q = RandomJoints(m, rng), x = RandomErrors(m, rng);
    const PoseMeasurement z = Exact(m, q, x);
    EXPECT_LT(Residual(m, z, x).norm(), 1e-14);
    // r(x + dx) ≈ r(x) − J dx for a small dx, independently of the Jacobian code's derivation.
    const Eigen::VectorXd dx = RandomErrors(m, rng, 1e-6, 1e-6);
    Eigen::MatrixXd J(6, m.num_params());
    m.IdentificationJacobian(q, x, J);
    EXPECT_LT((Residual(m, z, x + dx) - (-J * dx)).norm(), 1e-10);
    std::vector<int> all(m.num_params());
    for (int i = 0; i < m.num_params(); ++i) all[i] = i;
    Eigen::VectorXd r;
    Eigen::MatrixXd H;
    ResidualAndJacobian(m, z, x + dx, all, r, H);
    EXPECT_LT((r - Residual(m, z, x + dx)).norm(), 1e-15);
  }
}

TEST(Measurement, PositionOnlyHasThreeRows) {
  const KinematicModel m = Grb3016();
  PoseMeasurement z = Exact(m, Eigen::VectorXd::Zero(6), m.Nominal());
  z.has_orientation = false;
  z.covariance = Eigen::Matrix3d::Identity();
  z.p_WM_W.x() += 0.001;
  const Eigen::VectorXd r = Residual(m, z, m.Nominal());
  ASSERT_EQ(r.size(), 3);
  EXPECT_NEAR(r.x(), 0.001, 1e-15);
  EXPECT_TRUE(Validate(m, z).empty());
}

TEST(Measurement, ValidateNamesTheField) {
  const KinematicModel m = Grb3016();
  const PoseMeasurement good = Exact(m, Eigen::VectorXd::Zero(6), m.Nominal());
  EXPECT_EQ(Validate(m, good), "");
  PoseMeasurement z = good;
  z.q.resize(7);
  EXPECT_NE(Validate(m, z).find("q: 7 joints"), std::string::npos);
  z = good;
  z.R_EI *= -1;
  EXPECT_NE(Validate(m, z).find("R_EI"), std::string::npos);
  z = good;
  z.covariance(5, 5) = std::nan("");
  EXPECT_NE(Validate(m, z).find("covariance"), std::string::npos);
}

}  // namespace
}  // namespace rcal::kinematics
