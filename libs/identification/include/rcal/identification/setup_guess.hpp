// The set-up frames of a cell guessed from its first poses, before any calibration: where the
// tracker stands (world ← base), where each marker sits on the flange (flange → marker), how the
// IMU is mounted (flange → IMU) and where its earth frame points (earth ← world). The arm is taken
// at its drawing; its own errors (millimetres) are what is left in the residuals.
//
// Positions. The marker k of pose i is measured at
//   p_i = R_WB · (R_BF,i · p_FM,k + t_BF,i) + t_WB        (T_BF,i: the drawing's flange, base
//   frame)
// a registration of the tracker frame with unknown marker offsets. It is solved by alternating
// two closed forms until the set-up stops moving: the rigid alignment (Kabsch/Horn, with the
// reflection guard) of the drawing's marker points to the measured ones for (R_WB, t_WB), then
// the linear least squares in (t_WB, p_FM,k) for that rotation. Each step lowers the same sum of
// squares, so the alternation converges (to the joint least-squares optimum when the poses turn
// the flange enough to see the offsets; an offset direction they do not see stays nominal).
//
// Orientations. R_meas,i = R_EW · A_i · R_FI (A_i the drawing's orientation): a hand–eye problem.
// The rotation vectors of relative rotations obey Log(M_i M_jᵀ) = R_EW Log(A_i A_jᵀ), so R_EW is
// the Kabsch alignment of those vectors over all pairs, then R_FI the chordal mean of
// A_iᵀ R_EWᵀ M_i (with no earth frame in the model, R_FI alone by the chordal mean of A_iᵀ M_i).
//
// A bad pose (the tracker lost the reflector, a pose measured twice, a wrong joint reading) must
// not drag the guess: the pose with the largest residual is refitted out; if its residual against
// the others' fit exceeds `outlier_ratio` times their median, it is left out, and the next is
// tried (at most `max_outliers`). The arm's own errors make every residual millimetres, so the
// test is relative to the others, not to the sensor noise.
//
// Covariance: of the identifiable set-up parameters at the guess, from the linearised least
// squares over the poses kept, each block (positions, orientations) weighted by its own residual
// variance. It describes how well the poses fix the frames given the drawing's errors, the prior
// an identifier should start from.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::identification {

struct SetupGuessSettings {
  int max_iterations = 200;       ///< alternation rounds of the position registration
  double tolerance = 1e-12;       ///< [m | rad] stop when no set-up value moves more
  double outlier_ratio = 5.0;     ///< a pose this many times the others' median is left out
  int max_outliers = -1;          ///< −1: up to a quarter of the poses (at least 3 are kept)
  double rank_threshold = 1e-10;  ///< relative: offset directions the poses do not see stay nominal
};

struct SetupGuess {
  Eigen::VectorXd x;               ///< the model's errors: set-up frames guessed, the rest as given
  std::vector<int> setup;          ///< set-up parameters the poses identify (ascending)
  Eigen::MatrixXd covariance;      ///< of x(setup) [m², m·rad, rad²]
  std::vector<int> outliers;       ///< indices into the poses of those left out
  double rms_position_m = 0;       ///< residual of the poses kept, per pose (3-D) [m]
  double rms_orientation_rad = 0;  ///< the same for orientations [rad] (0 without)
  int iterations = 0;              ///< alternation rounds of the last registration
};

/// Guesses the set-up frames of `model` (parameter groups base, marker, imu, earth; frames the
/// model lacks are left alone) from poses `ms`, the rest of the model at `x0` (default: the
/// drawing). Fewer than 3 poses (3 orientations for the earth frame) leave those frames at x0.
SetupGuess GuessSetup(const kinematics::KinematicModel& model,
                      const std::vector<kinematics::PoseMeasurement>& ms,
                      const SetupGuessSettings& settings = {},
                      const Eigen::VectorXd& x0 = Eigen::VectorXd());

/// The set-up frames of x0 at a generic placement, for asking what a cell can identify before its
/// frames are known: a set-up frame at its nominal can sit where part of the model is invisible
/// (a marker at the flange origin lies on the last joint's axis, whose tilt then moves no
/// measured point), yet in any real cell those directions are seen. Seeded offsets: 5 cm on each
/// marker coordinate, 1 mm / 1 mrad on the other set-up parameters; the arm stays at x0.
Eigen::VectorXd GenericSetupPlacement(const kinematics::KinematicModel& model,
                                      const Eigen::VectorXd& x0, unsigned seed);

}  // namespace rcal::identification
