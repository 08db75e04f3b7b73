// The von Mises distribution on the circle (particle-filter paper, sec. II-B):
//
//   vM(kappa, theta0)(x) = exp(kappa cos(x - theta0)) / (2 pi I0(kappa)),   x in [-pi, pi)  (3)
//
// its exact sampler (Best and Fisher 1979), the circular mean (5), the mean resultant length and
// the maximum-likelihood kappa, and the product over joints (6).
//
// Angles are wrapped to [-pi, pi) (conventions.h). Samplers also return points on the unit circle
// (cos x, sin x) directly: the particle filter keeps its joint angles that way, so propagating
// x + v is a complex multiplication and forward kinematics needs no trigonometry.
//
// Bad parameters (kappa <= 0, NaN or infinite; theta0 not finite) throw InputError.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "estimators/pf/bessel.h"

namespace flexbench::pf {

// Uniform double in [0, 1) from the top 53 bits of one draw.
inline double Uniform53(std::mt19937_64& rng) {
  return static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0);
}

// A point on the unit circle: (cos x, sin x).
struct UnitAngle {
  double c = 1.0;
  double s = 0.0;
};

// Throws InputError "<what>: kappa must be finite and > 0, got <kappa>".
void CheckKappa(double kappa, const char* what);

// Best-Fisher's envelope: the wrapped Cauchy with r = (1 + rho^2) / (2 rho), stored as r - 1,
// r and sqrt(r^2 - 1) without cancellation. Any r > 1 gives an exact sampler; the optimal one
// for kappa (BestFisherEnvelope) maximises the acceptance rate.
struct BestFisherEnvelope {
  double r_minus_1 = 1.0;
  double r = 2.0;
  double sqrt_r2_minus_1 = 1.7320508075688772;
};
BestFisherEnvelope OptimalBestFisherEnvelope(double kappa);

// One exact draw of vM(kappa, 0) as (cos x, sin x) by Best and Fisher's algorithm with envelope
// `env`, written without trigonometric calls: the candidate cos(pi U) comes from a point uniform
// in a disc (its squared radius is the acceptance uniform, the sign of one coordinate the sign of
// the angle), 1 - cos x and sin x come in factored form (full relative precision for small
// angles at any kappa), and the acceptance test u <= c e^{1 - c} is decided by polynomial bounds
// (c (2 - c) below, c / (1 + y + y^2/2 + y^3/6), y = c - 1, above) before the exact log test.
inline UnitAngle BestFisherDraw(double kappa, const BestFisherEnvelope& env, std::mt19937_64& rng) {
  constexpr double kInv32 = 1.0 / 4294967296.0;
  for (;;) {
    const std::uint64_t bits = rng();
    // Two coordinates uniform in (-0.5, 0.5) from the two 32-bit halves.
    const double v = (static_cast<double>(bits >> 32) + 0.5) * kInv32 - 0.5;
    const double w = (static_cast<double>(bits & 0xffffffffu) + 0.5) * kInv32 - 0.5;
    const double d = v * v;
    const double e = w * w;
    const double de = d + e;
    if (de > 0.25) continue;        // outside the disc
    const double u = 4.0 * de;      // uniform in (0, 1]
    const double z = (e - d) / de;  // cos(pi U), U uniform
    const double rz = env.r + z;
    const double one_minus_f = env.r_minus_1 * (2.0 * d / de) / rz;  // 1 - cos x
    const double c = kappa * (env.r_minus_1 + one_minus_f);          // kappa (r - f)
    bool accept = c * (2.0 - c) > u;
    if (!accept) {
      const double y = c - 1.0;
      if (y > 0.0 && u * (1.0 + y * (1.0 + y * (0.5 + y * (1.0 / 6.0)))) > c) continue;
      accept = std::log(c / u) + 1.0 - c >= 0.0;
      if (!accept) continue;
    }
    // sin^2 x = (1 - f)(1 + f) = (r^2 - 1)(1 - z^2) / (r + z)^2, 1 - z^2 = 4 d e / de^2.
    const double s = 2.0 * env.sqrt_r2_minus_1 * std::sqrt(d * e) / (de * rz);
    return UnitAngle{1.0 - one_minus_f, v < 0.0 ? -s : s};
  }
}

// Best and Fisher's (1979) rejection sampler for vM(kappa, 0) (BestFisherDraw with the optimal
// envelope): exact for every kappa (1e-300 to 1e12 tested); acceptance of the disc point is
// pi/4, Best-Fisher's own acceptance is >= 0.66 for every kappa (0.9 near kappa = 5).
class VonMisesSampler {
 public:
  explicit VonMisesSampler(double kappa);

  double kappa() const { return kappa_; }

  // A deviation v ~ vM(kappa, 0) as (cos v, sin v).
  UnitAngle SampleUnit(std::mt19937_64& rng) const { return BestFisherDraw(kappa_, env_, rng); }

