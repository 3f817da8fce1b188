// Low-pass filters of the orientation KF's sensor inputs (orientation_kf.hpp), for a step dt [s]
// and a time constant τ [s]:
//   first order: y ← y + α (x − y), α = 1 − exp(−dt / τ), the exact discretisation of τ ẏ = x − y
//     for an input held over the step; magnitude 1/√(1 + (f/f_c)²), f_c = 1/(2π τ).
//   second-order Butterworth: cutoff f_c = √2 / (2π τ), so that its group delay at DC is τ, as
//     the first-order filter's; magnitude 1/√(1 + (f/f_c)⁴), falling as f⁻² instead of f⁻¹ above
//     the cutoff. Discretised by the bilinear transform with the cutoff prewarped: magnitude
//     exactly 1/√(1 + (tan(π f dt) / tan(π f_c dt))⁴). Direct form I:
//       y_k = b0 x_k + b1 x_{k−1} + b2 x_{k−2} − a1 y_{k−1} − a2 y_{k−2}.
//     VQF (Laidig & Seel 2023) low-passes the accelerometer so, with τ = 3 s.
#pragma once

namespace rcal::estimation {

/// α of the first-order low-pass for a step dt [s] and time constant tau [s]; 1 (no filtering)
/// when tau ≤ 0.
double FirstOrderLowPassGain(double dt, double tau);

/// Coefficients of the second-order Butterworth low-pass (header comment). DC gain 1:
/// (b0 + b1 + b2) / (1 + a1 + a2) = 1, so a constant input is passed unchanged.
struct Butterworth2 {
  double b0 = 1.0, b1 = 0.0, b2 = 0.0, a1 = 0.0, a2 = 0.0;
  /// For a step dt [s] and time constant tau [s], 0 < dt < π τ / √2 (the cutoff below Nyquist).
  static Butterworth2 LowPass(double dt, double tau);
};

}  // namespace rcal::estimation
