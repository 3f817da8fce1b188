#include "rcal/kinematics/model.hpp"

#include <gtest/gtest.h>

#include "rcal/geometry/so3.hpp"
#include "test_robots.hpp"

namespace rcal::kinematics {
namespace {

using geometry::Log;
using namespace testing;

// Central differences of the forward pose, in the Jacobian's convention: position rows directly,
// orientation rows as the left rotation error in the earth frame.
Eigen::MatrixXd NumericIdentificationJacobian(const KinematicModel& m, const Eigen::VectorXd& q,
                                              const Eigen::VectorXd& x) {
  const double h = 1e-6;
  Eigen::MatrixXd J(6, m.num_params());
  for (int i = 0; i < m.num_params(); ++i) {
    Eigen::VectorXd xp = x, xm = x;
    xp(i) += h;
    xm(i) -= h;
    const ToolPose a = m.Forward(q, xp), b = m.Forward(q, xm);
    J.block<3, 1>(0, i) = (a.p_WM_W - b.p_WM_W) / (2 * h);
    J.block<3, 1>(3, i) = Log(a.R_EI * b.R_EI.transpose()) / (2 * h);
  }
  return J;
}

Eigen::MatrixXd NumericJointJacobian(const KinematicModel& m, const Eigen::VectorXd& q,
                                     const Eigen::VectorXd& x) {
  const double h = 1e-6;
  Eigen::MatrixXd J(6, m.num_joints());
  for (int j = 0; j < m.num_joints(); ++j) {
    Eigen::VectorXd qp = q, qm = q;
    qp(j) += h;
    qm(j) -= h;
    const Eigen::Isometry3d a = m.ToolFrame(qp, x), b = m.ToolFrame(qm, x);
    J.block<3, 1>(0, j) = (a.translation() - b.translation()) / (2 * h);
    J.block<3, 1>(3, j) = Log(a.linear() * b.linear().transpose()) / (2 * h);
  }
  return J;
}

class JacobianTest : public ::testing::TestWithParam<int> {};

KinematicModel ModelFor(int which) {
  switch (which) {
    case 0:
      return Grb3016();
    case 1:
      return SevenJointSetup();
    case 2:
      return UrLikeUrdf();
    case 4:
      return UrLikeThreeMarkers();
    default: {
      // Hayati β (with nominal values) in both D–H forms, a prismatic joint and an IMU.
      ModelBuilder b("hayati");
      b.DhLink(0.150, -kPi / 2, 0.250, 0.0, Rev("j1"))
          .DhLink(0.570, -kPi, 0.0, -kPi / 2, Rev("j2"), /*hayati=*/true, /*beta=*/0.01)
          .ModifiedDhLink(0.150, kPi / 2, 0.0, 0.0, Rev("j3"), /*hayati=*/true, /*beta=*/-0.02)
          .DhLink(0.0, kPi / 2, 0.3, 0.0, {"slide", JointType::kPrismatic, 0.0, 0.5})
          .ImuMounting({0.1, 0.2, 0.3});
      return b.Build();
    }
  }
}

// Every marker of a model has its own view (ForMarker); each is checked like the model.
int Slots(const KinematicModel& m) {
  return std::max<int>(1, m.markers().size());
}

TEST_P(JacobianTest, IdentificationJacobianMatchesFiniteDifferences) {
  const KinematicModel model = ModelFor(GetParam());
  std::mt19937 rng(10 + GetParam());
  for (int trial = 0; trial < 20 * Slots(model); ++trial) {
    const KinematicModel& m = model.ForMarker(trial % Slots(model));
    const Eigen::VectorXd q = RandomJoints(m, rng);
    const Eigen::VectorXd x = RandomErrors(m, rng);
    Eigen::MatrixXd J(6, m.num_params());
    ToolPose pose;
    m.IdentificationJacobian(q, x, J, &pose);
    const Eigen::MatrixXd Jn = NumericIdentificationJacobian(m, q, x);
    EXPECT_LT((J - Jn).cwiseAbs().maxCoeff(), 1e-7) << m.name() << " trial " << trial;
    const ToolPose f = m.Forward(q, x);
    EXPECT_LT((pose.p_WM_W - f.p_WM_W).norm(), 1e-14);
    EXPECT_LT((pose.R_EI - f.R_EI).norm(), 1e-14);
  }
}

TEST_P(JacobianTest, JointJacobianMatchesFiniteDifferences) {
  const KinematicModel model = ModelFor(GetParam());
  std::mt19937 rng(20 + GetParam());
  for (int trial = 0; trial < 20 * Slots(model); ++trial) {
    const KinematicModel& m = model.ForMarker(trial % Slots(model));
    const Eigen::VectorXd q = RandomJoints(m, rng);
    const Eigen::VectorXd x = RandomErrors(m, rng);
    EXPECT_LT((m.JointJacobian(q, x) - NumericJointJacobian(m, q, x)).cwiseAbs().maxCoeff(), 1e-7);
  }
}

INSTANTIATE_TEST_SUITE_P(Robots, JacobianTest, ::testing::Values(0, 1, 2, 3, 4));

// Several markers: marker k's position is the flange frame applied to its own offset
// p_FM,k = nominal + error, the flange frame computed by a model whose chain ends there (no
// marker); the orientation is the same for every marker; all views share x.
TEST(Model, EachMarkerIsTheFlangeFrameAppliedToItsOwnOffset) {
  const KinematicModel m = UrLikeThreeMarkers();
  ASSERT_EQ(m.markers().size(), 3u);
  EXPECT_EQ(m.markers()[1].id, 2);
  EXPECT_EQ(m.MarkerSlot(5), 2);
  EXPECT_EQ(m.MarkerSlot(1), -1);
  EXPECT_EQ(m.num_params(), 6 + 36 + 9 + 3);
  EXPECT_GE(m.FindParameter("marker2_y"), 0);
  EXPECT_GE(m.FindParameter("marker5_z"), 0);
  ModelBuilder fb("flange");
  const KinematicModel flange = UrLikeChain(fb).Build();  // parameters: the first 42 of m, in order
  std::mt19937 rng(31);
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::VectorXd q = RandomJoints(m, rng);
    const Eigen::VectorXd x = RandomErrors(m, rng);
    const Eigen::Isometry3d T_WF = flange.ToolFrame(q, x.head(flange.num_params()));
    for (int k = 0; k < 3; ++k) {
      const Marker& mk = m.markers()[k];
      const Eigen::Vector3d p_FM(mk.nominal.x() + x(mk.param[0]), mk.nominal.y() + x(mk.param[1]),
                                 mk.nominal.z() + x(mk.param[2]));
      const ToolPose pose = m.ForMarker(k).Forward(q, x);
      EXPECT_LT((pose.p_WM_W - T_WF * p_FM).norm(), 1e-13) << "slot " << k;
      EXPECT_LT((pose.R_EI - m.Forward(q, x).R_EI).norm(), 1e-13) << "slot " << k;
    }
  }
  EXPECT_EQ(&m.ForMarker(0), &m);
  EXPECT_EQ(&m.ForMarker(2).ForMarker(2), &m.ForMarker(2));
  EXPECT_THROW(m.ForMarker(3), std::out_of_range);
  EXPECT_THROW(m.ForMarker(2).ForMarker(1), std::out_of_range);  // a view is one marker
  EXPECT_THROW(Grb3016().ForMarker(1), std::out_of_range);
  // A copy keeps its views, and they measure their own marker.
  const KinematicModel copy = m;
  const Eigen::VectorXd q = RandomJoints(m, rng);
  EXPECT_EQ(copy.ForMarker(1).Forward(q, m.Nominal()).p_WM_W,
            m.ForMarker(1).Forward(q, m.Nominal()).p_WM_W);
  EXPECT_GT((copy.ForMarker(1).Forward(q, m.Nominal()).p_WM_W -
             copy.ForMarker(2).Forward(q, m.Nominal()).p_WM_W)
                .norm(),
            0.05);
}

// R_EW alone: without an IMU mounting the orientation Forward gives is R_EW · R_WT, so the earth
// rotation is that orientation less the chain's; at x = 0 it is the builder's roll-pitch-yaw.
TEST(Model, EarthFromWorldIsTheRotationForwardPutsBeforeTheChain) {
  const Eigen::Vector3d rpy_EW(0.02, 0.03, 1.2);
  ModelBuilder b("earth");
  b.DhLink(0.15, -kPi / 2, 0.25, 0.0, Rev("j1"))
      .DhLink(0.57, 0.0, 0.0, -kPi / 2, Rev("j2"))
      .EarthFrame(rpy_EW);
  const KinematicModel m = b.Build();
  ASSERT_TRUE(m.has_earth());
  EXPECT_FALSE(Grb3016().has_earth());
  EXPECT_LT((m.EarthFromWorld(m.Nominal()) - geometry::FromRpy(rpy_EW)).norm(), 1e-15);
  std::mt19937 rng(5);
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::VectorXd q = RandomJoints(m, rng), x = RandomErrors(m, rng);
    const Eigen::Matrix3d R_EW = m.Forward(q, x).R_EI * m.ToolFrame(q, x).linear().transpose();
    EXPECT_LT((m.EarthFromWorld(x) - R_EW).norm(), 1e-14);
  }
  EXPECT_EQ(Grb3016().EarthFromWorld(Grb3016().Nominal()), Eigen::Matrix3d::Identity());
  EXPECT_THROW(m.EarthFromWorld(Eigen::VectorXd::Zero(2)), std::invalid_argument);
}

