// Chi-square distribution: CDF and quantiles, for consistency checks (NEES, NIS, confidence
// regions). Exact through the regularised incomplete gamma function, no tables.
#pragma once

namespace flexbench::stats {

// Regularised lower incomplete gamma P(a, x) for a > 0, x >= 0.
double RegularizedGammaP(double a, double x);

// P(X <= x) for X ~ chi-square(dof).
double ChiSquareCdf(double x, double dof);

// The p-quantile of chi-square(dof), p in (0, 1).
double ChiSquareQuantile(double p, double dof);

// Two-sided bounds on the mean of n independent chi-square(dof) values (the NEES average of
// n runs): [q(alpha/2; n dof) / n, q(1 - alpha/2; n dof) / n] (Bar-Shalom's consistency test).
struct ChiSquareBounds {
  double lower;
  double upper;
};
ChiSquareBounds MeanChiSquareBounds(double dof, int n, double alpha = 0.05);

}  // namespace flexbench::stats
