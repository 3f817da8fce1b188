#include "rcal/discrepancy/significance.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

namespace rcal::discrepancy {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// The z of the smallest positive double p (4.9e-324) and of the largest double below 1: beyond
// them a p written as a double is 0 or 1 and says nothing about z.
double ZOfSmallestP() {
  static const double z =
      NormalUpperQuantileLog(std::log(std::numeric_limits<double>::denorm_min()));
  return z;
}
double ZOfLargestP() {
  static const double z =
      NormalUpperQuantileLog(std::log1p(-std::numeric_limits<double>::epsilon() / 2));
  return z;
}

// The continued fraction of the incomplete beta function (Lentz's method; Numerical Recipes
// §6.4): I_x(a, b) = x^a (1 − x)^b / (a B(a, b)) · BetaContinuedFraction(a, b, x), converging
// fast for x < (a + 1) / (a + b + 2).
double BetaContinuedFraction(double a, double b, double x) {
  constexpr double kTiny = 1e-300, kEps = 1e-15;
  const double qab = a + b, qap = a + 1.0, qam = a - 1.0;
  auto guard = [](double v) { return std::abs(v) < kTiny ? kTiny : v; };
  double c = 1.0, d = 1.0 / guard(1.0 - qab * x / qap), h = d;
  for (int m = 1; m <= 500; ++m) {
    const double m2 = 2.0 * m;
    double aa = m * (b - m) * x / ((qam + m2) * (a + m2));
    d = 1.0 / guard(1.0 + aa * d);
    c = guard(1.0 + aa / c);
    h *= d * c;
    aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
    d = 1.0 / guard(1.0 + aa * d);
    c = guard(1.0 + aa / c);
    const double step = d * c;
    h *= step;
    if (std::abs(step - 1.0) < kEps) break;
  }
  return h;
}

// ln I_x(a, b) from ln x and ln(1 − x) (each exact where x or 1 − x underflows).
double LogIncompleteBeta(double a, double b, double log_x, double log_1mx) {
  const double x = std::exp(log_x);
  const double log_beta = std::lgamma(a) + std::lgamma(b) - std::lgamma(a + b);
  if (x < (a + 1.0) / (a + b + 2.0))
    return a * log_x + b * log_1mx - std::log(a) - log_beta +
           std::log(BetaContinuedFraction(a, b, x));
  // I_x(a, b) = 1 − I_{1−x}(b, a), the fraction converging on that side.
  const double log_other = b * log_1mx + a * log_x - std::log(b) - log_beta +
                           std::log(BetaContinuedFraction(b, a, std::exp(log_1mx)));
  return std::log1p(-std::exp(log_other));
}

}  // namespace

double LogStudentTUpper(double t, double dof) {
  if (std::isnan(t) || !(dof > 0)) return std::numeric_limits<double>::quiet_NaN();
  if (t == 0) return std::log(0.5);
  const double u = std::abs(t);
  // x = ν / (ν + t²), 1 − x = t² / (ν + t²), in logs (t² overflows beyond 1e154).
  const double log_sum = u > 1e100 ? 2.0 * std::log(u) : std::log(dof + u * u);
  const double log_x = std::log(dof) - log_sum, log_1mx = 2.0 * std::log(u) - log_sum;
  const double log_upper =
      std::isinf(u) ? -kInf : std::log(0.5) + LogIncompleteBeta(0.5 * dof, 0.5, log_x, log_1mx);
  return t > 0 ? log_upper : std::log1p(-std::exp(log_upper));
}

double LogNormalUpper(double z) {
  if (std::isnan(z)) return z;
  if (z < 0) {  // 1 − P(Z > |z|), accurate near p = 1
    return std::log1p(-0.5 * std::erfc(-z / std::numbers::sqrt2));
  }
  if (z < 30) return std::log(0.5 * std::erfc(z / std::numbers::sqrt2));
  // Beyond 30 erfc soon underflows (z ≈ 37.5); the asymptotic series of the Mills ratio,
  // P(Z > z) = φ(z)/z · (1 − 1/z² + 3/z⁴ − 15/z⁶ + 105/z⁸ − …), has error < 1e-14 there.
  if (std::isinf(z)) return -kInf;
  const double u = 1.0 / (z * z);
  const double series = 1.0 - u * (1.0 - u * (3.0 - u * (15.0 - u * 105.0)));
  return -0.5 * z * z - std::log(z) - 0.5 * std::log(2.0 * std::numbers::pi) + std::log(series);
}

double NormalUpperQuantileLog(double log_p) {
  if (std::isnan(log_p) || log_p > 0) return std::numeric_limits<double>::quiet_NaN();
  if (log_p == 0) return -kInf;
  if (std::isinf(log_p)) return kInf;
  // LogNormalUpper decreases in z; ln p ≈ −z²/2 for large z bounds the bracket.
  double lo = -40.0, hi = std::sqrt(-2.0 * log_p) + 2.0;
  for (int i = 0; i < 300 && hi - lo > 1e-13 * std::max(1.0, std::abs(hi)); ++i) {
    const double mid = 0.5 * (lo + hi);
    (LogNormalUpper(mid) > log_p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

WrittenZ WriteZ(double z) {
  if (z > ZOfSmallestP()) return {ZOfSmallestP(), ">"};
  if (z < ZOfLargestP()) return {ZOfLargestP(), "<"};
  return {z, ""};
}

std::string ZText(double z, int decimals) {
  const WrittenZ w = WriteZ(z);
  char buf[64];
  std::snprintf(buf, sizeof buf, "%s%.*f", w.bound.empty() ? "" : (w.bound + " ").c_str(),
                w.bound.empty() ? decimals : 2, w.value);
  return buf;
}

std::string PText(double log_p) {
  if (log_p >= 0) return "1";
  const double p = std::exp(log_p);
  if (!(p >= kPBound)) return "< 1e-300";
  char buf[32];
  std::snprintf(buf, sizeof buf, p >= 1e-3 ? "%.4f" : "%.2g", p);
  return buf;
}

}  // namespace rcal::discrepancy
