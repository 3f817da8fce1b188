#include "rcal/estimation/low_pass.hpp"

#include <cmath>
#include <numbers>

namespace rcal::estimation {

double FirstOrderLowPassGain(double dt, double tau) {
  return tau > 0.0 ? 1.0 - std::exp(-dt / tau) : 1.0;
}

Butterworth2 Butterworth2::LowPass(double dt, double tau) {
  // Prewarped bilinear transform of H(s) = ω_c² / (s² + √2 ω_c s + ω_c²), ω_c = √2 / τ:
  // c = tan(ω_c dt / 2), s → (1 − z⁻¹) / (1 + z⁻¹) in units where the prewarped ω_c is c.
  const double c = std::tan(std::numbers::sqrt2 / tau * dt / 2.0);
  const double d = c * c + std::numbers::sqrt2 * c + 1.0;
  const double b0 = c * c / d;
  return {b0, 2.0 * b0, b0, 2.0 * (c * c - 1.0) / d, (c * c - std::numbers::sqrt2 * c + 1.0) / d};
}

}  // namespace rcal::estimation
