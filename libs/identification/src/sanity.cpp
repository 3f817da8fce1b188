#include "rcal/identification/sanity.hpp"

#include <cmath>
#include <cstdio>
#include <numbers>

namespace rcal::identification {
namespace {

/// v with `digits` significant digits.
std::string Sig(double v, int digits = 3) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*g", digits, v);
  return buf;
}

std::string Mm(double m) {
  return Sig(m * 1e3) + " mm";
}

/// A ratio: whole above 100, else 2 significant digits.
std::string Times(double v) {
  return (v >= 100 ? Sig(std::round(v), 15) : Sig(v, 2)) + "×";
}

bool Given(double v) {
  return std::isfinite(v);
}

std::string Robot(const CalibrationFigures& f) {
  return f.robot.empty() ? "the robot file" : "'" + f.robot + "'";
}

}  // namespace

std::vector<std::string> CalibrationImplausible(const CalibrationFigures& f,
                                                const CalibrationSanityBounds& b) {
  std::vector<std::string> out;
  const std::string wrong_arm = "is this the robot that was measured (" + Robot(f) +
                                ")? Another arm's file, a chain ending at the wrong link "
                                "(--tip, --base-link) or joint zeros in another convention?";
  // 1. The drawing misses by a sizeable part of the arm's reach.
  if (Given(f.nominal_rms_position_m) && Given(f.arm_reach_m) && f.arm_reach_m > 0) {
    const double fraction = f.nominal_rms_position_m / f.arm_reach_m;
    if (fraction > b.nominal_fraction_of_reach)
      out.push_back(
          "the drawing with only the set-up frames fitted misses the measured positions "
          "by " +
          Mm(f.nominal_rms_position_m) + " RMS, " + Sig(fraction, 2) + " of the arm's reach (" +
          Sig(f.arm_reach_m) + " m): as if every joint were " +
          Sig(fraction * 180.0 / std::numbers::pi, 2) + "° off, where a drawing of " +
          "the measured arm misses by millimetres (refused beyond " +
          Sig(b.nominal_fraction_of_reach) + " of the reach)" +
          (Given(f.heldout_rms_position_m)
               ? "; held-out error after calibration " + Mm(f.heldout_rms_position_m) + " RMS"
               : std::string()) +
          ": " + wrong_arm);
  }
  // 2. The calibration does not predict what it did not fit.
  if (Given(f.heldout_rms_position_m) && Given(f.position_sigma_m) &&
      Given(f.heldout_nominal_rms_position_m)) {
    const double noise = std::sqrt(3.0) * f.position_sigma_m;
    if (f.heldout_rms_position_m > b.heldout_factor * noise &&
        f.heldout_rms_position_m > b.heldout_factor * f.heldout_nominal_rms_position_m)
      out.push_back(
          "held-out error " + Mm(f.heldout_rms_position_m) + " RMS after calibration, " +
          Times(f.heldout_rms_position_m / noise) + " what the noise allows (" + Mm(noise) +
          ") and " + Times(f.heldout_rms_position_m / f.heldout_nominal_rms_position_m) +
          " the drawing's (" + Mm(f.heldout_nominal_rms_position_m) +
          "): the calibration does not predict poses it did not fit (refused beyond " +
          Sig(b.heldout_factor) + "× both): too few poses for the parameters, or " + wrong_arm);
  }
  // 3. Noise no sensor has.
  if (Given(f.position_sigma_m) && f.position_sigma_m > b.max_position_sigma_m)
    out.push_back("position noise estimated from the residuals " + Mm(f.position_sigma_m) +
                  " per axis, beyond any position sensor (" + Mm(b.max_position_sigma_m) +
                  "): the calibrated model does not describe the data: is each row's position "
                  "measured at its joints (the same instant, the same marker)? " +
                  wrong_arm);
  if (Given(f.orientation_sigma_rad) && f.orientation_sigma_rad > b.max_orientation_sigma_rad)
    out.push_back("orientation noise estimated from the residuals " +
                  Sig(f.orientation_sigma_rad * 180.0 / std::numbers::pi) +
                  "° per axis, beyond any orientation sensor (" +
                  Sig(b.max_orientation_sigma_rad * 180.0 / std::numbers::pi) +
                  "°): the calibrated model does not describe the data: are the orientations of "
                  "the IMU on this tool, a unit quaternion w, x, y, z? " +
                  wrong_arm);
  // 4. A sequential fit that took no pose, or rejected most.
  if (f.poses == 0) out.push_back("no pose was given to the fit: nothing was calibrated");
  if (f.poses > 0 && f.poses_rejected >= 0 && f.poses_rejected > b.max_rejected_fraction * f.poses)
    out.push_back("the EKF rejected " + std::to_string(f.poses_rejected) + " of " +
                  std::to_string(f.poses) + " poses at its innovation gate (refused beyond " +
                  Sig(100 * b.max_rejected_fraction) +
                  " %): the model does not describe the measurements: set-up frames (world ← "
                  "base, flange → marker) far from where the EKF starts them (is the cell file the "
                  "cell that was recorded, its frames fixed, prior or guess as they are)? Or " +
                  wrong_arm);
  return out;
}

}  // namespace rcal::identification
