// One seeded calibration of `rcal calibration-sweep` (cmd_calibration_sweep.cpp) and its scoring,
// apart so that tests can call them (issue 12, item 1: the arm test matrix).
//
// Per seed: a truth arm (Gaussian geometric errors on the arm's parameters plus random set-up
// frames: world ← base metres away at any yaw with some tilt, flange → marker 5–15 cm, flange →
// IMU any rotation), calibration and independent test poses inside the joint limits, measured
// with Gaussian noise; identification::Calibrate with its default settings from a starting noise
// that is deliberately wrong; scored against the truth: identified count against the rank of the
// identification Jacobian at the truth, estimated/true noise, test-pose error against its
// Cramér–Rao prediction.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::tool {

/// The seed of one run: a hash of the robot's name, the mode (full pose / positions only) and the
/// seed index, so that a run's data do not depend on --jobs or on which other runs happen.
std::uint64_t CalibrationSeed(std::string_view robot, bool position_only, unsigned seed_index);

struct CalibrationSweepSettings {
  int poses = 200;       ///< calibration poses
  int test_poses = 100;  ///< independent poses the result is judged on (never fitted)
  bool position_only = false;
  double position_sigma_m = 5e-5;         ///< measurement noise per axis
  double orientation_sigma_rad = 8.7e-4;  ///< per axis (full pose only)
  double length_error_sigma_m = 5e-4;     ///< truth: σ of the arm's length errors
  double angle_error_sigma_rad = 1e-3;    ///< truth: σ of the arm's angle errors
  double start_noise_factor = 2.0;        ///< the noise Calibrate starts from, × the truth
};

struct CalibrationSeedResult {
  unsigned seed_index = 0;
  std::uint64_t seed = 0;
  int num_params = 0;
  int identified = 0;     ///< parameters Calibrate identified
  int rank_at_truth = 0;  ///< rank of the identification Jacobian at the truth, cal poses
  /// Column-scaled singular values at the truth around the rank: the last one kept and the first
  /// one dropped (0 when there is none), to see how clear the rank is.
  double last_kept_singular_value = 0, first_dropped_singular_value = 0;
  double position_noise_ratio = 0;     ///< estimated / true position σ
  double orientation_noise_ratio = 0;  ///< estimated / true orientation σ (0: positions only)
  /// The noise this seed's measurements happen to carry (RMS per axis at the truth) / the true
  /// σ: 200 poses give σ to about ±3 %, so an estimate far from 1 is judged against this.
  double realized_position_noise_ratio = 0, realized_orientation_noise_ratio = 0;
  double test_position_m = 0;  ///< mean test-pose position error against the truth
  double cr_position_m = 0;    ///< its Cramér–Rao prediction (truth, identified set)
  double test_orientation_rad = 0, cr_orientation_rad = 0;  ///< full pose only
  double position_ratio = 0;                                ///< test_position_m / cr_position_m
  double orientation_ratio = 0;                             ///< full pose only
  int lm_iterations = 0;                                    ///< of the last LM solve
  double cost = 0;     ///< Σ rᵀR⁻¹r at the estimate (noise as estimated)
  double x_norm = 0;   ///< |x| of the estimate over the arm's (non set-up) parameters
  double seconds = 0;  ///< CPU time of Calibrate (this thread)
};

/// The simulated cell of one run: the truth, the poses and the measurements (with the true
/// noise's covariance), drawn from the run's seed.
struct SweepCell {
  std::uint64_t seed = 0;
  Eigen::VectorXd x_true;  ///< [m | rad], set-up frames included
  std::vector<Eigen::VectorXd> cal_q, test_q;
  std::vector<kinematics::PoseMeasurement> measured;  ///< at cal_q
};
SweepCell MakeSweepCell(const kinematics::KinematicModel& model, std::string_view robot_name,
                        const CalibrationSweepSettings& settings, unsigned seed_index);

/// One seeded run on `model` (the robot as `rcal calibrate` loads it: set-up frames added, and the
/// flange → IMU rotation for full pose). `robot_name` seeds it (CalibrationSeed).
CalibrationSeedResult RunCalibrationSeed(const kinematics::KinematicModel& model,
                                         std::string_view robot_name,
                                         const CalibrationSweepSettings& settings,
                                         unsigned seed_index);

/// Median (type 7), minimum and maximum of the finite values.
struct RatioSummary {
  int n = 0;
  double median = 0, min = 0, max = 0;
};
RatioSummary SummarizeRatios(std::vector<double> v);

}  // namespace rcal::tool
