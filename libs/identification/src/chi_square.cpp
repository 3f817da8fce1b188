#include "rcal/identification/chi_square.hpp"

#include <cmath>
#include <stdexcept>

namespace rcal::identification {
namespace {

// The continued fraction h of the regularised upper incomplete gamma, Q(a, x) =
// exp(−x + a ln x − ln Γ(a)) · h (Numerical Recipes; converges for x ≥ a + 1).
double GammaQContinuedFraction(double a, double x) {
  double b = x + 1.0 - a, c = 1.0 / 1e-300, d = 1.0 / b, h = d;
  for (int i = 1; i < 1000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < 1e-300) d = 1e-300;
    c = b + an / c;
    if (std::abs(c) < 1e-300) c = 1e-300;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::abs(del - 1.0) < 1e-15) break;
  }
  return h;
}

// Regularised lower incomplete gamma P(a, x) (Numerical Recipes: series below a + 1, continued
// fraction above).
double GammaP(double a, double x) {
  if (x <= 0) return 0.0;
  const double gln = std::lgamma(a);
  if (x < a + 1.0) {
    double ap = a, sum = 1.0 / a, del = sum;
    for (int n = 0; n < 1000; ++n) {
      ap += 1.0;
      del *= x / ap;
      sum += del;
      if (std::abs(del) < std::abs(sum) * 1e-15) break;
    }
    return sum * std::exp(-x + a * std::log(x) - gln);
  }
  return 1.0 - std::exp(-x + a * std::log(x) - gln) * GammaQContinuedFraction(a, x);
}

}  // namespace

double ChiSquareCdf(double x, double dof) {
  return GammaP(0.5 * dof, 0.5 * x);
}

double ChiSquareLogUpper(double x, double dof) {
  const double a = 0.5 * dof, h = 0.5 * x;
  if (h <= 0) return 0.0;
  // Below a + 1 the upper tail is not small (Q > ~0.1), so 1 − P loses nothing there.
  // Above, ln Q from the continued fraction in log form: finite where Q itself underflows.
  if (h < a + 1.0) return std::log1p(-GammaP(a, h));
  return -h + a * std::log(h) - std::lgamma(a) + std::log(GammaQContinuedFraction(a, h));
}

double ChiSquareQuantile(double p, double dof) {
  if (!(p > 0 && p < 1) || !(dof > 0))
    throw std::invalid_argument("ChiSquareQuantile: p must be in (0,1) and dof > 0");
  double lo = 0, hi = dof + 10 * std::sqrt(2 * dof) + 10;
  while (ChiSquareCdf(hi, dof) < p) hi *= 2;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (ChiSquareCdf(mid, dof) < p ? lo : hi) = mid;
    if (hi - lo < 1e-12 * hi) break;
  }
  return 0.5 * (lo + hi);
}

}  // namespace rcal::identification
