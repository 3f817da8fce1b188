// Test statistics whose p-value a double cannot hold.
//
// A strong effect gives p-values far below the smallest double (4.9e-324): a binomial count of
// 5000 samples outside a 1e-3 band has p ≈ 1e-9000. Computed as a double, such a p underflows to
// 0, and a z derived from it (z = Φ̄⁻¹(p)) was clamped to the z of the clamp (37.05 for p = 1e-300):
// a number that looks measured and is not. So the tests here carry ln p, which a double holds for
// any p > 0, derive z from ln p (exact for any finite z), and write what still cannot be held as a
// bound:
//   - a p below 1e-300 is written "p < 1e-300" (text) and, in JSON, as "p_value": the double
//     value (0 after underflow) with "p_value_bound": "< 1e-300" and the exact "log10_p_value";
//   - a z beyond what a double p can express (p below 4.9e-324, the smallest double, or above
//     1 − 1.1e-16, the largest below 1) is written as that bound: "z > 38.47" or "z < -8.21"; in
//     JSON the bound is the number and "<key>_bound" is ">" or "<". That covers the infinite z
//     (p exactly 0: zero spread of a paired difference; p exactly 1: no count beyond the band)
//     and a finite z such as 95 from a ratio |τ|/σ: its p (e^−4500) is no double, and a normal
//     tail that far out is no model of anything measured, so only the bound is a statement.
//     z within the bounds are written as they are.
#pragma once

#include <string>

namespace rcal::discrepancy {

/// p below which a p-value is written as the bound "< 1e-300".
inline constexpr double kPBound = 1e-300;

/// ln P(Z > z), Z standard normal: accurate for any z (ln p = −805 at z = 40, where p underflows).
double LogNormalUpper(double z);
/// The z with ln P(Z > z) = log_p (log_p ≤ 0): +∞ for log_p = −∞ (p = 0), −∞ for log_p = 0.
double NormalUpperQuantileLog(double log_p);
/// ln P(T > t), T Student's t with `dof` degrees of freedom (> 0): the tail of a mean over a few
/// blocks divided by its standard error (sd/√B has B − 1 degrees of freedom; a normal critical
/// value would make such a ratio significant several times too often). By the regularised
/// incomplete beta function, P(T > t) = ½ I_{ν/(ν+t²)}(ν/2, ½), its continued fraction in log
/// space, so ln p stays finite far into the tail. NaN for a NaN t or dof ≤ 0.
double LogStudentTUpper(double t, double dof);

/// A z as written: within [−8.21, 38.47] as it is; beyond, as the bound a double p can express
/// (text above).
struct WrittenZ {
  double value = 0;   ///< z, or the bound
  std::string bound;  ///< "" (exact), ">" or "<": the true z lies beyond `value` this way
};
WrittenZ WriteZ(double z);
/// "3.7", "> 38.47", "< -8.21" (`decimals` after the point).
std::string ZText(double z, int decimals = 1);
/// "0.0123", "3.4e-12", "< 1e-300" from ln p; "1" for p = 1.
std::string PText(double log_p);

}  // namespace rcal::discrepancy