// The linearised covariance of R_WE against sampling: parameters drawn with their σ (every
// parameter, so the arm's own must not reach the earth frame), the rotation error of each draw's
// R_WE against the estimate's as a left rotation vector in W; 20 000 draws, sample covariance
// within 5 % (σ of 10 mrad: the linearisation's error is far below that).
TEST(Model, WorldFromEarthCovarianceMatchesSampledRotations) {
  ModelBuilder b("earth");
  b.DhLink(0.15, -kPi / 2, 0.25, 0.0, Rev("j1"))
      .DhLink(0.57, 0.0, 0.0, -kPi / 2, Rev("j2"))
      .EarthFrame(Eigen::Vector3d(0.02, 0.03, 1.2));
  const KinematicModel m = b.Build();
  std::mt19937 rng(11);
  const Eigen::VectorXd x = RandomErrors(m, rng);
  Eigen::VectorXd sigma(m.num_params());
  for (int i = 0; i < m.num_params(); ++i) sigma(i) = 0.002 + 0.008 * (i % 3) / 2.0;
  const Eigen::Matrix3d C = m.WorldFromEarthCovariance(x, sigma);
  const Eigen::Matrix3d R_WE = m.EarthFromWorld(x).transpose();
  std::normal_distribution<double> N(0.0, 1.0);
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
  const int n = 20000;
  for (int k = 0; k < n; ++k) {
    Eigen::VectorXd xs = x;
    for (int i = 0; i < m.num_params(); ++i) xs(i) += sigma(i) * N(rng);
    const Eigen::Vector3d d = geometry::Log(m.EarthFromWorld(xs).transpose() * R_WE.transpose());
    S += d * d.transpose() / n;
  }
  EXPECT_GT(C.trace(), 1e-5);
  EXPECT_LT((S - C).norm(), 0.05 * C.norm()) << "sampled\n" << S << "\nlinearised\n" << C;
  EXPECT_EQ(Grb3016().WorldFromEarthCovariance(Grb3016().Nominal(),
                                               Eigen::VectorXd::Ones(Grb3016().num_params())),
            Eigen::Matrix3d::Zero());
  EXPECT_THROW(m.WorldFromEarthCovariance(x, Eigen::VectorXd::Zero(2)), std::invalid_argument);
}

