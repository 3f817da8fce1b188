#include "rcal/identification/setup_guess.hpp"

#include <gtest/gtest.h>

#include "../kinematics/test_robots.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::identification {
namespace {

// A 7-joint arm whose base stands 1.3 m away, turned 50°, three reflectors 5–13 cm off the
// flange, an IMU mounted at 30° and magnetic north 50° off: far from any linearisation.
struct Cell {
  kinematics::KinematicModel model;
  Eigen::VectorXd x_true;
};

Cell MakeCell(unsigned seed, double arm_sigma) {
  kinematics::ModelBuilder b("seven_cell");
  b.BaseFrame({0, 0, 0}, {0, 0, 0});
  kinematics::testing::SevenJointLinks(b)
      .MarkerOffset({0, 0, 0})
      .MarkerOffset({0, 0, 0}, true, 1)
      .MarkerOffset({0, 0, 0}, true, 2)
      .ImuMounting({0, 0, 0})
      .EarthFrame({0, 0, 0});
  Cell c{b.Build(), {}};
  sim::Rng rng(seed);
  c.x_true = sim::RandomErrors(c.model, rng, arm_sigma, arm_sigma * 2);
  const auto set = [&](const char* name, double v) { c.x_true(c.model.FindParameter(name)) = v; };
  const std::pair<const char*, double> truth[] = {
      {"base_x", 1.3},     {"base_y", -0.4},     {"base_z", 0.2},     {"base_rz", 0.87},
      {"base_ry", 0.05},   {"base_rx", -0.03},   {"marker_x", 0.12},  {"marker_y", -0.03},
      {"marker_z", 0.05},  {"marker1_x", -0.02}, {"marker1_y", 0.09}, {"marker1_z", 0.04},
      {"marker2_x", 0.01}, {"marker2_y", 0.02},  {"marker2_z", 0.13}, {"imu_rz", 0.52},
      {"imu_ry", -0.1},    {"imu_rx", 0.2},      {"earth_rz", 0.87},  {"earth_ry", 0.02},
      {"earth_rx", -0.01}};
  for (const auto& [name, v] : truth) set(name, v);
  return c;
}

std::vector<kinematics::PoseMeasurement> Measure(const Cell& c, int poses, double sigma_p,
                                                 double sigma_o, unsigned seed) {
  sim::Rng rng(seed);
  sim::PoseNoise noise;
  noise.position_sigma = sigma_p;
  noise.orientation_sigma = sigma_o;
  return sim::MeasureMarkers(c.model, c.x_true, sim::SampleJoints(c.model, poses, rng), noise, rng);
}

double SetupError(const Cell& c, const Eigen::VectorXd& x, const std::string& group) {
  double e = 0;
  for (int i = 0; i < c.model.num_params(); ++i)
    if (c.model.parameters()[i].group == group) e = std::max(e, std::abs(x(i) - c.x_true(i)));
  return e;
}

// The drawing is exact and the sensors noiseless: every set-up frame, each reflector's offset
// included, comes out exact from six stops, in closed form (no calibration behind it).
TEST(SetupGuess, ExactDataGiveTheSetupExactly) {
  const Cell c = MakeCell(1, 0.0);
  const auto ms = Measure(c, 6, 0.0, 0.0, 2);
  const SetupGuess g = GuessSetup(c.model, ms);
  for (const char* group : {"base", "marker", "imu", "earth"})
    EXPECT_LT(SetupError(c, g.x, group), 1e-9) << group;
  EXPECT_TRUE(g.outliers.empty());
  EXPECT_EQ(g.setup.size(), 6u + 9u + 3u + 3u);
  EXPECT_LT(g.rms_position_m, 1e-9);
  EXPECT_TRUE(g.covariance.allFinite());
}

// One bad stop among eight (the tracker measured another reflector: 40 cm off; or the IMU's
// orientation 30° off): left out, and the guess is what the seven good stops give; without the
// outlier test (max_outliers = 0) the same stop drags the guess by centimetres or degrees.
TEST(SetupGuess, ABadPoseIsLeftOut) {
  const Cell c = MakeCell(3, 0.0);
  auto ms = Measure(c, 8, 5e-5, 1e-3, 4);
  const SetupGuess clean = GuessSetup(c.model, ms);
  for (const bool orientation : {false, true}) {
    auto bad = ms;
    const int k = 13;  // stop 4, reflector 1
    if (orientation)
      bad[k].R_EI = geometry::Exp(Eigen::Vector3d(0.0, 0.52, 0.0)) * bad[k].R_EI;
    else
      bad[k].p_WM_W += Eigen::Vector3d(0.3, -0.2, 0.2);
    const SetupGuess g = GuessSetup(c.model, bad);
    ASSERT_EQ(g.outliers, std::vector<int>{k}) << (orientation ? "orientation" : "position");
    for (const char* group : {"base", "marker", "imu", "earth"})
      EXPECT_LT(SetupError(c, g.x, group), 2e-3) << group;
    SetupGuessSettings none;
    none.max_outliers = 0;
    const SetupGuess dragged = GuessSetup(c.model, bad, none);
    EXPECT_GT(SetupError(c, dragged.x, orientation ? "imu" : "base"), 1e-2)
        << (orientation ? "orientation" : "position");
  }
  EXPECT_TRUE(clean.outliers.empty());
}

// With the arm's own errors (2 mm / 4 mrad per parameter) the drawing misses by millimetres: the
// guess is then off by about that much, and its covariance says so (each frame's error within a
// few of its σ; a covariance from the sensor noise alone would be 100 times too small).
TEST(SetupGuess, TheCovarianceCoversTheDrawingsErrors) {
  int within = 0, total = 0;
  for (unsigned seed = 10; seed < 20; ++seed) {
    const Cell c = MakeCell(seed, 2e-3);
    const auto ms = Measure(c, 12, 5e-5, 1e-3, seed + 100);
    const SetupGuess g = GuessSetup(c.model, ms);
    ASSERT_TRUE(g.outliers.empty()) << "seed " << seed;
    for (size_t k = 0; k < g.setup.size(); ++k) {
      const int i = g.setup[k];
      const double z = std::abs(g.x(i) - c.x_true(i)) / std::sqrt(g.covariance(k, k));
      within += z < 3.0;
      ++total;
    }
    EXPECT_GT(g.rms_position_m, 1e-3) << "seed " << seed;  // the drawing's errors, not noise
  }
  // Gaussian would put 99.7 % within 3σ; the arm's errors are systematic, not independent noise.
  EXPECT_GT(within, 0.85 * total) << within << " of " << total;
  std::printf("set-up errors within 3 sigma: %d of %d\n", within, total);
}

TEST(SetupGuess, RefusesAForeignStart) {
  const Cell c = MakeCell(1, 0.0);
  EXPECT_THROW(GuessSetup(c.model, Measure(c, 3, 0, 0, 1), {}, Eigen::VectorXd::Zero(3)),
               std::invalid_argument);
  // Too few poses (two measurements): the frames stay where they were.
  auto two = Measure(c, 1, 0, 0, 1);
  two.resize(2);
  const SetupGuess g = GuessSetup(c.model, two);
  EXPECT_EQ(g.x.segment(0, 6), Eigen::VectorXd::Zero(6));
}

}  // namespace
}  // namespace rcal::identification
