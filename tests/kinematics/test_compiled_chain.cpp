// CompiledChain against the ET-by-ET KinematicModel (the independent truth): same tool frame and
// same joint Jacobian to 1e-12 at random parameter errors and random joints.
#include "rcal/kinematics/compiled_chain.hpp"

#include <gtest/gtest.h>

#include <random>

#include "test_robots.hpp"

namespace rcal::kinematics {
namespace {

using namespace testing;

/// Every joint kind the compiler distinguishes: ±x/±y/±z revolute fast paths, a general axis,
/// prismatic joints (D–H d and URDF axis), fixed transforms with no joint in between, fixed parts
/// kept as primitive rotations (merged about one axis, or two axes) and parts collapsed into one
/// general rotation.
KinematicModel MixedAxes() {
  ModelBuilder b("mixed");
  b.BaseFrame({0.2, 0.0, 0.3}, {0.1, 0.2, 0.3})
      .UrdfJoint({0, 0, 0.1}, {0, 0, 0}, {0, 0, -1}, Rev("rz_neg"))
      .UrdfJoint({0.1, 0, 0}, {0.3, 0, 0}, {1, 0, 0}, Rev("rx"))
      .UrdfJoint({0, 0.2, 0}, {0, 0, 0}, {-1, 0, 0}, Rev("rx_neg"))
      .UrdfJoint({0, 0, 0.3}, {0, 0.2, 0}, {0, -1, 0}, Rev("ry_neg"))
      .UrdfJoint({0.1, 0.1, 0}, {0, 0, 0.4}, {1, 2, -0.5}, Rev("general"))
      .FixedTransform({0.05, 0, 0.02}, {0.0, 0.1, 0.0})
      .UrdfJoint({0, 0, 0.05}, {0, 0, 0}, {0.3, -0.2, 1.0},
                 {"slide_general", JointType::kPrismatic, -0.2, 0.2})
      .DhLink(0.05, 0.3, 0.1, 0.2, {"slide_dh", JointType::kPrismatic, 0.0, 0.3})
      .DhLink(0.1, -0.4, 0.05, 0.0, Rev("rz"))
      // Rx(α) of the link above, this Rx(0.3) and the next link's Rx(α₋₁) are consecutive: they
      // merge into one axis rotation, kept next to a Ry(β) (two primitive rotations).
      .FixedTransform({0, 0, 0}, {0.3, 0, 0})
      .ModifiedDhLink(0.05, 0.4, 0.1, 0.2, Rev("mdh_hayati"), true)
      .DhLink(0.2, 0.0, 0.0, 0.1, Rev("dh_hayati"), true)
      .MarkerOffset({0.0, 0.02, 0.1});
  return b.Build();
}

KinematicModel ModelFor(int which) {
  switch (which) {
    case 0:
      return Grb3016();
    case 1:
      return SevenJointSetup();
    case 2:
      return UrLikeUrdf();
    default:
      return MixedAxes();
  }
}

class CompiledChainTest : public ::testing::TestWithParam<int> {};

TEST_P(CompiledChainTest, MatchesModelToolFrameAndJacobian) {
  const KinematicModel m = ModelFor(GetParam());
  std::mt19937 rng(1234 + GetParam());
  double max_dT = 0.0, max_dJ = 0.0;
  for (int trial = 0; trial < 200; ++trial) {
    // Errors well beyond calibration size, so folding mistakes in x cannot hide.
    const Eigen::VectorXd x = RandomErrors(m, rng, 0.05, 0.2);
    const CompiledChain chain(m, x);
    ASSERT_EQ(chain.num_joints(), m.num_joints());
    for (int k = 0; k < 5; ++k) {
      const Eigen::VectorXd q = RandomJoints(m, rng);
      const Eigen::Isometry3d T_ref = m.ToolFrame(q, x);
      const Eigen::MatrixXd J_ref = m.JointJacobian(q, x);

      const Eigen::Isometry3d T_WT = chain.ToolFrame(q);
      max_dT = std::max(max_dT, (T_WT.matrix() - T_ref.matrix()).cwiseAbs().maxCoeff());

      CompiledChain::Jacobian J(6, m.num_joints());
      J.setConstant(1e9);  // every entry must be overwritten
      Eigen::Isometry3d T_from_J;
      chain.JointJacobian(q, J, &T_from_J);
      max_dJ = std::max(max_dJ, (J - J_ref).cwiseAbs().maxCoeff());
      max_dT = std::max(max_dT, (T_from_J.matrix() - T_ref.matrix()).cwiseAbs().maxCoeff());
      EXPECT_LT((chain.JointJacobian(q) - J_ref).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
  EXPECT_LT(max_dT, 1e-12) << m.name();
  EXPECT_LT(max_dJ, 1e-12) << m.name();
  // The last row of an affine transform must be exactly [0 0 0 1].
  const Eigen::Isometry3d T = CompiledChain(m, m.Nominal()).ToolFrame(RandomJoints(m, rng));
  EXPECT_EQ(T.matrix().row(3), Eigen::RowVector4d(0, 0, 0, 1));
}

INSTANTIATE_TEST_SUITE_P(Robots, CompiledChainTest, ::testing::Values(0, 1, 2, 3));

TEST(CompiledChain, NominalGrbHomePoseByHand) {
  // Independent of both implementations: the GRB3016 at q = 0 with a zero tool, from Table 1.
  // D–H: link frames chain Rz(θ) Tz(d) Tx(a) Rx(α); computed here with plain matrices.
  const KinematicModel m = Grb3016(0, 0, 0, 0);
  const CompiledChain chain(m, m.Nominal());
  const double a[6] = {0.150, 0.570, 0.150, 0.0, 0.0, 0.0};
  const double alpha[6] = {-kPi / 2, -kPi, kPi / 2, -kPi / 2, kPi / 2, 0.0};
  const double d[6] = {0.250, 0.0, 0.0, 0.645, 0.0, -0.200};
  const double theta[6] = {0.0, -kPi / 2, 0.0, 0.0, -kPi / 2, 0.0};
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  for (int i = 0; i < 6; ++i) {
    const double ct = std::cos(theta[i]), st = std::sin(theta[i]);
    const double ca = std::cos(alpha[i]), sa = std::sin(alpha[i]);
    Eigen::Matrix4d A;
    A << ct, -st * ca, st * sa, a[i] * ct,  //
        st, ct * ca, -ct * sa, a[i] * st,   //
        0, sa, ca, d[i],                    //
        0, 0, 0, 1;
    T = T * A;
  }
  EXPECT_LT((chain.ToolFrame(Eigen::VectorXd::Zero(6)).matrix() - T).cwiseAbs().maxCoeff(), 1e-14);
}

TEST(CompiledChain, RejectsWrongParameterSize) {
  const KinematicModel m = Grb3016();
  EXPECT_THROW(CompiledChain(m, Eigen::VectorXd::Zero(m.num_params() + 1)), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::kinematics