TEST(Model, MarkerIdsAreDistinctAndEndTheChain) {
  ModelBuilder b("twice");
  b.DhLink(0.1, 0.0, 0.0, 0.0, Rev("j1")).MarkerOffset({0, 0, 0.1}, true, 3);
  EXPECT_THROW(b.MarkerOffset({0, 0, 0.2}, true, 3), std::invalid_argument);
  EXPECT_THROW(b.MarkerOffset({0, 0, 0.2}, true, -1), std::invalid_argument);
  EXPECT_THROW(b.DhLink(0.1, 0.0, 0.0, 0.0, Rev("j2")), std::logic_error);
}

TEST(Model, DhLinkMatchesClosedFormMatrix) {
  // One standard D–H link against the textbook matrix.
  const double a = 0.3, alpha = 0.7, d = 0.2, theta = -0.4, q = 0.9;
  ModelBuilder b("one");
  b.DhLink(a, alpha, d, theta, Rev("j1"));
  const KinematicModel m = b.Build();
  const Eigen::Isometry3d T = m.ToolFrame(Eigen::VectorXd::Constant(1, q), m.Nominal());
  const double ct = std::cos(theta + q), st = std::sin(theta + q);
  const double ca = std::cos(alpha), sa = std::sin(alpha);
  Eigen::Matrix4d expected;
  expected << ct, -st * ca, st * sa, a * ct,  //
      st, ct * ca, -ct * sa, a * st,          //
      0, sa, ca, d,                           //
      0, 0, 0, 1;
  EXPECT_LT((T.matrix() - expected).norm(), 1e-15);
}

