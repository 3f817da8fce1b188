// Chi-square distribution, for innovation gates and residual tests.
#pragma once

namespace rcal::identification {

/// P(X ≤ x) for X ~ χ²(dof).
double ChiSquareCdf(double x, double dof);
/// The x with ChiSquareCdf(x, dof) = p, for p in (0, 1).
double ChiSquareQuantile(double p, double dof);

}  // namespace rcal::identification
