// The simulated cell against its own truth: the base set is the drawing's full rank with every
// set-up frame in it and no D–H tool parameter; the truth on the base set reproduces the truth
// robot; the still windows of a short run agree with the truth within their covariance; the
// set-up guess lands near the truth frames; the online EKF brings the test poses to a fraction of
// a millimetre.
#include "rcal/cell/sim_cell.hpp"

#include <gtest/gtest.h>

#include <algorithm>

#include "rcal/identification/calibration.hpp"
#include "rcal/io/robot_urdf.hpp"

namespace rcal::cell {
namespace {

const io::LoadedRobot& Grb3016() {
  static const io::LoadedRobot robot = io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  return robot;
}

TEST(SimCell, BaseSetIsFullRankWithEverySetUpFrameAndNoToolParameter) {
  const Cell c = MakeCell(Grb3016().spec, 1);
  const auto& m = c.model;
  EXPECT_EQ(static_cast<int>(c.base.size()), c.ident.rank);
  EXPECT_EQ(c.ident.rank, 32);
  EXPECT_EQ(c.setup.size(), 15u);
  for (int i : c.setup)
    EXPECT_TRUE(std::binary_search(c.base.begin(), c.base.end(), i)) << m.parameters()[i].name;
  for (int i : c.base) EXPECT_NE(m.parameters()[i].group, "tool") << m.parameters()[i].name;
  // The truth restated on the base set moves no pose (dense noise-free poses, LM).
  EXPECT_LT(c.eq_residual_m, 1e-6);  // 1 µm: 30× below the sensor noise
}

TEST(SimCell, WindowsSetUpGuessAndOnlineEkfAgainstTheTruth) {
  const Cell c = MakeCell(Grb3016().spec, 2);
  RunSettings rs;
  rs.seed = 2;
  rs.num_cal = 30;
  rs.num_test = 10;
  const Windows w = SimulateWindows(c, rs);
  ASSERT_EQ(w.cal.size(), 30u);
  ASSERT_EQ(w.test.size(), 10u);
  EXPECT_EQ(w.missing, 0);
  // Windows vs truth: sub-millimetre, and a NEES near its 6 degrees of freedom.
  EXPECT_LT(w.mean_position_error_m, 5e-4);
  EXPECT_GT(w.mean_nees, 2.0);
  EXPECT_LT(w.mean_nees, 15.0);

  const Eigen::VectorXd x0 = SetupGuess(c, {w.cal.begin(), w.cal.begin() + 6});
  for (const char* name : {"base_x", "base_y", "base_z"}) {
    const int i = c.model.FindParameter(name);
    EXPECT_NEAR(x0(i), c.x_true(i), 0.03) << name;  // the arm's 26 mm of errors remain
  }
  for (const char* name : {"base_rz", "earth_rz", "imu_rz"}) {
    const int i = c.model.FindParameter(name);
    EXPECT_NEAR(x0(i), c.x_true(i), 0.06) << name;  // the arm's 3.2° of errors remain
  }

  std::vector<Eigen::VectorXd> test_q;
  for (const auto& m : w.test) test_q.push_back(m.q);
  const OnlineResult r = RunOnline(c, w.cal, test_q);
  EXPECT_EQ(r.accepted + r.rejected, 30);
  EXPECT_GT(r.test_error_after_pose_mm.front(), 1.0);
  EXPECT_LT(r.test_error_after_pose_mm.back(), 0.1);
  // Every base parameter within 4σ of the truth restated on the base set.
  for (int i : c.base) {
    EXPECT_LT(std::abs(r.x(i) - c.x_eq(i)), 4 * r.sigma(i) + 1e-9) << c.model.parameters()[i].name;
  }
}

}  // namespace
}  // namespace rcal::cell