  // A deviation v ~ vM(kappa, 0) in [-pi, pi).
  double Sample(std::mt19937_64& rng) const {
    const UnitAngle a = SampleUnit(rng);
    // atan2 of the factored pair keeps small angles exact; +pi maps to -pi.
    const double x = std::atan2(a.s, a.c);
    return x >= M_PI ? -M_PI : x;
  }

 private:
  double kappa_;
  BestFisherEnvelope env_;
};

// Puts every (c[i], s[i]) back on the unit circle (one Newton step; vectorises).
void RenormaliseUnit(double* c, double* s, int n);

// An exact sampler of vM(kappa, 0) for a fixed kappa, built for the filter's hot loop (the
// system noise of [PF eq. 30] is drawn N * m times per step). Rejection from a piecewise-constant
// envelope of the density on [0, pi] (the density is symmetric and decreasing there):
// kBins bins of width h up to x_max = min(pi, 12 / sqrt(kappa)) and one tail piece up to pi. Each
// bin is split into the rectangle under its right-edge value (always accepted) and the cap above
// it (accepted with probability f(x) / f(a) by an exact test); a Walker alias table picks one of
// the 2 kBins + 1 pieces. One 64-bit draw serves the accepted-without-test case (~98% of draws
// for kappa = 5): 9 bits piece, 22 bits alias threshold, 1 bit sign, 32 bits position. The
// sample is returned as (cos x, sin x) from the bin edge's tabulated cos/sin rotated by the
// offset inside the bin (Taylor series of the small rotation, exact to rounding), so again no
// trigonometric call. Exact up to the 2^-22 resolution of the alias thresholds; the tests check
// it like the Best-Fisher sampler (moments, Kolmogorov-Smirnov, chi-square).
class VonMisesTableSampler {
 public:
  static constexpr int kBins = 255;

  explicit VonMisesTableSampler(double kappa);
  double kappa() const { return kappa_; }

  // Rotates each (c[i], s[i]), i < n, by its own independent draw v ~ vM(kappa, 0): the
  // system model x + v of [PF eq. 30] on unit vectors. Each rotation moves |(c, s)| by an ulp or
  // so; callers put the vectors back with RenormaliseUnit every few moves. Same distribution as
  // SampleUnit, organised for throughput: all first draws are made up front into
  // `scratch` (n words), the ~98% of them that land under the envelope's lower part are used
  // directly in a loop free of the generator's state, and the rest finish their rejection test
  // (restarting with SampleUnit when rejected, which is the same rejection sampler).
  void RotateByNoise(std::mt19937_64& rng, double* c, double* s, int n,
                     std::uint64_t* scratch) const;

  UnitAngle SampleUnit(std::mt19937_64& rng) const {
    for (;;) {
      const std::uint64_t r = rng();
      const unsigned slot = static_cast<unsigned>(r >> 55);                        // 9 bits
      const std::uint32_t coin = static_cast<std::uint32_t>(r >> 33) & 0x3fffffu;  // 22 bits
      const bool negative = ((r >> 32) & 1u) != 0;
      const double t = (static_cast<double>(r & 0xffffffffu) + 0.5) * (1.0 / 4294967296.0);
      const unsigned piece = coin < threshold_[slot] ? slot : alias_[slot];
      if (piece < kBins) {  // under the bin's lower edge value: accept
        const UnitAngle a = Rotate(piece, t);
        return UnitAngle{a.c, negative ? -a.s : a.s};
      }
      const double u = Uniform53(rng);
      if (piece < 2 * kBins) {  // a cap: accept with (f(x) - f(b)) / (f(a) - f(b))
        const unsigned bin = piece - kBins;
        const UnitAngle a = Rotate(bin, t);
        const double fx = std::exp(kappa_ * (a.c - 1.0));
        if (f_right_[bin] + u * (f_left_[bin] - f_right_[bin]) < fx) {
          return UnitAngle{a.c, negative ? -a.s : a.s};
        }
        continue;
      }
      if (piece == 2 * kBins) {  // the tail (x_max, pi]
        const double x = x_max_ + t * (M_PI - x_max_);
        const double c = std::cos(x);
        if (u * f_tail_ < std::exp(kappa_ * (c - 1.0))) {
          const double s = std::sin(x);
          return UnitAngle{c, negative ? -s : s};
        }
      }
    }
  }

 private:
  // (cos, sin) of a_bin + t h.
  UnitAngle Rotate(unsigned bin, double t) const {
    const double d = t * h_;
    const double d2 = d * d;
    // |d| <= pi / 255: the next terms (d^8 / 8!, d^9 / 9!) are below 1e-19.
    const double cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24 - d2 * (1.0 / 720)));
    const double sd = d * (1.0 - d2 * (1.0 / 6 - d2 * (1.0 / 120 - d2 * (1.0 / 5040))));
    return UnitAngle{cos_a_[bin] * cd - sin_a_[bin] * sd, sin_a_[bin] * cd + cos_a_[bin] * sd};
  }

  double kappa_;
  double x_max_;
  double h_;
  double f_tail_;  // f(x_max), the tail's envelope
  double cos_a_[kBins], sin_a_[kBins], f_left_[kBins], f_right_[kBins];
  std::uint32_t threshold_[512];
  std::uint16_t alias_[512];
};