TEST(Model, ModifiedDhLinkMatchesClosedFormMatrix) {
  // Craig's modified D–H: Rx(α) Tx(a) Rz(θ) Tz(d).
  const double a = 0.3, alpha = 0.7, d = 0.2, theta = -0.4, q = 0.9;
  ModelBuilder b("one");
  b.ModifiedDhLink(a, alpha, d, theta, Rev("j1"));
  const KinematicModel m = b.Build();
  const Eigen::Isometry3d T = m.ToolFrame(Eigen::VectorXd::Constant(1, q), m.Nominal());
  const double ct = std::cos(theta + q), st = std::sin(theta + q);
  const double ca = std::cos(alpha), sa = std::sin(alpha);
  Eigen::Matrix4d expected;
  expected << ct, -st, 0, a,           //
      st * ca, ct * ca, -sa, -sa * d,  //
      st * sa, ct * sa, ca, ca * d,    //
      0, 0, 0, 1;
  EXPECT_LT((T.matrix() - expected).norm(), 1e-15);
}

TEST(Model, Grb3016ZeroPoseMatchesHandComputation) {
  // At q = 0 with the Table 1 offsets the arm stands in its documented zero posture; position of
  // the flange (zero tool) computed by hand from the D–H table:
  // x = a1 + a2·cos(−π/2)... evaluated numerically below link by link.
  const KinematicModel m = Grb3016(0, 0, 0, 0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  const double dh[6][4] = {{0.150, -kPi / 2, 0.250, 0.0}, {0.570, -kPi, 0.0, -kPi / 2},
                           {0.150, kPi / 2, 0.0, 0.0},    {0.0, -kPi / 2, 0.645, 0.0},
                           {0.0, kPi / 2, 0.0, -kPi / 2}, {0.0, 0.0, -0.200, 0.0}};
  for (const auto& l : dh) {
    Eigen::Isometry3d A = Eigen::Isometry3d::Identity();
    A.linear() = geometry::Rz(l[3]) * geometry::Rx(l[1]);
    A.translation() = Eigen::Vector3d(l[0] * std::cos(l[3]), l[0] * std::sin(l[3]), l[2]);
    T = T * A;
  }
  const Eigen::Isometry3d Tm = m.ToolFrame(Eigen::VectorXd::Zero(6), m.Nominal());
  EXPECT_LT((Tm.matrix() - T.matrix()).norm(), 1e-14);
}

TEST(Model, WrongSizesAreRejectedWithTheirName) {
  const KinematicModel m = Grb3016();
  try {
    m.Forward(Eigen::VectorXd::Zero(5), m.Nominal());
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("q has 5 joints"), std::string::npos);
  }
  EXPECT_THROW(m.Forward(Eigen::VectorXd::Zero(6), Eigen::VectorXd::Zero(3)),
               std::invalid_argument);
}

TEST(Model, ParameterCountsAndNames) {
  const KinematicModel grb = Grb3016();
  EXPECT_EQ(grb.num_params(), 28);  // 4(N+1), as the paper
  EXPECT_EQ(grb.FindParameter("d3"), 9);
  EXPECT_EQ(grb.FindParameter("tool_alpha"), 27);
  const KinematicModel seven = SevenJointSetup();
  EXPECT_EQ(seven.num_params(), 6 + 28 + 3 + 3 + 3);
  EXPECT_EQ(UrLikeUrdf().num_params(), 6 + 36 + 3);
}

}  // namespace
}  // namespace rcal::kinematics
