// Modified Bessel functions of the first kind, orders 0 and 1, in log form: what the von Mises
// density [PF eq. 3], its mean resultant length and the Bingham normaliser
// on S^3 (bingham.h) need, stable from kappa = 0 to kappa = 1e300.
//
// Method: the power series sum_k (x^2/4)^k / (k! (k+nu)!) for x < kSeriesLimit (all terms
// positive, so no cancellation), and above it the asymptotic (Hankel) expansion
//   I_nu(x) = e^x / sqrt(2 pi x) * sum_k (-1)^k a_k(nu) / x^k,
//   a_k(nu) = prod_{j=1..k} (4 nu^2 - (2j - 1)^2) / (k! 8^k),
// truncated at its smallest term, which is below e^{-2x} < 1e-17 for x >= 20. Both branches are
// accurate to a few ulp; the log form never overflows (I0(800) ~ 1e346 does in double).
#pragma once

#include <algorithm>

namespace flexbench::pf {

// The switch between the two branches.
inline constexpr double kBesselSeriesLimit = 20.0;

// log I0(x) for x >= 0 (I0(0) = 1). Throws InputError for negative or NaN x.
double LogBesselI0(double x);
// log I1(x) for x > 0 (-inf at x = 0). Throws InputError for negative or NaN x.
double LogBesselI1(double x);
// The exponentially scaled I0e(x) = exp(-x) I0(x), in (0, 1] for x >= 0.
double BesselI0Scaled(double x);
// A1(x) = I1(x) / I0(x), the mean resultant length of vM(x): 0 at 0, -> 1 - 1/(2x) as x -> inf.
double BesselRatioA1(double x);
// The inverse of A1 on [0, 1): the kappa with A1(kappa) = r (maximum-likelihood kappa of a
// sample with mean resultant length r). r = 0 gives 0; r >= 1 gives +inf. Newton iterations on
// A1(k) - r with A1'(k) = 1 - A1/k - A1^2, started from Best and Fisher's approximation, to
// relative accuracy 1e-14.
double InverseBesselRatioA1(double r);

// log I0 on a fixed interval [a, b] by a Chebyshev interpolant of degree up to 64, built at
// construction from LogBesselI0 and checked there against it at 2001 points: the degree grows
// until the largest error is below 1e-14 * max(1, |log I0|); if even degree 64 does not reach
// that, Evaluate falls back to LogBesselI0 (exact() reports which). For the particle filter's
// encoder-conjugate proposal, whose weights need log I0(k) with k in [|kappa_v - kappa_w|,
// kappa_v + kappa_w] once per particle and joint.
class LogBesselI0Interpolant {
 public:
  LogBesselI0Interpolant(double a, double b);
  double Evaluate(double x) const {
    if (!interpolated_ || x < a_ || x > b_) return LogBesselI0(x);
    // Clenshaw's recurrence on t in [-1, 1].
    const double t = (2.0 * x - a_ - b_) * inv_half_width_ * 0.5;
    const double t2 = 2.0 * t;
    double b1 = 0.0, b2 = 0.0;
    for (int k = degree_; k >= 1; --k) {
      const double b0 = coef_[k] + t2 * b1 - b2;
      b2 = b1;
      b1 = b0;
    }
    return coef_[0] + t * b1 - b2;
  }
  // acc[i] += log I0(x[i]) for i < n, in a loop over i that vectorises (the recurrences of
  // different points are independent). x outside [a, b] by rounding is clamped; further out it
  // is evaluated exactly.
  void AddTo(const double* x, double* acc, int n) const;
  bool interpolated() const { return interpolated_; }
  int degree() const { return degree_; }
  double max_error() const { return max_error_; }

 private:
  double a_, b_, inv_half_width_;
  int degree_ = 0;
  bool interpolated_ = false;
  double max_error_ = 0.0;
  double coef_[65] = {};
};

// A1(x) = I1(x) / I0(x) fast, for a moment per particle and joint: a cubic Hermite table in
// u = 1 / (1 + x) on [0, 1] (values and slopes from BesselRatioA1 and A1' = 1 - A1 / x - A1^2),
// no loop and no branch on the band. Checked at construction between every two nodes against
// BesselRatioA1; max_error() reports the largest deviation seen (about 1e-14).
class BesselRatioA1Interpolant {
 public:
  BesselRatioA1Interpolant();
  // Throws InputError for negative or NaN x, like BesselRatioA1.
  double Evaluate(double x) const {
    if (!(x >= 0.0)) return BesselRatioA1(x);
    const double u = 1.0 / (1.0 + x);  // in (0, 1]; x = inf gives 0
    const double s = u * kIntervals;
    const int k = std::min(static_cast<int>(s), kIntervals - 1);
    const double t = s - k;
    const double* c = &coef_[4 * k];
    return c[0] + t * (c[1] + t * (c[2] + t * c[3]));
  }
  double max_error() const { return max_error_; }

 private:
  static constexpr int kIntervals = 2048;
  double coef_[4 * kIntervals] = {};  // per interval, the cubic in t = u * kIntervals - k
  double max_error_ = 0.0;
};

}  // namespace flexbench::pf
