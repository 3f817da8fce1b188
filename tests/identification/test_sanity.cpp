// Whether a calibration is one (identification/sanity.hpp, issue 13, item 4): the measured arm's
// fit passes, another arm's file, a sensor no calibration can use and a fit that predicts nothing
// are refused with the likely cause named.
#include "rcal/identification/sanity.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>

#include "rcal/identification/calibration.hpp"
#include "rcal/io/pose_dataset.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::identification {
namespace {

/// An arm of tests/data/arms in a cell: world ← base and the marker offset identified.
kinematics::KinematicModel Arm(const std::string& name) {
  io::UrdfOptions o;
  o.add_base_frame = true;
  o.add_marker = true;
  return io::LoadRobotUrdf(std::string(RCAL_SOURCE_DIR) + "/tests/data/arms/" + name + ".urdf", o);
}

/// `n` poses of `model`, positions only with `sigma` [m] per axis: the drawing with 0.5 mm /
/// 1 mrad errors on every joint placement, the base 1.5 m away, the marker 0.1 m off the flange.
std::vector<kinematics::PoseMeasurement> Measured(const kinematics::KinematicModel& model, int n,
                                                  double sigma, unsigned seed) {
  sim::Rng rng(seed);
  Eigen::VectorXd x = sim::RandomErrors(model, rng, 5e-4, 1e-3);
  for (int i = 0; i < model.num_params(); ++i) {
    const auto& P = model.parameters()[i];
    if (P.group == "base" && !P.is_angle) x(i) = 1.5;
    if (P.group == "marker") x(i) = 0.1;
  }
  sim::PoseNoise noise;
  noise.orientation = false;
  noise.position_sigma = sigma;
  return sim::MeasurePoses(model, x, sim::SampleJoints(model, n, rng), noise, rng);
}

/// The figures of calibrating `model` on `ms` as `rcal calibrate` takes them.
CalibrationFigures Judge(const kinematics::KinematicModel& model,
                         std::vector<kinematics::PoseMeasurement> ms) {
  SetNoise(ms, 1e-4, 0.0);  // the CLI's starting noise
  const CalibrationFit fit = Calibrate(model, ms);
  const HeldOutErrors held = HeldOut(model, ms, {}, fit);
  CalibrationFigures f;
  f.robot = model.name();
  f.arm_reach_m = io::ArmReach(model, false);
  f.nominal_rms_position_m = fit.nominal_fit.rms_position_m;
  f.heldout_nominal_rms_position_m = held.nominal.rms_position_m;
  f.heldout_rms_position_m = held.calibrated.rms_position_m;
  f.position_sigma_m = fit.position_sigma_m;
  return f;
}

std::string All(const std::vector<std::string>& reasons) {
  std::string s;
  for (const auto& r : reasons) s += r + "\n";
  return s;
}

// The KR6's poses calibrated with its own file pass on every seed; calibrated with the UR5e's
// (six revolute joints too, so nothing before the fit tells them apart) they are refused.
TEST(CalibrationSanity, AnotherArmsFileIsRefusedAndTheMeasuredArmsIsNot) {
  const kinematics::KinematicModel kr6 = Arm("kr6_like"), ur5e = Arm("ur5e_like");
  for (unsigned seed = 1; seed <= 3; ++seed) {
    SCOPED_TRACE(seed);
    const auto ms = Measured(kr6, 60, 5e-5, seed);
    const CalibrationFigures own = Judge(kr6, ms);
    EXPECT_EQ(All(CalibrationImplausible(own)), "");
    const CalibrationFigures other = Judge(ur5e, ms);
    const std::string why = All(CalibrationImplausible(other));
    EXPECT_NE(why.find("the drawing with only the set-up frames fitted misses the measured "
                       "positions by "),
              std::string::npos)
        << why;
    EXPECT_NE(why.find("is this the robot that was measured ('ur5e_like')?"), std::string::npos)
        << why;
    // The bound is a tenth of the reach; the wrong arm misses by several tenths, the right one by
    // a few thousandths.
    EXPECT_GT(other.nominal_rms_position_m, 0.2 * other.arm_reach_m);
    EXPECT_LT(own.nominal_rms_position_m, 0.01 * own.arm_reach_m);
  }
}

// A position sensor of 20 mm per axis is no calibration sensor: the estimated noise says so (the
// drawing still passes: its 35 mm RMS is within a tenth of the KR6's reach). 3 mm (a camera) is
// coarse but usable.
TEST(CalibrationSanity, NoiseNoPositionSensorHasIsRefused) {
  const kinematics::KinematicModel kr6 = Arm("kr6_like");
  const CalibrationFigures coarse = Judge(kr6, Measured(kr6, 60, 0.02, 4));
  EXPECT_NEAR(coarse.position_sigma_m / 0.02, 1.0, 0.2);
  const std::vector<std::string> why = CalibrationImplausible(coarse);
  ASSERT_EQ(why.size(), 1u) << All(why);
  EXPECT_EQ(why[0].find("position noise estimated from the residuals "), 0u) << why[0];
  EXPECT_NE(why[0].find(" per axis, beyond any position sensor (10 mm)"), std::string::npos)
      << why[0];
  EXPECT_EQ(All(CalibrationImplausible(Judge(kr6, Measured(kr6, 60, 0.003, 4)))), "");
}

// Test 2 needs both: many times the noise and many times the drawing's held-out error.
TEST(CalibrationSanity, AFitThatDoesNotPredictIsRefusedOnlyBeyondBothBounds) {
  CalibrationFigures f;
  f.robot = "arm.urdf";
  f.position_sigma_m = 1e-4;  // √3σ = 0.173 mm
  f.heldout_nominal_rms_position_m = 2e-3;
  f.heldout_rms_position_m = 0.0201;  // 116× the noise, 10.05× the drawing
  std::vector<std::string> why = CalibrationImplausible(f);
  ASSERT_EQ(why.size(), 1u) << All(why);
  EXPECT_EQ(why[0],
            "held-out error 20.1 mm RMS after calibration, 116× what the noise allows "
            "(0.173 mm) and 10× the drawing's (2 mm): the calibration does not predict poses it "
            "did not fit (refused beyond 10× both): too few poses for the parameters, or is this "
            "the robot that was measured ('arm.urdf')? Another arm's file, a chain ending at the "
            "wrong link (--tip, --base-link) or joint zeros in another convention?");
  f.heldout_rms_position_m = 0.0199;  // 9.95× the drawing
  EXPECT_EQ(All(CalibrationImplausible(f)), "");
  f.heldout_nominal_rms_position_m = 1e-3;
  f.position_sigma_m = 1.2e-3;  // 9.6× the noise
  EXPECT_EQ(All(CalibrationImplausible(f)), "");
  // A figure not given skips its test.
  f.position_sigma_m = CalibrationFigures::kAbsent;
  EXPECT_EQ(All(CalibrationImplausible(f)), "");
}

// Test 4, a sequential fit (the EKF of `rcal calibrate --log`): refused when it rejected more
// than half the poses or had none; a few outliers pass.
TEST(CalibrationSanity, AnEkfThatRejectedMostPosesOrHadNoneIsRefused) {
  CalibrationFigures f;
  f.robot = "arm.yaml";
  f.poses = 20;
  f.poses_rejected = 20;
  std::vector<std::string> why = CalibrationImplausible(f);
  ASSERT_EQ(why.size(), 1u) << All(why);
  EXPECT_EQ(why[0].find("the EKF rejected 20 of 20 poses at its innovation gate (refused beyond "
                        "50 %): the model does not describe the measurements: set-up frames "
                        "(world ← base, flange → marker) far from where the EKF starts them"),
            0u)
      << why[0];
  EXPECT_NE(why[0].find("Or is this the robot that was measured ('arm.yaml')?"), std::string::npos)
      << why[0];
  f.poses_rejected = 11;
  EXPECT_EQ(CalibrationImplausible(f).size(), 1u);
  f.poses_rejected = 10;  // half: not most
  EXPECT_EQ(All(CalibrationImplausible(f)), "");
  f.poses_rejected = 2;
  EXPECT_EQ(All(CalibrationImplausible(f)), "");
  f.poses = 0;
  f.poses_rejected = 0;
  EXPECT_EQ(All(CalibrationImplausible(f)),
            "no pose was given to the fit: nothing was calibrated\n");
  f.poses = -1;  // not a sequential fit
  EXPECT_EQ(All(CalibrationImplausible(f)), "");
}

// With as many parameters as measured values the fit passes through every pose: no residual to
// estimate the noise from. Was: a NaN covariance and "measurement 0: covariance: not finite".
TEST(CalibrationSanity, TooFewPosesToEstimateTheNoiseAreRefusedSayingSo) {
  const kinematics::KinematicModel kr6 = Arm("kr6_like");
  std::vector<kinematics::PoseMeasurement> ms = Measured(kr6, 8, 5e-5, 5);
  SetNoise(ms, 1e-4, 0.0);
  std::string what = "<no error>";
  try {
    Calibrate(kr6, ms);
  } catch (const std::exception& e) {
    what = e.what();
  }
  EXPECT_NE(what.find("calibration: 8 poses give 24 measured values for "), std::string::npos)
      << what;
  EXPECT_NE(what.find("the fit passes through every pose and leaves nothing to estimate the noise "
                      "from; measure more poses"),
            std::string::npos)
      << what;
}

}  // namespace
}  // namespace rcal::identification
