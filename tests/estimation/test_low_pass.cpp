// estimation/low_pass.hpp against the closed forms: the first-order filter's exact
// discretisation, the bilinear Butterworth's magnitude response and its group delay at DC.
#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <numbers>

#include "rcal/estimation/low_pass.hpp"

namespace {

using rcal::estimation::Butterworth2;
using rcal::estimation::FirstOrderLowPassGain;

// H(e^{jωdt}) of the direct form I coefficients.
std::complex<double> Response(const Butterworth2& c, double f_hz, double dt) {
  const std::complex<double> z1 = std::polar(1.0, -2.0 * std::numbers::pi * f_hz * dt);  // z⁻¹
  return (c.b0 + c.b1 * z1 + c.b2 * z1 * z1) / (1.0 + c.a1 * z1 + c.a2 * z1 * z1);
}

TEST(LowPass, FirstOrderIsTheExactDiscretisation) {
  // A unit step through n steps of dt leaves exp(−n dt / τ) of it.
  const double dt = 0.01, tau = 3.0;
  double y = 0.0;
  for (int k = 0; k < 300; ++k) y += FirstOrderLowPassGain(dt, tau) * (1.0 - y);
  EXPECT_NEAR(1.0 - y, std::exp(-3.0 / tau), 1e-12);
  EXPECT_EQ(FirstOrderLowPassGain(dt, 0.0), 1.0);
}

// To 1e-9: with τ ≫ dt the poles sit near z = 1 and 1 + a1 + a2 ≈ c² (c = tan(dt/(√2 τ)), 1.6e-7
// at τ = 9 s and dt = 5 ms), so rounding is amplified by 1/c².
TEST(LowPass, ButterworthMagnitudeIsTheBilinearClosedForm) {
  for (double dt : {0.01, 0.005}) {
    for (double tau : {0.5, 3.0, 9.0}) {
      const Butterworth2 c = Butterworth2::LowPass(dt, tau);
      EXPECT_NEAR((c.b0 + c.b1 + c.b2) / (1.0 + c.a1 + c.a2), 1.0, 1e-9);  // DC gain
      const double fc = std::numbers::sqrt2 / (2.0 * std::numbers::pi * tau);
      for (double f : {0.01, fc, 0.5, 2.0, 10.0}) {
        if (f >= 0.5 / dt) continue;
        const double w = std::tan(std::numbers::pi * f * dt) / std::tan(std::numbers::pi * fc * dt);
        EXPECT_NEAR(std::abs(Response(c, f, dt)), 1.0 / std::sqrt(1.0 + std::pow(w, 4)), 1e-9)
            << "dt " << dt << " tau " << tau << " f " << f;
      }
    }
  }
}

// Its group delay at low frequency is τ (the first-order filter's), and it holds a 0.5 Hz
// linear acceleration to about 2 % with τ = 3 s, where the first-order filter keeps about 11 %.
TEST(LowPass, ButterworthDelaysAsTauAndFallsAsTheSquareOfFrequency) {
  const double dt = 0.01, tau = 3.0;
  const Butterworth2 c = Butterworth2::LowPass(dt, tau);
  const double f = 1e-4, df = 1e-6;
  const double phase1 = std::arg(Response(c, f, dt)), phase2 = std::arg(Response(c, f + df, dt));
  const double delay = -(phase2 - phase1) / (2.0 * std::numbers::pi * df);
  EXPECT_NEAR(delay, tau, 1e-3 * tau);
  const double second = std::abs(Response(c, 0.5, dt));
  const double a = FirstOrderLowPassGain(dt, tau);
  const std::complex<double> z1 = std::polar(1.0, -2.0 * std::numbers::pi * 0.5 * dt);
  const double first = std::abs(a / (1.0 - (1.0 - a) * z1));
  // The analog magnitude 1/√(1 + (f/f_c)⁴), (f/f_c)⁴ = (2π f τ)⁴ / 4.
  EXPECT_NEAR(second, 1.0 / std::sqrt(1.0 + std::pow(2.0 * std::numbers::pi * 0.5 * tau, 4) / 4.0),
              1e-4);
  EXPECT_LT(second, 0.025);
  EXPECT_GT(first, 0.10);
}

}  // namespace
