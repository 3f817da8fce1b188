// A magnetometer's hard-iron offset, learned online from the field's norm (a sphere fit).
//
// A magnet or magnetised steel fixed to the sensor (a gripper's magnet, a phone strapped beside
// the IMU, BROAD's "attached magnet" trials) adds a field b_B that turns with the body:
//   m_B = R_EBᵀ m_E + b_B + n.
// Whatever the attitude, |m_B − b_B| = |m_E| = r: as the body turns, its samples lie on a sphere
// of radius r about b_B. This filter estimates x = [b_B, r] from that constraint alone, an EKF
// with the scalar measurement
//   0 = |m_B − b̂_B| − r̂ + v,   H = [−uᵀ, −1],   u = (m_B − b̂_B) / |m_B − b̂_B|,
// v white with σ = noise · m₀ (m₀ the first sample's norm). It needs no attitude, so it shares no
// error with the orientation filter that uses its offset (the gyro's scale errors, the
// accelerometer's linear accelerations), and a magnetometer's lag, a rotation, leaves the norm
// alone. b is observable only as the body turns: at rest only its component along the field is,
// traded against r, which its prior (norm_sigma) holds near m₀. So the first sample is taken as
// the earth's field: a magnet already on the sensor then is not found (its sphere's radius is
// wrong; the fit restarts and is not applied); one attached later is.
// A random walk on b follows a magnet that shifts on the tool. A sample whose innovation fails
// the χ² gate is not used; after restart_time of failures in a row b̂ starts again from zero, as
// at the first sample (a magnet attached or taken off: the sphere's centre moved), while r̂, the
// earth's field here, is kept.
// Units: the magnetometer's own; every setting is a fraction of m₀, so one set serves µT, gauss
// or raw counts.
// The offset is applied (offset_B() non-zero) only once it has been known in every direction
// (√tr P_bb below confident_sigma · m₀) and large (|b̂| above apply_floor · r̂) for settle_time.
// Below that floor a fit is not told apart from the magnetometer's own scale and soft-iron errors,
// which bend the norm by a few % with the attitude, nor from a magnet fixed in the room, which
// bends it with place: on BROAD's undisturbed and stationary-magnet trials the fit wanders to 2–10
// % of the field, while a magnet 2 cm from the sensor (trial 33) is 60 % of it.
#pragma once

#include <Eigen/Core>
#include <cstdint>

#include "rcal/estimation/result.hpp"

namespace rcal::estimation {

/// Settings of MagHardIron; fractions [-] of the first sample's field norm m₀ unless stated.
struct MagHardIronSettings {
  /// σ of one sample's norm [-] (the sensor's noise and its calibration errors).
  double noise = 0.02;
  /// Random walk of b [1/√s]: σ grows by random_walk · m₀ per √s.
  double random_walk = 0.001;
  /// σ of b at the start and after a restart [-] (a magnet up to about the field itself).
  double initial_sigma = 0.5;
  /// σ of r about the first sample's norm [-]: the first sample is taken as the earth's field
  /// (as the orientation KF takes its magnetic reference at rest). Loose (0.05–0.5), r drifts
  /// with the magnetometer's own errors and the fit can fall to |m − b| → 0 (on BROAD: r̂ 1.2 µT
  /// on ten trials at 0.5; 39–56 µT at 0.05 for a field of 44).
  double norm_sigma = 0.003;
  /// χ² gate (1 dof) on the norm innovation [-].
  double gate_chi2 = 25.0;
  /// Failures of the gate in a row for this long start the fit again [s].
  double restart_time = 2.0;
  /// Apply b̂ once √tr P_bb, the σ of its error vector, is below this [-].
  double confident_sigma = 0.01;
  /// ... and |b̂| exceeds this fraction of r̂ [-],
  double apply_floor = 0.2;
  /// ... both for this long in a row [s] (right after a start the covariance shrinks before a
  /// far b̂ has converged: simulated, 10–14 µT off for up to 4 s with no settling).
  double settle_time = 5.0;
};

/// Checks every MagHardIronSettings field (finite, in range); an error names the field.
Status CheckMagHardIronSettings(const MagHardIronSettings& s);

class MagHardIron {
 public:
  struct Counters {
    std::int64_t samples = 0;   ///< samples given
    std::int64_t gated = 0;     ///< samples the χ² gate refused
    std::int64_t restarts = 0;  ///< fits started again after restart_time of refusals
    std::int64_t applied = 0;   ///< samples for which the offset was applied
  };

  explicit MagHardIron(const MagHardIronSettings& settings = {});

  /// One magnetometer sample m_B [the sensor's unit] at time t [s], non-decreasing. A
  /// non-finite or zero sample, or a time that goes back, is refused and changes nothing; with
  /// settings CheckMagHardIronSettings refuses, every sample is refused with its error.
  Status Update(double t, const Eigen::Vector3d& m_B);

  /// The offset to subtract, b̂_B, while it is applied (header comment), else zero.
  Eigen::Vector3d offset_B() const;
  bool applied() const { return applied_; }
  /// The fit: b̂_B and r̂ [the sensor's unit], and its 4×4 covariance (order b, r).
  const Eigen::Vector3d& b_B() const { return b_B_; }
  double r() const { return r_; }
  const Eigen::Matrix4d& P() const { return P_; }
  /// √tr P_bb, the σ of b̂'s error vector [the sensor's unit] (at least its largest σ in any
  /// direction); infinite before the first sample.
  double b_sigma() const;
  const Counters& counters() const { return counters_; }
  const MagHardIronSettings& settings() const { return settings_; }

 private:
  void Start(double t, const Eigen::Vector3d& m_B);

  MagHardIronSettings settings_;
  Status settings_status_;
  bool started_ = false;
  double t_ = 0.0;
  double m0_ = 0.0;  // the first sample's norm: the scale of every setting
  Eigen::Vector3d b_B_ = Eigen::Vector3d::Zero();
  double r_ = 0.0;
  Eigen::Matrix4d P_ = Eigen::Matrix4d::Zero();
  double gated_time_ = 0.0;  // refusals in a row so far [s]
  double known_time_ = 0.0;  // known and large in a row so far [s]
  bool applied_ = false;
  Counters counters_;
};

}  // namespace rcal::estimation
