// Chi-square distribution, for innovation gates and residual tests.
#pragma once

namespace rcal::identification {

/// P(X ≤ x) for X ~ χ²(dof).
double ChiSquareCdf(double x, double dof);
/// ln P(X > x) for X ~ χ²(dof): finite where the upper tail underflows a double (a χ² of 22681
/// on 303 dof has p ≈ 1e-4500; 1 − ChiSquareCdf is 0 below 1e-16).
double ChiSquareLogUpper(double x, double dof);
/// The x with ChiSquareCdf(x, dof) = p, for p in (0, 1).
double ChiSquareQuantile(double p, double dof);

}  // namespace rcal::identification
