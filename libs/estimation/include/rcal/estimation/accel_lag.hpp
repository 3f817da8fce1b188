// The accelerometer's lag behind its stamps, measured from a recording: the position sensor's
// second differences against the accelerometer turned into the position sensor's frame (beyond
// the paper; PositionKfSettings::accel_delay takes it out online).
//
// Why: a MEMS accelerometer low-passes internally, so a sample stamped t is the specific force of
// t − δ. In fast motion that is an error of the jerk times δ, and the position KF integrates it
// (BROAD's fast translation: jerks of ~100 m/s³, δ ≈ 2.2 ms, 0.2 m/s² per axis). δ belongs to the
// IMU (and its configuration), not to a trial, so it is measured once, like the lever arm.
//
// Model. Three consecutive position samples p₀, p₁, p₂ at t₀ < t₁ < t₂ (the marker, frame W) give
// twice their second divided difference,
//   y = 2 ((p₂ − p₁)/(t₂ − t₁) − (p₁ − p₀)/(t₁ − t₀)) / (t₂ − t₀) = ∫ p̈(s) M(s) ds,
// M the hat (linear B-spline) on [t₀, t₂] peaked at t₁ with unit integral (Peano kernel of the
// divided difference; exact for any motion). The accelerometer's side is the same integral of the
// marker's acceleration, by the trapezoid over the IMU samples in [t₀, t₂]:
//   p̈_M(s) = R_WB(s) f_B(s + δ) − g·up + R_WB(s) ([α_B]× + [ω_B]×²) r_B − b_W,
// the sensor reading late in its own axes (f_B(s) is the body's specific force of s − δ), so,
// linearised in δ, R_WB f_B(s + δ) ≈ R_WB (f_B + δ ḟ_B)(s) (ḟ_B by central differences between
// samples). With a = R_WE (R_EB f_B − g·up_E),
//   y − ∫ a M = δ ∫ R_WB ḟ_B M + (∫ R_WB ([α]× + [ω]×²) M) r_B − b_W.
// δ's column R_WB ḟ_B = ȧ − ω_W × (a + g·up) holds the jerk and the gravity turned by the body's
// rotation over δ (a tilt rate of 2 rad/s turns g by 0.1 m/s² over 5 ms, more than the jerk of a
// slow translation gives; a column of ȧ alone missed it: the lag scattered by ~0.5 ms between
// simulated streams whose σ said 0.1 ms). So
// linear in θ = (δ, r_B, b_W): seven unknowns, three rows per triplet, solved by least squares,
// reweighted (Huber's weight per triplet, on its largest residual over the robust σ of its axis)
// so that a tap or a glitch of the position sensor does not pull δ; a triplet whose span holds an
// IMU gap is not used. r_B and b_W are PositionKf's (the IMU → marker lever arm; the world-frame
// accelerometer bias, where the orientation's tilt error g × δθ shows). The triplets overlap
// (neighbours share two samples), so the residuals are correlated and the least-squares σ is
// wrong: σ_δ is the delete-one-block jackknife over B contiguous blocks of triplets,
// σ² = (B − 1)/B Σ (δ₋b − δ̄)² (a block at rest only adds nothing and removes nothing).
//
// The position sensor's frame (estimate_R_WE, beyond the paper): where a cell only guesses
// earth_from_world, a wrong R_WE turns the acceleration by its error (the linear acceleration,
// not gravity, which is removed in E). It is estimated from the same triplets: first aligned in
// closed form (Kabsch: the rotation that best turns the centred ∫ a_E M onto the centred y, a
// constant bias dropping out; refused when the acceleration spans less than a plane), then
// refined by Gauss–Newton with δ, r_B and b_W on a small rotation φ of W, R_WE ← Exp(φ) R_WE,
// whose columns are −[R_WE ∫ a_E M]× (ten unknowns, re-linearised until |φ| < 1e-10).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "rcal/estimation/fqa.hpp"
#include "rcal/estimation/result.hpp"

namespace rcal::estimation {

/// A recording for EstimateAccelLag: the IMU stream (time [s], specific force f_B [m/s²], the
/// orientation estimate R_EB (body → earth) and the body rate ω_B [rad/s], bias removed) and the
/// position sensor's samples (time [s], marker position p_WM_W [m] in its frame W). Both in time
/// order, on the same clock.
struct AccelLagData {
  std::vector<double> t_imu;
  std::vector<Eigen::Vector3d> f_B;
  std::vector<Eigen::Matrix3d> R_EB;
  std::vector<Eigen::Vector3d> omega_B;
  std::vector<double> t_position;
  std::vector<Eigen::Vector3d> p_WM_W;
};

struct AccelLagSettings {
  EarthFrame earth = EarthFrame::kNed;
  double gravity = 9.81;  ///< [m/s²]
  /// The position sensor's frame W against the earth frame E (PositionKf::SetWorldFromEarth).
  Eigen::Matrix3d R_WE = Eigen::Matrix3d::Identity();
  /// Estimate R_WE as well (a real cell whose tracker frame is only guessed): aligned in closed
  /// form, then refined with the rest (header comment); R_WE above is then not used.
  bool estimate_R_WE = false;
  /// Each triplet's outer position samples are the first at least this far from its middle one
  /// [s]; 0: the neighbours. A tracker of 100 Hz or more gives second differences over its own
  /// steps that are mostly noise (0.1 mm over 10 ms: 2.4 m/s²); 0.05 s is a 20 Hz tracker's.
  double min_position_step = 0.0;
  /// A triplet whose two steps differ by more than this factor, or whose span holds an IMU step
  /// longer than max_imu_step, is not used (a dropped sample or a gap).
  double max_step_ratio = 1.5;
  double max_imu_step = 0.05;  ///< [s]
  int blocks = 8;              ///< contiguous blocks of the jackknife for σ_δ (header comment)
  /// Fewest usable triplets per block: fewer and the estimate is refused.
  int min_triplets_per_block = 20;
};

/// Huber's k on the normalised residual [-] (95 % efficiency under Gaussian noise).
inline constexpr double kAccelLagHuber = 1.345;

struct AccelLagEstimate {
  double delay = 0.0;        ///< δ [s]: a sample stamped t is the specific force of t − δ
  double delay_sigma = 0.0;  ///< its standard error, by the blocks' jackknife [s]
  Eigen::Vector3d lever_arm_B = Eigen::Vector3d::Zero();  ///< IMU → marker r_B [m]
  Eigen::Vector3d bias_W = Eigen::Vector3d::Zero();       ///< b_W [m/s²], as PositionKf's
  /// The frame used: the settings' R_WE, or the estimate (R_WE_estimated).
  Eigen::Matrix3d R_WE = Eigen::Matrix3d::Identity();
  bool R_WE_estimated = false;
  int triplets = 0;           ///< position triplets used
  double residual_rms = 0.0;  ///< per axis, after the fit [m/s²]
  double jerk_rms = 0.0;      ///< RMS of ∫ R_WB ḟ_B M per axis [m/s³]: what δ is read from
};

/// δ, r_B and b_W by the model of the header comment. Refused, naming the field, when the data
/// are not finite, not in time order, of unequal lengths, or too few triplets are usable.
Result<AccelLagEstimate> EstimateAccelLag(const AccelLagData& data,
                                          const AccelLagSettings& settings = {});

}  // namespace rcal::estimation
