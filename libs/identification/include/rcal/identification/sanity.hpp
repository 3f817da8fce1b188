// Whether a calibration is one: the figures of a fit that describes no arm the robot file could
// be (another arm's file, a chain ending at the wrong link, joints or positions in other units, a
// fit that does not predict), refused with the likely cause named instead of written as a
// calibrated robot (issue 13, item 4).
//
// A calibration corrects a drawing by small amounts and then predicts the arm to the noise. Three
// tests, each on a figure the caller may or may not have (NaN: that test is skipped):
//
// 1. The drawing, with only the set-up frames fitted (world ← base, markers, IMU), misses the
//    measured positions by more than `nominal_fraction_of_reach` of the arm's reach (RMS): as if
//    every joint were 0.1 rad (5.7°) off. A real arm's drawing misses by millimetres (joint
//    offsets ≲ 1°, lengths ≲ 1 mm; the paper's deliberately large Table 3 errors: 26 mm on the
//    GRB3016), so no calibration of the measured arm needs that much; another arm's file does.
// 2. The calibrated model predicts poses it did not fit `heldout_factor` times worse than both
//    what the noise allows (√3·σ per axis, the RMS length of a 3-D noise vector; a correct model
//    predicts within a small factor of it, √(1 + p/N) for p parameters fitted to N values) and
//    the drawing's own held-out error: the fit is not determined by the data (too few poses,
//    another arm), an order of magnitude from anything a working calibration gives.
// 3. The noise estimated from the residuals is beyond any position sensor (`max_position_sigma_m`
//    per axis: laser trackers 0.01–0.05 mm, motion capture 0.1–1 mm, a camera a few mm) or any
//    orientation sensor (`max_orientation_sigma_rad`: IMUs and trackers 0.01–1°): what is left is
//    not noise but a model that does not describe the data.
// 4. A sequential fit (the EKF of `rcal calibrate --log` and ekf_identifier) rejected more than
//    `max_rejected_fraction` of the poses at its innovation gate, or had none to take: the model,
//    with its set-up frames where they start, does not describe the measurements (a sensor's
//    outliers are a few poses, not most).
#pragma once

#include <limits>
#include <string>
#include <vector>

namespace rcal::identification {

/// The figures a calibration is judged by [m, rad]; NaN: not available, that test is skipped.
struct CalibrationFigures {
  static constexpr double kAbsent = std::numeric_limits<double>::quiet_NaN();
  std::string robot;             ///< the robot file or model name, named in the messages
  double arm_reach_m = kAbsent;  ///< io::ArmReach(model, false): the drawing's reach
  /// The drawing with only the set-up frames fitted, RMS position error on the fitted poses
  /// (CalibrationFit::nominal_fit.rms_position_m; live: the set-up guess's residuals).
  double nominal_rms_position_m = kAbsent;
  /// On poses not fitted (HeldOutErrors): the drawing (set-up frames fitted) and the calibrated
  /// model, RMS position error (live: the RMS of the position innovations before each update).
  double heldout_nominal_rms_position_m = kAbsent;
  double heldout_rms_position_m = kAbsent;
  /// Noise per axis estimated from the residuals (NaN when given by the user, not estimated).
  double position_sigma_m = kAbsent;
  double orientation_sigma_rad = kAbsent;  ///< NaN or 0 when positions only
  /// A sequential fit: the poses it was given and those it rejected (its innovation gate);
  /// −1: not a sequential fit, test 4 skipped.
  int poses = -1;
  int poses_rejected = -1;
};

struct CalibrationSanityBounds {
  double nominal_fraction_of_reach = 0.1;  ///< test 1: 0.1 rad of every joint at the reach
  double heldout_factor = 10.0;            ///< test 2: an order of magnitude
  double max_position_sigma_m = 0.01;      ///< test 3 [m per axis]
  double max_orientation_sigma_rad = 0.1;  ///< test 3 [rad per axis]
  double max_rejected_fraction = 0.5;      ///< test 4: most poses
};

/// Why the calibration is no calibration, one sentence per failed test naming the figure, its
/// bound and the likely cause; empty when every available figure passes.
std::vector<std::string> CalibrationImplausible(const CalibrationFigures& figures,
                                                const CalibrationSanityBounds& bounds = {});

}  // namespace rcal::identification
