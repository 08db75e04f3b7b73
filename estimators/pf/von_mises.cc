#include "estimators/pf/von_mises.h"

#include <algorithm>
#include <sstream>
#include <stdexcept>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "estimators/pf/particle_loop.h"

namespace flexbench::pf {

void CheckKappa(double kappa, const char* what) {
  if (!(kappa > 0.0) || !std::isfinite(kappa)) {
    std::ostringstream msg;
    msg << what << ": kappa must be finite and > 0, got " << kappa;
    throw InputError(msg.str());
  }
}

BestFisherEnvelope OptimalBestFisherEnvelope(double kappa) {
  // tau = 1 + s, s = sqrt(1 + 4 kappa^2), rho = (tau - sqrt(2 tau)) / (2 kappa),
  // r = (1 + rho^2) / (2 rho), r - 1 = (1 - rho)^2 / (2 rho). Both rho and 1 - rho are formed
  // without cancellation: tau - sqrt(2 tau) = tau (s - 1) / (tau + sqrt(2 tau)) with
  // s - 1 = 4 kappa^2 / (s + 1); and 2 kappa - tau = -1 - 1 / (s + 2 kappa).
  const double s = std::sqrt(1.0 + 4.0 * kappa * kappa);
  const double tau = 1.0 + s;
  const double sqrt_2tau = std::sqrt(2.0 * tau);
  const double rho = 2.0 * kappa * tau / ((s + 1.0) * (tau + sqrt_2tau));
  const double one_minus_rho =
      kappa < 1.0 ? 1.0 - rho : (sqrt_2tau - 1.0 - 1.0 / (s + 2.0 * kappa)) / (2.0 * kappa);
  BestFisherEnvelope env;
  env.r_minus_1 = one_minus_rho * (one_minus_rho / (2.0 * rho));
  env.r = 1.0 + env.r_minus_1;
  env.sqrt_r2_minus_1 = std::sqrt(env.r_minus_1) * std::sqrt(env.r + 1.0);
  return env;
}

VonMisesSampler::VonMisesSampler(double kappa) : kappa_(kappa) {
  CheckKappa(kappa, "VonMisesSampler");
  env_ = OptimalBestFisherEnvelope(kappa);
}

VonMisesTableSampler::VonMisesTableSampler(double kappa) : kappa_(kappa) {
  CheckKappa(kappa, "VonMisesTableSampler");
  x_max_ = std::min(M_PI, 12.0 / std::sqrt(kappa));
  h_ = x_max_ / kBins;
  // f(x) = exp(kappa (cos x - 1)) <= 1, decreasing on [0, pi].
  const auto f = [&](double x) { return std::exp(kappa * (std::cos(x) - 1.0)); };
  constexpr int kSlots = 512;
  double mass[kSlots] = {};
  for (int k = 0; k < kBins; ++k) {
    const double a = k * h_;
    const double b = (k + 1) * h_;
    cos_a_[k] = std::cos(a);
    sin_a_[k] = std::sin(a);
    f_left_[k] = f(a);
    f_right_[k] = f(b);
    mass[k] = h_ * f_right_[k];                         // accepted without a test
    mass[kBins + k] = h_ * (f_left_[k] - f_right_[k]);  // the cap
  }
  f_tail_ = f(x_max_);
  mass[2 * kBins] = x_max_ < M_PI ? (M_PI - x_max_) * f_tail_ : 0.0;
  // Walker's alias table (Vose's construction) over the 2 kBins + 1 pieces; slot 511 is empty.
  double total = 0.0;
  for (double m : mass) total += m;
  double scaled[kSlots];
  int small[kSlots], large[kSlots];
  int ns = 0, nl = 0;
  for (int i = 0; i < kSlots; ++i) {
    scaled[i] = mass[i] * kSlots / total;
    (scaled[i] < 1.0 ? small[ns++] : large[nl++]) = i;
  }
  constexpr double kScale = 4194304.0;  // 2^22
  while (ns > 0 && nl > 0) {
    const int s = small[--ns];
    const int l = large[--nl];
    threshold_[s] = static_cast<std::uint32_t>(std::llround(scaled[s] * kScale));
    alias_[s] = static_cast<std::uint16_t>(l);
    scaled[l] -= 1.0 - scaled[s];
    (scaled[l] < 1.0 ? small[ns++] : large[nl++]) = l;
  }
  while (nl > 0) {
    const int l = large[--nl];
    threshold_[l] = static_cast<std::uint32_t>(kScale);
    alias_[l] = static_cast<std::uint16_t>(l);
  }
  while (ns > 0) {  // rounding leftovers: probability 1 of themselves
    const int s = small[--ns];
    threshold_[s] = static_cast<std::uint32_t>(kScale);
    alias_[s] = static_cast<std::uint16_t>(s);
  }
}

FLEXBENCH_PARTICLE_LOOP void RenormaliseUnit(double* c, double* s, int n) {
  // One Newton step of 1/sqrt at 1: |(c, s)| = 1 + e becomes 1 + O(e^2).
  double* __restrict cc = c;
  double* __restrict ss = s;
  for (int i = 0; i < n; ++i) {
    const double k = 0.5 * (3.0 - (cc[i] * cc[i] + ss[i] * ss[i]));
    cc[i] *= k;
    ss[i] *= k;
  }
}

FLEXBENCH_PARTICLE_LOOP void VonMisesTableSampler::RotateByNoise(std::mt19937_64& rng, double* c,
                                                                 double* s, int n,
                                                                 std::uint64_t* scratch) const {
  for (int i = 0; i < n; ++i) scratch[i] = rng();
  int pending = 0;  // indices whose draw needs the exact test, compacted into scratch's front
  for (int i = 0; i < n; ++i) {
    const std::uint64_t r = scratch[i];
    const unsigned slot = static_cast<unsigned>(r >> 55);
    const std::uint32_t coin = static_cast<std::uint32_t>(r >> 33) & 0x3fffffu;
    const unsigned piece = coin < threshold_[slot] ? slot : alias_[slot];
    if (piece >= static_cast<unsigned>(kBins)) {
      // Keep the piece bits (high word) with the index in place of the position bits, which
      // are redrawn below (they are independent of the piece choice).
      scratch[pending++] = (r & ~std::uint64_t{0xffffffffu}) | static_cast<std::uint32_t>(i);
      continue;
    }
    const double t = (static_cast<double>(r & 0xffffffffu) + 0.5) * (1.0 / 4294967296.0);
    UnitAngle v = Rotate(piece, t);
    if ((r >> 32) & 1u) v.s = -v.s;
    const double cn = c[i] * v.c - s[i] * v.s;
    const double sn = s[i] * v.c + c[i] * v.s;
    c[i] = cn;
    s[i] = sn;
  }
  for (int p = 0; p < pending; ++p) {
    const std::uint64_t r = scratch[p];
    const int i = static_cast<int>(r & 0xffffffffu);
    const unsigned slot = static_cast<unsigned>(r >> 55);
    const std::uint32_t coin = static_cast<std::uint32_t>(r >> 33) & 0x3fffffu;
    const unsigned piece = coin < threshold_[slot] ? slot : alias_[slot];
    const bool negative = ((r >> 32) & 1u) != 0;
    // The position inside the piece: fresh bits (independent of the piece choice).
    const double t = (static_cast<double>(rng() >> 32) + 0.5) * (1.0 / 4294967296.0);
    const double u = Uniform53(rng);
    UnitAngle v{1.0, 0.0};
    bool accepted = false;
    if (piece < static_cast<unsigned>(2 * kBins)) {
      const unsigned bin = piece - kBins;
      v = Rotate(bin, t);
      accepted =
          f_right_[bin] + u * (f_left_[bin] - f_right_[bin]) < std::exp(kappa_ * (v.c - 1.0));
    } else if (piece == static_cast<unsigned>(2 * kBins)) {
      const double x = x_max_ + t * (M_PI - x_max_);
      v = UnitAngle{std::cos(x), std::sin(x)};
      accepted = u * f_tail_ < std::exp(kappa_ * (v.c - 1.0));
    }
    if (accepted) {
      if (negative) v.s = -v.s;
    } else {
      v = SampleUnit(rng);  // rejected: the sampler starts over
    }
    const double cn = c[i] * v.c - s[i] * v.s;
    const double sn = s[i] * v.c + c[i] * v.s;
    c[i] = cn;
    s[i] = sn;
  }
}

VonMisesFamilySampler::VonMisesFamilySampler(double k_min, double k_max) : k_min_(k_min) {
  CheckKappa(k_max, "VonMisesFamilySampler");
  if (!(k_min >= 0.0) || !(k_max > k_min)) {
    throw InputError("VonMisesFamilySampler: need 0 <= k_min < k_max");
  }
  width_ = (k_max - k_min) / kBins;
  inv_width_ = 1.0 / width_;
  first_ = k_min > 0.0 ? 0 : 1;
  tables_.reserve(kBins);
  for (int b = 0; b < kBins; ++b) tables_.emplace_back(std::max(k_min + b * width_, 1e-300));
}

UnitAngle VonMisesFamilySampler::SampleUnit(double k, std::mt19937_64& rng) const {
  const double pos = (k - k_min_) * inv_width_;
  const int b = pos >= 0.0 ? static_cast<int>(pos) : -1;
  if (b < first_ || b >= kBins) return BestFisherDraw(k, OptimalBestFisherEnvelope(k), rng);
  const double kb = k_min_ + b * width_;
  for (;;) {
    const UnitAngle a = tables_[b].SampleUnit(rng);
    const double y = (k - kb) * (1.0 - a.c);  // >= 0
    const double u = Uniform53(rng);
    if (u <= 1.0 - y || u <= std::exp(-y)) return a;
  }
}

void VonMisesFamilySampler::RotateBatch(const double* k, double* c, double* s, int n,
                                        std::mt19937_64& rng) const {
  for (int i = 0; i < n; ++i) {
    const UnitAngle v = SampleUnit(k[i], rng);
    const double cn = c[i] * v.c - s[i] * v.s;
    const double sn = s[i] * v.c + c[i] * v.s;
    const double r = 0.5 * (3.0 - (cn * cn + sn * sn));
    c[i] = cn * r;
    s[i] = sn * r;
  }
}

VonMises::VonMises(double kappa, double theta0)
    : kappa_(kappa),
      theta0_(0.0),
      log_norm_(0.0),
      sampler_((CheckKappa(kappa, "VonMises"), kappa)) {
  if (!std::isfinite(theta0)) {
    std::ostringstream msg;
    msg << "VonMises: theta0 must be finite, got " << theta0;
    throw InputError(msg.str());
  }
  theta0_ = WrapAngle(theta0);
  log_norm_ = std::log(2.0 * M_PI) + LogBesselI0(kappa);
}

double VonMises::CircularStd() const { return std::sqrt(-2.0 * std::log(MeanResultantLength())); }

double VonMises::Sample(std::mt19937_64& rng) const {
  return WrapAngle(theta0_ + sampler_.Sample(rng));
}

CircularSummary SummariseAngles(const std::vector<double>& angles,
                                const std::vector<double>& weights) {
  if (angles.empty()) throw InputError("SummariseAngles: no angles");
  if (!weights.empty() && weights.size() != angles.size()) {
    throw std::invalid_argument("SummariseAngles: " + std::to_string(weights.size()) +
                                " weights for " + std::to_string(angles.size()) + " angles");
  }
  double sw = 0.0;
  double sc = 0.0;
  double ss = 0.0;
  for (size_t i = 0; i < angles.size(); ++i) {
    const double w = weights.empty() ? 1.0 : weights[i];
    if (!(w >= 0.0) || !std::isfinite(w) || !std::isfinite(angles[i])) {
      throw InputError("SummariseAngles: angle or weight " + std::to_string(i) +
                       " is not finite or the weight is negative");
    }
    sw += w;
    sc += w * std::cos(angles[i]);
    ss += w * std::sin(angles[i]);
  }
  if (!(sw > 0.0)) throw InputError("SummariseAngles: the weights sum to zero");
  CircularSummary out;
  out.mean = WrapAngle(std::atan2(ss, sc));
  out.mean_resultant_length = std::min(1.0, std::hypot(sc, ss) / sw);
  out.kappa_mle = InverseBesselRatioA1(out.mean_resultant_length);
  out.circular_std = std::sqrt(-2.0 * std::log(out.mean_resultant_length));
  return out;
}

double CircularMean(const std::vector<double>& angles, const std::vector<double>& weights) {
  return SummariseAngles(angles, weights).mean;
}

double NaiveMean(const std::vector<double>& angles) {
  if (angles.empty()) throw InputError("NaiveMean: no angles");
  double sum = 0.0;
  for (double a : angles) sum += a;
  return sum / static_cast<double>(angles.size());
}

VonMisesProduct::VonMisesProduct(std::vector<double> kappas, std::vector<double> theta0s) {
  if (kappas.size() != theta0s.size() || kappas.empty()) {
    throw std::invalid_argument("VonMisesProduct: need as many kappas as theta0s (got " +
                                std::to_string(kappas.size()) + " and " +
                                std::to_string(theta0s.size()) + ")");
  }
  components_.reserve(kappas.size());
  for (size_t j = 0; j < kappas.size(); ++j) components_.emplace_back(kappas[j], theta0s[j]);
}

VonMisesProduct VonMisesProduct::Iid(int m, double kappa, double theta0) {
  if (m <= 0) throw InputError("VonMisesProduct: need at least one component");
  return VonMisesProduct(std::vector<double>(m, kappa), std::vector<double>(m, theta0));
}

double VonMisesProduct::LogDensity(const std::vector<double>& x) const {
  if (static_cast<int>(x.size()) != size()) {
    throw std::invalid_argument("VonMisesProduct: x has " + std::to_string(x.size()) +
                                " entries, expected " + std::to_string(size()));
  }
  double sum = 0.0;
  for (int j = 0; j < size(); ++j) sum += components_[j].LogDensity(x[j]);
  return sum;
}

void VonMisesProduct::Sample(std::mt19937_64& rng, std::vector<double>* x) const {
  x->resize(components_.size());
  for (int j = 0; j < size(); ++j) (*x)[j] = components_[j].Sample(rng);
}

}  // namespace flexbench::pf
