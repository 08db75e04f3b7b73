#include "estimators/pf/bessel.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "estimators/error.h"

namespace flexbench::pf {
namespace {

constexpr double kRelTol = 1e-17;

void CheckArgument(double x, const char* fn) {
  if (!(x >= 0.0)) {  // also rejects NaN
    std::ostringstream msg;
    msg << fn << ": argument must be >= 0, got " << x;
    throw InputError(msg.str());
  }
}

// log of sum_k (x^2/4)^k / (k! (k+nu)!) * nu!, i.e. log(I_nu(x) / ((x/2)^nu / nu!)).
double LogSeriesSum(int nu, double x) {
  const double q = 0.25 * x * x;
  double term = 1.0;
  double sum = 1.0;
  for (int k = 1; k < 500; ++k) {
    term *= q / (static_cast<double>(k) * static_cast<double>(k + nu));
    sum += term;
    if (term < kRelTol * sum && k > 0.5 * x) break;
  }
  return std::log(sum);
}

// The asymptotic series sum_k (-1)^k a_k(nu) / x^k, truncated at its smallest term.
double AsymptoticSum(int nu, double x) {
  const double mu = 4.0 * nu * nu;
  double term = 1.0;
  double sum = 1.0;
  for (int k = 1; k < 200; ++k) {
    const double odd = 2.0 * k - 1.0;
    const double next = term * (odd * odd - mu) / (8.0 * k * x);
    if (std::abs(next) >= std::abs(term)) break;  // the series starts to diverge
    term = next;
    sum += term;
    if (std::abs(term) < kRelTol * std::abs(sum)) break;
  }
  return sum;
}

double LogAsymptoticPrefactor(double x) { return x - 0.5 * std::log(2.0 * M_PI * x); }

}  // namespace

double LogBesselI0(double x) {
  CheckArgument(x, "LogBesselI0");
  if (x < kBesselSeriesLimit) return LogSeriesSum(0, x);
  if (std::isinf(x)) return x;
  return LogAsymptoticPrefactor(x) + std::log(AsymptoticSum(0, x));
}

double LogBesselI1(double x) {
  CheckArgument(x, "LogBesselI1");
  if (x == 0.0) return -std::numeric_limits<double>::infinity();
  if (x < kBesselSeriesLimit) return std::log(0.5 * x) + LogSeriesSum(1, x);
  if (std::isinf(x)) return x;
  return LogAsymptoticPrefactor(x) + std::log(AsymptoticSum(1, x));
}

double BesselI0Scaled(double x) {
  CheckArgument(x, "BesselI0Scaled");
  if (x < kBesselSeriesLimit) return std::exp(LogSeriesSum(0, x) - x);
  if (std::isinf(x)) return 0.0;
  return AsymptoticSum(0, x) / std::sqrt(2.0 * M_PI * x);
}

double BesselRatioA1(double x) {
  CheckArgument(x, "BesselRatioA1");
  if (x == 0.0) return 0.0;
  if (std::isinf(x)) return 1.0;
  if (x < kBesselSeriesLimit) {
    return 0.5 * x * std::exp(LogSeriesSum(1, x) - LogSeriesSum(0, x));
  }
  // The common prefactor e^x / sqrt(2 pi x) cancels exactly.
  return AsymptoticSum(1, x) / AsymptoticSum(0, x);
}

double InverseBesselRatioA1(double r) {
  if (std::isnan(r) || r < 0.0) {
    std::ostringstream msg;
    msg << "InverseBesselRatioA1: mean resultant length must be in [0, 1], got " << r;
    throw InputError(msg.str());
  }
  if (r == 0.0) return 0.0;
  if (r >= 1.0) return std::numeric_limits<double>::infinity();
  // Best and Fisher's piecewise approximation as the starting point.
  double k;
  if (r < 0.53) {
    k = 2.0 * r + r * r * r + 5.0 * std::pow(r, 5) / 6.0;
  } else if (r < 0.85) {
    k = -0.4 + 1.39 * r + 0.43 / (1.0 - r);
  } else {
    k = 1.0 / (r * r * r - 4.0 * r * r + 3.0 * r);
  }
  for (int it = 0; it < 100; ++it) {
    const double a = BesselRatioA1(k);
    const double da = 1.0 - a / k - a * a;
    if (!(da > 0.0)) break;
    double step = (a - r) / da;
    // Keep kappa positive: never step past half of the way to zero.
    if (step > 0.5 * k) step = 0.5 * k;
    k -= step;
    if (std::abs(step) <= 1e-14 * k) break;
  }
  return k;
}

void LogBesselI0Interpolant::AddTo(const double* x, double* acc, int n) const {
  if (!interpolated_) {
    for (int i = 0; i < n; ++i) acc[i] += LogBesselI0(x[i]);
    return;
  }
  const double slack = 1e-12 * (b_ - a_);
  for (int i = 0; i < n; ++i) {
    if (x[i] < a_ - slack || x[i] > b_ + slack) {  // not rounding: exact, then done
      for (int k = 0; k < n; ++k) acc[k] += Evaluate(x[k]);
      return;
    }
  }
  // Clenshaw's recurrence for blocks of points at once: the inner loops run over the points.
  const double mid = a_ + b_;
  const double scale = 0.5 * inv_half_width_;
  constexpr int kBlock = 64;
  double t[kBlock], b1[kBlock], b2[kBlock];
  for (int start = 0; start < n; start += kBlock) {
    const int m = std::min(kBlock, n - start);
    const double* __restrict xs = x + start;
    for (int i = 0; i < m; ++i) {
      const double ti = (2.0 * xs[i] - mid) * scale;
      t[i] = ti < -1.0 ? -1.0 : (ti > 1.0 ? 1.0 : ti);
      b1[i] = 0.0;
      b2[i] = 0.0;
    }
    for (int k = degree_; k >= 1; --k) {
      const double ck = coef_[k];
      for (int i = 0; i < m; ++i) {
        const double b0 = ck + 2.0 * t[i] * b1[i] - b2[i];
        b2[i] = b1[i];
        b1[i] = b0;
      }
    }
    double* __restrict out = acc + start;
    for (int i = 0; i < m; ++i) out[i] += coef_[0] + t[i] * b1[i] - b2[i];
  }
}

LogBesselI0Interpolant::LogBesselI0Interpolant(double a, double b) : a_(a), b_(b) {
  if (!(a >= 0.0) || !(b > a) || !std::isfinite(b)) {
    std::ostringstream msg;
    msg << "LogBesselI0Interpolant: need 0 <= a < b < inf, got [" << a << ", " << b << "]";
    throw InputError(msg.str());
  }
  inv_half_width_ = 2.0 / (b - a);
  for (int n = 8; n <= 64; n *= 2) {
    // Chebyshev coefficients from the values at the n + 1 Chebyshev (Gauss) nodes.
    const int m = n + 1;
    double f[65];
    for (int j = 0; j < m; ++j) {
      const double t = std::cos(M_PI * (j + 0.5) / m);
      f[j] = LogBesselI0(0.5 * (a + b) + 0.5 * (b - a) * t);
    }
    for (int k = 0; k < m; ++k) {
      double sum = 0.0;
      for (int j = 0; j < m; ++j) sum += f[j] * std::cos(M_PI * k * (j + 0.5) / m);
      coef_[k] = (k == 0 ? 1.0 : 2.0) * sum / m;
    }
    degree_ = n;
    interpolated_ = true;
    double worst = 0.0;
    for (int i = 0; i <= 2000; ++i) {
      const double x = a + (b - a) * i / 2000.0;
      const double exact = LogBesselI0(x);
      worst = std::max(worst, std::abs(Evaluate(x) - exact) / std::max(1.0, std::abs(exact)));
    }
    max_error_ = worst;
    if (worst <= 1e-14) return;
  }
  interpolated_ = false;  // not accurate enough: Evaluate uses LogBesselI0
}

BesselRatioA1Interpolant::BesselRatioA1Interpolant() {
  // Node u_k = k / K: A1 and dA1/du = A1'(x) dx/du, dx/du = -1 / u^2 (x = 1 / u - 1).
  constexpr int K = kIntervals;
  double f[K + 1], d[K + 1];
  for (int k = 0; k <= K; ++k) {
    const double u = static_cast<double>(k) / K;
    if (k == 0) {  // x = inf: A1 = 1 - u / 2 - u^2 / 8 - ...
      f[k] = 1.0;
      d[k] = -0.5;
      continue;
    }
    const double x = 1.0 / u - 1.0;
    const double a = BesselRatioA1(x);
    const double da_dx = x > 0.0 ? 1.0 - a / x - a * a : 0.5;
    f[k] = a;
    d[k] = -da_dx / (u * u);
  }
  // Hermite cubic on [u_k, u_k+1] in t in [0, 1], slopes scaled by h = 1 / K.
  const double h = 1.0 / K;
  for (int k = 0; k < K; ++k) {
    const double f0 = f[k], f1 = f[k + 1], m0 = d[k] * h, m1 = d[k + 1] * h;
    double* c = &coef_[4 * k];
    c[0] = f0;
    c[1] = m0;
    c[2] = 3.0 * (f1 - f0) - 2.0 * m0 - m1;
    c[3] = 2.0 * (f0 - f1) + m0 + m1;
  }
  for (int k = 0; k < K; ++k) {
    for (double t : {0.25, 0.5, 0.75}) {
      const double u = (k + t) / K;
      const double x = 1.0 / u - 1.0;
      max_error_ = std::max(max_error_, std::abs(Evaluate(x) - BesselRatioA1(x)));
    }
  }
}

}  // namespace flexbench::pf
