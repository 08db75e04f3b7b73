#include "estimators/stats/chi_square.h"

#include <cmath>
#include <limits>

#include "estimators/error.h"

namespace flexbench::stats {
namespace {

// Series for x < a + 1, continued fraction (modified Lentz) otherwise; both converge to double
// precision within a few hundred terms for the arguments used here.
double GammaPSeries(double a, double x) {
  double sum = 1.0 / a;
  double term = sum;
  for (int n = 1; n < 10000; ++n) {
    term *= x / (a + n);
    sum += term;
    if (std::abs(term) < std::abs(sum) * 1e-16) break;
  }
  return sum * std::exp(-x + a * std::log(x) - std::lgamma(a));
}

double GammaQContinuedFraction(double a, double x) {
  constexpr double kTiny = 1e-300;
  double b = x + 1.0 - a;
  double c = 1.0 / kTiny;
  double d = 1.0 / b;
  double h = d;
  for (int i = 1; i < 10000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < kTiny) d = kTiny;
    c = b + an / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double delta = d * c;
    h *= delta;
    if (std::abs(delta - 1.0) < 1e-16) break;
  }
  return std::exp(-x + a * std::log(x) - std::lgamma(a)) * h;
}

}  // namespace

double RegularizedGammaP(double a, double x) {
  if (!(a > 0.0) || !(x >= 0.0)) throw InputError("RegularizedGammaP: needs a > 0, x >= 0");
  if (x == 0.0) return 0.0;
  if (std::isinf(x)) return 1.0;
  return x < a + 1.0 ? GammaPSeries(a, x) : 1.0 - GammaQContinuedFraction(a, x);
}

double ChiSquareCdf(double x, double dof) {
  if (x <= 0.0) return 0.0;
  return RegularizedGammaP(0.5 * dof, 0.5 * x);
}

double ChiSquareQuantile(double p, double dof) {
  if (!(p > 0.0 && p < 1.0) || !(dof > 0.0)) {
    throw InputError("ChiSquareQuantile: needs 0 < p < 1 and dof > 0");
  }
  // Bracket, then bisect on the monotone CDF (robust for every dof; 200 halvings reach
  // machine precision from any bracket used here).
  double lo = 0.0;
  double hi = std::max(1.0, dof);
  while (ChiSquareCdf(hi, dof) < p) hi *= 2.0;
  for (int i = 0; i < 200 && hi - lo > 1e-14 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (ChiSquareCdf(mid, dof) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

ChiSquareBounds MeanChiSquareBounds(double dof, int n, double alpha) {
  const double total = dof * n;
  return {ChiSquareQuantile(0.5 * alpha, total) / n,
          ChiSquareQuantile(1.0 - 0.5 * alpha, total) / n};
}

}  // namespace flexbench::stats
