// The simulated calibration cell of the paper's experiments from raw sensor streams (issue 4): the
// truth cell, its simulated sensor streams through the pose pipeline (still windows), the set-up
// guess and the online EKF. One library so that `rcal experiment paper --sensors`, the live
// processes (sensor_acquisition --source sim, `rcal experiment paper --sensors`) and the tests
// build exactly the same cell, guess and base set.
//
// The cell. The arm of the robot file plus the set-up a real cell has, all unknown to the
// identifier and identified with the arm:
//   world ← base T_WB (position sensor frame; base_x … base_rx), earth ← world R_EW (magnetic
//   north arbitrary; earth_rz …), flange → marker p_FM (marker_x …), flange → IMU R_FI (imu_rz …).
// The drawing (nominal) says T_WB = I, R_EW = I, p_FM = kMarkerNominal, R_FI = I; the truth adds
// the Table 3 arm errors and the set-up values below. The identifier starts from a guess of the
// set-up frames fitted to the first poses (SetupGuess), as a user would after mounting.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::cell {

struct Cell {
  kinematics::KinematicModel model;  ///< arm + set-up frames
  Eigen::VectorXd x_true;            ///< Table 3 + set-up truth [m | rad]
  kinematics::IdentifiabilityReport ident;
  std::vector<int> base;   ///< identifiable (base) set
  std::vector<int> setup;  ///< set-up parameters (base, marker, imu, earth groups)
  Eigen::VectorXd x_eq;    ///< the truth expressed on the base set
  double eq_residual_m = 0;
};

/// The truth cell for the arm of `arm` (its base/marker/imu/earth entries are replaced).
Cell MakeCell(io::RobotSpec arm, unsigned seed);

/// The truth cell of any model (arm + set-up frames) at the truth `x_true` [m | rad]: the
/// identifiability, base set and truth on the base set as MakeCell(arm, seed) computes them
/// (draws seeded by `seed`), for measurements of `kind`. MakeCell(arm, seed) is this with its
/// model, its truth and full poses.
Cell MakeCell(kinematics::KinematicModel model, Eigen::VectorXd x_true, unsigned seed,
              kinematics::MeasurementKind kind);

struct RunSettings {
  unsigned seed = 1;
  int num_cal = 50, num_test = 50;
  int num_extra = 0;         ///< still poses after the test poses (peg-in-hole phase)
  double noise_scale = 1.0;  ///< multiplies every sensor noise (and the filters' σ)
  double still_time = 1.5;   ///< [s] at each stop
  bool gyro_bias = false;    ///< constant + random-walk gyro bias
  bool mag_disturbance = false;
  double dropout = 0.0;     ///< position-sensor dropout probability per sample
  bool orientation = true;  ///< false: position-only windows
};

struct Windows {
  std::vector<kinematics::PoseMeasurement> cal, test, extra;
  int emitted = 0, dropped = 0, missing = 0;   ///< missing: stops without a window
  double sim_wall_s = 0, pipeline_wall_s = 0;  ///< computation time [s]
  double duration_s = 0;                       ///< simulated time [s]
  double mean_position_error_m = 0, mean_orientation_error_rad = 0;  ///< windows vs truth
  double mean_nees = 0;  ///< of the windows vs truth (6 or 3 dof)
  int ticks = 0;
};

/// Simulates the streams of the cell along home + cal + test + extra stops and runs the pose
/// pipeline. Deterministic in settings.seed.
Windows SimulateWindows(const Cell& cell, const RunSettings& settings);

/// Set-up frames from measured poses: base from a rigid fit of the positions, earth and IMU
/// rotations from R_meas,k = R_EW A_k R_FI (rotation-vector alignment of pose pairs, then a
/// chordal mean). Other parameters 0.
Eigen::VectorXd SetupGuess(const Cell& cell, const std::vector<kinematics::PoseMeasurement>& ms);

/// The online identifier of the experiment, started at x0 on the base set.
identification::EkfIdentifier MakeEkf(const Cell& cell, const Eigen::VectorXd& x0);

/// Result of a run: the identifier fed with the cal windows (first `guess_poses` give x0).
struct OnlineResult {
  std::shared_ptr<identification::EkfIdentifier> ekf;  ///< still running (peg-in-hole phase)
  Eigen::VectorXd x0, x, sigma;
  std::vector<double> test_error_after_pose_mm;  ///< vs truth, after each pose
  std::vector<double> update_s;                  ///< computation per update [s]
  int accepted = 0, rejected = 0;
};
OnlineResult RunOnline(const Cell& cell, const std::vector<kinematics::PoseMeasurement>& cal,
                       const std::vector<Eigen::VectorXd>& test_q, int guess_poses = 6);

}  // namespace rcal::cell