// Exact draws of vM(k, 0) for many different k in [k_min, k_max] (the encoder-conjugate
// proposal draws each particle's joint from its own concentration). The range is cut into
// kBins bins; a draw for k in the bin starting at k_b is a draw x of the table sampler at k_b
// (broader than vM(k)) accepted with probability exp(-(k - k_b)(1 - cos x)) <= 1, which makes it
// exactly vM(k) (acceptance ~ 1 - (k - k_b) / (2 k), about 98% here); the test uses the bound
// exp(-y) >= 1 - y first. k outside the range (rounding) and the lowest bin when it starts at 0
// use Best-Fisher with the optimal envelope.
class VonMisesFamilySampler {
 public:
  static constexpr int kBins = 16;

  VonMisesFamilySampler(double k_min, double k_max);

  // Rotates each (c[i], s[i]) by its own draw v ~ vM(k[i], 0) and renormalises it.
  void RotateBatch(const double* k, double* c, double* s, int n, std::mt19937_64& rng) const;
  // One draw of vM(k, 0).
  UnitAngle SampleUnit(double k, std::mt19937_64& rng) const;

 private:
  double k_min_, width_, inv_width_;
  std::vector<VonMisesTableSampler> tables_;  // tables_[b] at k_min + b * width (b >= first_)
  int first_ = 0;                             // 1 when k_min = 0 (no table at kappa 0)
};

class VonMises {
 public:
  // vM(kappa, theta0); theta0 is wrapped to [-pi, pi).
  VonMises(double kappa, double theta0 = 0.0);

  double kappa() const { return kappa_; }
  double theta0() const { return theta0_; }

  // log vM(kappa, theta0)(x), [PF eq. 3], with log I0 from bessel.h (finite for any kappa).
  double LogDensity(double x) const { return kappa_ * std::cos(x - theta0_) - log_norm_; }
  double Density(double x) const { return std::exp(LogDensity(x)); }
  // kappa cos(x - theta0): the log-density up to its constant.
  double UnnormalisedLogDensity(double x) const { return kappa_ * std::cos(x - theta0_); }
  // log(2 pi I0(kappa)).
  double LogNormaliser() const { return log_norm_; }
  // E[cos(x - theta0)] = A1(kappa).
  double MeanResultantLength() const { return BesselRatioA1(kappa_); }
  // Circular standard deviation sqrt(-2 log A1(kappa)).
  double CircularStd() const;

  // x ~ vM(kappa, theta0), wrapped to [-pi, pi).
  double Sample(std::mt19937_64& rng) const;

 private:
  double kappa_;
  double theta0_;
  double log_norm_;
  VonMisesSampler sampler_;
};

// Statistics of a (weighted) sample of angles. Weights must be >= 0 with a positive sum;
// throws InputError otherwise (std::invalid_argument when sizes differ).
struct CircularSummary {
  double mean = 0.0;                   // [PF eq. 5]: atan2(sum w sin x, sum w cos x)
  double mean_resultant_length = 0.0;  // |sum w e^{ix}| / sum w, in [0, 1]
  double kappa_mle = 0.0;              // InverseBesselRatioA1(mean_resultant_length)
  double circular_std = 0.0;           // sqrt(-2 log R)
};
CircularSummary SummariseAngles(const std::vector<double>& angles,
                                const std::vector<double>& weights = {});
// [PF eq. 5] alone.
double CircularMean(const std::vector<double>& angles, const std::vector<double>& weights = {});
// The naive arithmetic mean the paper warns against (Fig. 3), for comparisons.
double NaiveMean(const std::vector<double>& angles);

// The product of independent von Mises variables over m joints [PF eq. 6].
class VonMisesProduct {
 public:
  VonMisesProduct(std::vector<double> kappas, std::vector<double> theta0s);
  // vM(kappa, 0)^m [PF eq. 29].
  static VonMisesProduct Iid(int m, double kappa, double theta0 = 0.0);

  int size() const { return static_cast<int>(components_.size()); }
  const VonMises& component(int j) const { return components_[j]; }
  // Sum of the component log-densities; x must have size() entries (std::invalid_argument
  // otherwise).
  double LogDensity(const std::vector<double>& x) const;
  // One draw of every component, in order.
  void Sample(std::mt19937_64& rng, std::vector<double>* x) const;

 private:
  std::vector<VonMises> components_;
};

}  // namespace flexbench::pf
