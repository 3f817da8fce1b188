// Factored Quaternion Algorithm (Yun, Bachmann, McGhee, IEEE Trans. Instrum. Meas. 57(3), 2008):
// the orientation of a body from one accelerometer and one magnetometer sample.
//
// Model (worked in NED internally; an ENU earth frame is mapped in and out exactly):
//   â = f_B / |f_B|  (specific force; at rest a level forward-right-down body reads [0, 0, −g])
//   elevation (pitch) θ:  sin θ = â_x,  cos θ = √(1 − â_x²)
//   roll φ:               sin φ = −â_y / cos θ,  cos φ = −â_z / cos θ
//   half angles:          cos(α/2) = √((1 + cos α)/2),  sin(α/2) = sgn(sin α) √((1 − cos α)/2)
//   q_e = [cos θ/2, 0, sin θ/2, 0],  q_r = [cos φ/2, sin φ/2, 0, 0]
//   m_L = q_e ⊗ q_r ⊗ m_B ⊗ (q_e ⊗ q_r)*      (magnetometer in the levelled frame)
//   M = (m_L,x, m_L,y)/|·|,  N = (m_ref,n, m_ref,e)/|·|   (horizontal directions)
//   cos ψ = M·N,  sin ψ = N_y M_x − N_x M_y,  q_a = [cos ψ/2, 0, 0, sin ψ/2]
//   q_NB = q_a ⊗ q_e ⊗ q_r                      (Hamilton, [w, x, y, z], body → NED)
// The magnetometer only enters q_a, a rotation about the vertical: it cannot change the tilt.
//
// Singularities. cos θ → 0 at pitch ±90° leaves roll undefined. As Yun et al. do, the
// measurement frame is rotated first: the body frame B' = C·B is chosen among six quarter/half
// turns so that the measured gravity is closest to B'’s "down" axis (|sin θ'| ≤ 1/√2), then
// q_NB = q_NB' ⊗ q_B'B. The result does not depend on that choice: it is the unique rotation
// that maps the measured gravity direction exactly onto the vertical and the horizontal part of
// the levelled magnetometer onto the reference's horizontal direction. At heading 180°,
// sgn(0) = +1 is used, so ψ = +π (q and −q are one rotation anyway). The returned quaternion is
// normalised with w ≥ 0.
//
// Bad input (non-finite, zero vectors, a magnetometer parallel to gravity, a reference field
// with no horizontal part) returns an error naming the field, never a NaN quaternion.
#pragma once

#include <Eigen/Core>

#include "rcal/estimation/result.hpp"

namespace rcal::estimation {

/// The earth frame the orientation maps into. Both are right-handed with z vertical.
enum class EarthFrame {
  kNed,  ///< x north, y east, z down (the paper's frame).
  kEnu,  ///< x east, y north, z up (BROAD's frame).
};

/// Unit vector pointing up in the earth frame ([0,0,−1] NED, [0,0,1] ENU).
Eigen::Vector3d UpVector(EarthFrame frame);
/// Quaternion [w,x,y,z] rotating NED coordinates into ENU (and back: it is its own inverse).
Eigen::Vector4d QuatEnuFromNed();

struct FqaSettings {
  /// Earth frame of the result and of `m_ref_E`.
  EarthFrame earth = EarthFrame::kNed;
  /// Reference magnetic field in the earth frame [any unit]. Only its horizontal direction is
  /// used: it defines heading zero. The default points to magnetic north in NED; use
  /// MagneticNorth(kEnu) = [0, 1, 0] for ENU with magnetic north on +y.
  Eigen::Vector3d m_ref_E = Eigen::Vector3d(1.0, 0.0, 0.0);
  /// The levelled magnetometer must keep at least this fraction of its norm horizontal [-];
  /// below it the heading is undefined and an error is returned.
  double min_horizontal_fraction = 1e-6;
};

/// Unit horizontal vector to magnetic north in `frame` (+x in NED, +y in ENU).
Eigen::Vector3d MagneticNorth(EarthFrame frame);

/// FQA orientation q_EB [w,x,y,z] (body → earth) from specific force f_B [m/s²] and magnetic
/// field m_B [any unit], both in the body (sensor) frame.
Result<Eigen::Vector4d> Fqa(const Eigen::Vector3d& f_B, const Eigen::Vector3d& m_B,
                            const FqaSettings& settings = {});

}  // namespace rcal::estimation
