#include "rcal/estimation/fqa.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "rcal/geometry/so3.hpp"

namespace rcal::estimation {
namespace {

using geometry::QuatMultiply;

bool AllFinite(const Eigen::Vector3d& v) {
  return v.allFinite();
}

// cos(α/2), sin(α/2) from cos α and the sign of sin α (sgn(0) = +1).
std::pair<double, double> HalfAngle(double cos_a, double sin_a) {
  const double c = std::clamp(cos_a, -1.0, 1.0);
  const double ch = std::sqrt(0.5 * (1.0 + c));
  const double sh = std::sqrt(0.5 * (1.0 - c));
  return {ch, sin_a < 0.0 ? -sh : sh};
}

// Quarter and half turns of the measurement frame, q_B'B: identity first, so the plain FQA is
// used whenever the body is not far from level.
const std::array<Eigen::Vector4d, 6>& FrameTurns() {
  static const std::array<Eigen::Vector4d, 6> turns = [] {
    const double h = std::sqrt(0.5);
    return std::array<Eigen::Vector4d, 6>{
        Eigen::Vector4d(1, 0, 0, 0), Eigen::Vector4d(0, 1, 0, 0),    // I, Rx(π)
        Eigen::Vector4d(h, 0, h, 0), Eigen::Vector4d(h, 0, -h, 0),   // Ry(±π/2)
        Eigen::Vector4d(h, h, 0, 0), Eigen::Vector4d(h, -h, 0, 0)};  // Rx(±π/2)
  }();
  return turns;
}

}  // namespace

Eigen::Vector3d UpVector(EarthFrame frame) {
  return frame == EarthFrame::kNed ? Eigen::Vector3d(0, 0, -1) : Eigen::Vector3d(0, 0, 1);
}

Eigen::Vector3d MagneticNorth(EarthFrame frame) {
  return frame == EarthFrame::kNed ? Eigen::Vector3d(1, 0, 0) : Eigen::Vector3d(0, 1, 0);
}

Eigen::Vector4d QuatEnuFromNed() {
  // 180° about (1, 1, 0)/√2: x_E = y_N, y_E = x_N, z_E = −z_N.
  const double h = std::sqrt(0.5);
  return {0.0, h, h, 0.0};
}

Result<Eigen::Vector4d> Fqa(const Eigen::Vector3d& f_B, const Eigen::Vector3d& m_B,
                            const FqaSettings& settings) {
  using R = Result<Eigen::Vector4d>;
  if (!AllFinite(f_B)) return R::Error("fqa: accelerometer f_B is not finite");
  if (!AllFinite(m_B)) return R::Error("fqa: magnetometer m_B is not finite");
  if (!AllFinite(settings.m_ref_E)) return R::Error("fqa: reference field m_ref_E is not finite");
  const double f_norm = f_B.norm();
  const double m_norm = m_B.norm();
  if (!(f_norm > 0.0)) return R::Error("fqa: accelerometer f_B is zero");
  if (!(m_norm > 0.0)) return R::Error("fqa: magnetometer m_B is zero");

  // Reference horizontal direction N in NED.
  Eigen::Matrix3d R_NE = Eigen::Matrix3d::Identity();
  if (settings.earth == EarthFrame::kEnu) R_NE = geometry::QuatToMatrix(QuatEnuFromNed());
  const Eigen::Vector3d m_ref_N = R_NE * settings.m_ref_E;
  const double n_h = std::hypot(m_ref_N.x(), m_ref_N.y());
  if (!(n_h > settings.min_horizontal_fraction * m_ref_N.norm()) || !(n_h > 0.0))
    return R::Error("fqa: reference field m_ref_E has no horizontal component");
  const double N_x = m_ref_N.x() / n_h, N_y = m_ref_N.y() / n_h;

  // Measurement frame B' = C·B with gravity closest to B'’s down axis (see header).
  const Eigen::Vector3d a_B = f_B / f_norm;
  const auto& turns = FrameTurns();
  int best = 0;
  double best_down = -2.0;
  for (int i = 0; i < static_cast<int>(turns.size()); ++i) {
    const double down = -(geometry::QuatToMatrix(turns[i]) * a_B).z();
    if (down > best_down + 1e-12) {
      best_down = down;
      best = i;
    }
    if (i == 0 && down >= std::sqrt(0.5)) break;  // plain FQA: |sin θ| ≤ 1/√2
  }
  const Eigen::Vector4d q_BpB = turns[best];
  const Eigen::Matrix3d R_BpB = geometry::QuatToMatrix(q_BpB);
  const Eigen::Vector3d a = R_BpB * a_B;
  const Eigen::Vector3d m = R_BpB * (m_B / m_norm);

  // Elevation θ and roll φ (half-angle quaternions).
  const double sin_t = std::clamp(a.x(), -1.0, 1.0);
  const double cos_t = std::sqrt(std::max(0.0, 1.0 - sin_t * sin_t));
  const double sin_r = -a.y() / cos_t;
  const double cos_r = -a.z() / cos_t;
  const auto [ct2, st2] = HalfAngle(cos_t, sin_t);
  const auto [cr2, sr2] = HalfAngle(cos_r, sin_r);
  const Eigen::Vector4d q_e(ct2, 0.0, st2, 0.0);
  const Eigen::Vector4d q_r(cr2, sr2, 0.0, 0.0);
  const Eigen::Vector4d q_tilt = QuatMultiply(q_e, q_r);

  // Magnetometer in the levelled frame; azimuth from its horizontal part.
  const Eigen::Vector3d m_L = geometry::QuatToMatrix(q_tilt) * m;
  const double m_h = std::hypot(m_L.x(), m_L.y());
  if (!(m_h > settings.min_horizontal_fraction))
    return R::Error("fqa: magnetometer m_B is parallel to gravity (heading undefined)");
  const double M_x = m_L.x() / m_h, M_y = m_L.y() / m_h;
  const double cos_y = M_x * N_x + M_y * N_y;
  const double sin_y = N_y * M_x - N_x * M_y;
  const auto [cy2, sy2] = HalfAngle(cos_y, sin_y);
  const Eigen::Vector4d q_a(cy2, 0.0, 0.0, sy2);

  Eigen::Vector4d q_NB = QuatMultiply(QuatMultiply(q_a, q_tilt), q_BpB);
  Eigen::Vector4d q_EB =
      settings.earth == EarthFrame::kNed ? q_NB : QuatMultiply(QuatEnuFromNed(), q_NB);
  q_EB.normalize();
  if (q_EB(0) < 0.0) q_EB = -q_EB;
  if (!q_EB.allFinite()) return R::Error("fqa: internal error, non-finite quaternion");
  return q_EB;
}

}  // namespace rcal::estimation
