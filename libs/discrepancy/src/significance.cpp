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

}  // namespace

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
