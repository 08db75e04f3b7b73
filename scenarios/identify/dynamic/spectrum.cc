#include "scenarios/identify/dynamic/spectrum.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <complex>
#include <numeric>
#include <stdexcept>
#include <string>

#include "estimators/stats/chi_square.h"

namespace flexbench::identify::dynamic {
namespace {

constexpr double kPi = 3.14159265358979323846;
// Half-width (bins) of the band the noise floor is fitted over. A wider band scatters less but lets
// a coloured floor's curvature through: with 12 or 16, AR(1) residuals (coefficients -0.5 .. 0.97)
// gave false peaks in long logs; with 8 the false-positive rate stays near alpha for windows of
// 256 samples or more (spectrum.h).
constexpr int kFloorHalfWidth = 8;
// Bins either side of a peak that hold a sinusoid's power (the Hann main lobe is +-2 bins).
constexpr int kPeakHalfWidth = 2;

void CheckSeries(const double* x, int n, const char* what) {
  if (x == nullptr) throw std::invalid_argument(std::string(what) + ": null pointer");
  if (n < 8) {
    throw std::invalid_argument(std::string(what) + ": needs at least 8 samples, got " +
                                std::to_string(n));
  }
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(x[i])) {
      throw std::invalid_argument(std::string(what) + ": sample " + std::to_string(i) +
                                  " is not finite");
    }
  }
}

void CheckRate(double rate_hz, const char* what) {
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) {
    throw std::invalid_argument(std::string(what) + ": rate_hz must be positive and finite");
  }
}

// In-place iterative radix-2 FFT of a.size() = 2^k samples, with the bit-reversal permutation
// and the twiddles exp(-2 pi i j / size) (j < size / 2) computed once per call of the caller.
void Fft(std::vector<std::complex<double>>& a, const std::vector<int>& bit_reversed,
         const std::vector<std::complex<double>>& twiddle) {
  const int size = static_cast<int>(a.size());
  for (int i = 0; i < size; ++i) {
    if (i < bit_reversed[i]) std::swap(a[i], a[bit_reversed[i]]);
  }
  for (int len = 2; len <= size; len *= 2) {
    const int stride = size / len;
    for (int start = 0; start < size; start += len) {
      for (int j = 0; j < len / 2; ++j) {
        const std::complex<double> odd = twiddle[j * stride] * a[start + j + len / 2];
        a[start + j + len / 2] = a[start + j] - odd;
        a[start + j] += odd;
      }
    }
  }
}

// Continued fraction of the incomplete beta function (modified Lentz).
double BetaContinuedFraction(double a, double b, double x) {
  constexpr double kTiny = 1e-300;
  double c = 1.0;
  double d = 1.0 - (a + b) * x / (a + 1.0);
  if (std::abs(d) < kTiny) d = kTiny;
  d = 1.0 / d;
  double h = d;
  for (int m = 1; m < 10000; ++m) {
    const double m2 = 2.0 * m;
    double aa = m * (b - m) * x / ((a + m2 - 1.0) * (a + m2));
    for (int step = 0; step < 2; ++step) {
      d = 1.0 + aa * d;
      if (std::abs(d) < kTiny) d = kTiny;
      c = 1.0 + aa / c;
      if (std::abs(c) < kTiny) c = kTiny;
      d = 1.0 / d;
      h *= d * c;
      aa = -(a + m) * (a + b + m) * x / ((a + m2) * (a + m2 + 1.0));
    }
    if (std::abs(d * c - 1.0) < 1e-15) break;
  }
  return h;
}

// Regularised incomplete beta I_x(a, b), each tail from the side where its fraction converges.
double RegularizedBeta(double a, double b, double x) {
  if (x <= 0.0) return 0.0;
  if (x >= 1.0) return 1.0;
  const double log_front =
      std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) + b * std::log1p(-x);
  if (x < (a + 1.0) / (a + b + 2.0))
    return std::exp(log_front) * BetaContinuedFraction(a, b, x) / a;
  return 1.0 - std::exp(log_front) * BetaContinuedFraction(b, a, 1.0 - x) / b;
}

// P(F > f) for F ~ F(d1, d2), computed as the lower tail of a beta so tiny values keep precision.
double FSurvival(double f, double d1, double d2) {
  if (!(f > 0.0)) return 1.0;
  return RegularizedBeta(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f));
}

double NormalTwoSided(double z) { return std::erfc(std::abs(z) / std::sqrt(2.0)); }

// sum_{|k| <= m} (1 - |k| / (m + 1)) sum_t g_t g_{t-k}^T over the rows of g (Newey-West's
// Bartlett-weighted long-run sum). It equals (1 / (m + 1)) sum_t B_t B_t^T with B_t the sums of
// m + 1 consecutive rows (the series zero-padded), O(n) for any bandwidth. The bandwidth is
// Andrews' (1991) AR(1) plug-in for the Bartlett kernel, 1.1447 (alpha n)^(1/3), from the
// column whose lag-one autocorrelation asks for the widest, at most n / 4.
Eigen::MatrixXd LongRunSum(const Eigen::MatrixXd& g) {
  const int n = static_cast<int>(g.rows());
  const int p = static_cast<int>(g.cols());
  double alpha = 0.0;
  for (int j = 0; j < p; ++j) {
    const double s0 = g.col(j).squaredNorm();
    if (s0 <= 0.0) continue;
    const double s1 = g.col(j).tail(n - 1).dot(g.col(j).head(n - 1));
    const double rho = std::clamp(s1 / s0, -0.999, 0.999);
    alpha = std::max(alpha, 4.0 * rho * rho / std::pow((1.0 - rho) * (1.0 + rho), 2));
  }
  const int m = std::min(
      n / 4, static_cast<int>(std::ceil(1.1447 * std::cbrt(alpha * static_cast<double>(n)))));
  Eigen::MatrixXd sum = Eigen::MatrixXd::Zero(p, p);
  Eigen::VectorXd block = Eigen::VectorXd::Zero(p);
  // Block B_t covers rows [t, t + m], t from -m to n - 1.
  for (int t = -m; t < n; ++t) {
    if (t + m < n) block += g.row(t + m).transpose();
    if (t - 1 >= 0) block -= g.row(t - 1).transpose();
    sum.noalias() += block * block.transpose();
  }
  return sum / (m + 1.0);
}

// Covariance of least-squares coefficients of y ~ X with Newey-West standard errors (scaled by
// n / (n - p) so that white residuals give the ordinary ones).
Eigen::MatrixXd CoefficientCovariance(const Eigen::MatrixXd& X, const Eigen::VectorXd& u) {
  const double n = static_cast<double>(X.rows());
  const Eigen::MatrixXd bread = (X.transpose() * X).inverse();
  const Eigen::MatrixXd meat = LongRunSum(X.array().colwise() * u.array());
  return bread * meat * bread * (n / (n - X.cols()));
}

// Digamma and trigamma: the mean and variance of log(chi2(dof) / dof) are
// digamma(dof / 2) - log(dof / 2) and trigamma(dof / 2). Recurrence up to 6, then the asymptotic
// series (error below 1e-10 there).
double Digamma(double x) {
  double r = 0.0;
  for (; x < 6.0; x += 1.0) r -= 1.0 / x;
  const double x2 = 1.0 / (x * x);
  return r + std::log(x) - 0.5 / x - x2 * (1.0 / 12 - x2 * (1.0 / 120 - x2 / 252));
}
double Trigamma(double x) {
  double r = 0.0;
  for (; x < 6.0; x += 1.0) r += 1.0 / (x * x);
  const double x2 = 1.0 / (x * x);
  return r + 1.0 / x + 0.5 * x2 + x2 / x * (1.0 / 6 - x2 * (1.0 / 30 - x2 / 42));
}

// The PSD's noise floor at each searched bin and the degrees of freedom of its estimate.
struct NoiseFloor {
  std::vector<double> mean;  // 0 where the band holds too few bins
  std::vector<double> dof;
};

// Per bin k: a line in log PSD, least squares over the band k +- kFloorHalfWidth, evaluated at k.
// The band is mirrored at DC and Nyquist (a PSD is even about both) so that it stays centred; the
// line follows a coloured floor's slope (in log, so a steep one too) where a running median over
// a shifted band would not. Left out of the fit: the peak's own lobe (|m - k| <= kPeakHalfWidth),
// DC and bin 1 (the means removed per window take power from them), Nyquist (half the dof), and
// bins standing out of the band's running median at per-bin level 1e-3 (other peaks). A noise
// bin's log scatters by trigamma(dof / 2) about log(mean) + digamma(dof / 2) - log(dof / 2); the
// fit's value at k, sum_m W_m log psd_m, by trigamma(dof / 2) sum_m W_m^2 bin_correlation
// (neighbours correlated). psd_k / floor_k is then taken as F(dof, dof_floor), dof_floor the dof
// of a chi2 / dof whose log has that variance. (A quadratic, which follows curvature too, costs
// the floor so much scatter across the lobe's gap that weak peaks go unseen: a sinusoid at 0.12
// of unit noise, 8192 samples, window 256, was found in 9 % of the seeds against 33 %; switching
// to it only where the curvature is significant gained little calibration.)
NoiseFloor FitNoiseFloor(const Spectrum& s, int first, int last) {
  const int nyquist = static_cast<int>(s.psd.size()) - 1;
  const int half = std::min(kFloorHalfWidth, nyquist - 1);
  NoiseFloor floor{std::vector<double>(nyquist + 1, 0.0), std::vector<double>(nyquist + 1, 0.0)};
  auto mirror = [&](int j) { return j < 0 ? -j : (j > nyquist ? 2 * nyquist - j : j); };

  // Running median of the band, only to flag other peaks.
  const double median_to_mean = s.dof / stats::ChiSquareQuantile(0.5, s.dof);
  const double outlier = stats::ChiSquareQuantile(1.0 - 1e-3, s.dof) / s.dof;
  std::vector<char> flagged(nyquist + 1, 0);
  std::vector<double> scratch(2 * half + 1);
  for (int k = 1; k < nyquist; ++k) {
    int count = 0;
    for (int j = k - half; j <= k + half; ++j) {
      if (mirror(j) > 1) scratch[count++] = s.psd[mirror(j)];
    }
    if (count == 0) continue;
    std::nth_element(scratch.begin(), scratch.begin() + count / 2, scratch.begin() + count);
    flagged[k] = s.psd[k] > outlier * median_to_mean * scratch[count / 2];
  }

  const double log_bias = Digamma(0.5 * s.dof) - std::log(0.5 * s.dof);
  std::vector<double> weight(nyquist + 1, 0.0);
  for (int k = first; k <= last; ++k) {
    auto usable = [&](int m) {
      return m > 1 && m < nyquist && std::abs(m - k) > kPeakHalfWidth && !flagged[m] &&
             s.psd[m] > 0.0;
    };
    Eigen::Matrix2d normal = Eigen::Matrix2d::Zero();
    Eigen::Vector2d rhs = Eigen::Vector2d::Zero();
    int points = 0;
    for (int j = k - half; j <= k + half; ++j) {
      if (!usable(mirror(j))) continue;
      const Eigen::Vector2d phi(1.0, j - k);
      normal += phi * phi.transpose();
      rhs += phi * std::log(s.psd[mirror(j)]);
      ++points;
    }
    if (points < 6) continue;
    // The fit's value at k is row . rhs: each point's weight is row . phi.
    const Eigen::Vector2d row = normal.inverse().col(0);
    for (int m = std::max(0, k - half); m <= std::min(nyquist, k + half); ++m) weight[m] = 0.0;
    for (int j = k - half; j <= k + half; ++j) {
      if (usable(mirror(j))) weight[mirror(j)] += row(0) + row(1) * (j - k);  // mirrored: twice
    }
    double sum_w2 = 0.0;
    for (int m = std::max(0, k - half); m <= std::min(nyquist, k + half); ++m) {
      sum_w2 += weight[m] * weight[m];
    }
    floor.mean[k] = std::exp(row.dot(rhs) - log_bias);
    // trigamma(x) ~ 1 / (x - 1/2) for the dof of that variance.
    floor.dof[k] = 2.0 / (Trigamma(0.5 * s.dof) * sum_w2 * s.bin_correlation) + 1.0;
  }
  return floor;
}

}  // namespace

Spectrum Welch(const double* x, int n, double rate_hz, int window) {
  CheckSeries(x, n, "Welch: x");
  CheckRate(rate_hz, "Welch");
  if (window < 8) throw std::invalid_argument("Welch: window must be at least 8 samples");
  int size = 8;
  while (size * 2 <= std::min(window, n)) size *= 2;
  const int hop = size / 2;
  const int bins = size / 2 + 1;

  // Periodic Hann: overlapped by half, the windows sum to a constant.
  std::vector<double> hann(size);
  for (int i = 0; i < size; ++i) hann[i] = 0.5 - 0.5 * std::cos(2.0 * kPi * i / size);
  const double power = std::inner_product(hann.begin(), hann.end(), hann.begin(), 0.0);
  std::vector<int> bit_reversed(size, 0);
  for (int i = 1; i < size; ++i) {
    bit_reversed[i] = (bit_reversed[i >> 1] >> 1) | ((i & 1) ? size >> 1 : 0);
  }
  std::vector<std::complex<double>> twiddle(size / 2);
  for (int j = 0; j < size / 2; ++j) twiddle[j] = std::polar(1.0, -2.0 * kPi * j / size);
  std::vector<std::complex<double>> buffer(size);

  Spectrum s;
  s.rate_hz = rate_hz;
  s.df_hz = rate_hz / size;
  s.windows = 1 + (n - size) / hop;
  s.frequency_hz.resize(bins);
  s.psd.assign(bins, 0.0);
  for (int k = 0; k < bins; ++k) s.frequency_hz[k] = k * s.df_hz;
  for (int w = 0; w < s.windows; ++w) {
    const double* seg = x + static_cast<std::ptrdiff_t>(w) * hop;
    const double mean = std::accumulate(seg, seg + size, 0.0) / size;
    for (int i = 0; i < size; ++i) buffer[i] = (seg[i] - mean) * hann[i];
    Fft(buffer, bit_reversed, twiddle);
    for (int k = 0; k < bins; ++k) s.psd[k] += std::norm(buffer[k]);
  }
  // One-sided: the negative frequencies fold onto 1 .. size/2 - 1; DC and Nyquist have no twin.
  for (int k = 0; k < bins; ++k) {
    const double fold = (k == 0 || k == bins - 1) ? 1.0 : 2.0;
    s.psd[k] *= fold / (rate_hz * power * s.windows);
  }

  // Welch's (1967) equivalent degrees of freedom: with 50 % overlap only neighbouring windows
  // share samples, correlated by rho = sum w_t w_{t+hop} / sum w^2 (1/6 for Hann), so
  // dof = 2K / (1 + 2 (1 - 1/K) rho^2) (Percival & Walden, eq. 292b).
  double rho = 0.0;
  for (int i = 0; i + hop < size; ++i) rho += hann[i] * hann[i + hop];
  rho /= power;
  const double k_windows = s.windows;
  s.dof = 2.0 * k_windows / (1.0 + 2.0 * (1.0 - 1.0 / k_windows) * rho * rho);
  // Noise bins j apart are correlated by |sum w^2 exp(2 pi i j t / size)| / sum w^2 (complex
  // amplitudes), their powers by its square; Hann's w^2 has harmonics 1 and 2 only.
  s.bin_correlation = 1.0;
  for (int j = 1; j <= 4 && j < bins; ++j) {
    std::complex<double> c = 0.0;
    for (int t = 0; t < size; ++t)
      c += hann[t] * hann[t] * std::polar(1.0, 2.0 * kPi * j * t / size);
    s.bin_correlation += 2.0 * std::norm(c / power);
  }
  return s;
}

std::vector<SpectrumPeak> FindPeaks(const Spectrum& s, double alpha, int max_peaks, double min_hz) {
  std::vector<SpectrumPeak> peaks;
  const int bins = static_cast<int>(s.psd.size());
  // A peak's lobe must stay clear of DC and Nyquist: a slower periodic residual is not told from a
  // drift (a floor that rises towards DC), nor one closer to Nyquist from aliasing.
  const int nyquist = bins - 1;
  const int last = nyquist - kPeakHalfWidth - 1;
  const int first =
      std::max(kPeakHalfWidth + 1, static_cast<int>(std::ceil(min_hz / s.df_hz - 1e-9)));
  if (last < first || !(s.dof > 0.0) || !(s.df_hz > 0.0) || max_peaks <= 0) return peaks;
  const int searched = last - first + 1;
  const NoiseFloor floor = FitNoiseFloor(s, first, last);

  struct Candidate {
    int bin;
    double ratio;
    double p;
  };
  std::vector<Candidate> candidates;
  for (int k = first; k <= last; ++k) {
    if (!(floor.mean[k] > 0.0) || !(s.psd[k] > s.psd[k - 1]) || s.psd[k] < s.psd[k + 1]) continue;
    const double ratio = s.psd[k] / floor.mean[k];
    const double p = std::min(1.0, searched * FSurvival(ratio, s.dof, floor.dof[k]));
    if (p < alpha) candidates.push_back({k, ratio, p});
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.ratio > b.ratio; });
  std::vector<Candidate> kept;
  for (const Candidate& c : candidates) {
    const bool merged = std::any_of(kept.begin(), kept.end(), [&](const Candidate& k) {
      return std::abs(k.bin - c.bin) <= kPeakHalfWidth;
    });
    if (!merged) kept.push_back(c);
  }
  std::stable_sort(kept.begin(), kept.end(),
                   [](const Candidate& a, const Candidate& b) { return a.p < b.p; });
  if (static_cast<int>(kept.size()) > max_peaks) kept.resize(max_peaks);

  for (const Candidate& c : kept) {
    // A sinusoid of amplitude A holds variance A^2 / 2 = the PSD's excess integrated over its lobe.
    double excess = 0.0;
    double weight = 0.0;
    double weighted_hz = 0.0;
    for (int j = std::max(0, c.bin - kPeakHalfWidth);
         j <= std::min(bins - 1, c.bin + kPeakHalfWidth); ++j) {
      const double e = s.psd[j] - floor.mean[c.bin];
      excess += e;
      weight += std::max(e, 0.0);
      weighted_hz += std::max(e, 0.0) * s.frequency_hz[j];
    }
    SpectrumPeak peak;
    peak.frequency_hz = weight > 0.0 ? weighted_hz / weight : s.frequency_hz[c.bin];
    peak.amplitude = std::sqrt(2.0 * std::max(excess, 0.0) * s.df_hz);
    peak.power_ratio = c.ratio;
    peak.p_value = c.p;
    peaks.push_back(peak);
  }
  return peaks;
}

VelocityTrend ResidualVersusVelocity(const double* residual, const double* velocity, int n,
                                     int bins) {
  CheckSeries(residual, n, "ResidualVersusVelocity: residual");
  CheckSeries(velocity, n, "ResidualVersusVelocity: velocity");
  if (bins < 1) throw std::invalid_argument("ResidualVersusVelocity: bins must be at least 1");
  bins = std::min(bins, n);

  VelocityTrend trend;
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return velocity[a] < velocity[b]; });
  for (int b = 0; b < bins; ++b) {
    const int begin = static_cast<int>(static_cast<long long>(b) * n / bins);
    const int end = static_cast<int>(static_cast<long long>(b + 1) * n / bins);
    double v = 0.0, r = 0.0;
    for (int i = begin; i < end; ++i) {
      v += velocity[order[i]];
      r += residual[order[i]];
    }
    trend.bin_velocity.push_back(v / (end - begin));
    trend.bin_mean.push_back(r / (end - begin));
    trend.bin_count.push_back(end - begin);
  }

  // Columns: intercept, then sign(v) and v where they vary (a constant one is the intercept).
  Eigen::Map<const Eigen::VectorXd> r(residual, n);
  Eigen::Map<const Eigen::VectorXd> v(velocity, n);
  const Eigen::VectorXd sign = v.unaryExpr([](double x) { return double((x > 0) - (x < 0)); });
  const double tss = (r.array() - r.mean()).square().sum();
  if (!(tss > 0.0)) return trend;
  const bool has_sign = sign.maxCoeff() > sign.minCoeff();
  const bool has_v = v.maxCoeff() > v.minCoeff();
  const int p = 1 + has_sign + has_v;
  if (p == 1 || n <= p) return trend;
  Eigen::MatrixXd X(n, p);
  X.col(0).setOnes();
  int col = 1;
  const int sign_col = has_sign ? col++ : -1;
  const int v_col = has_v ? col++ : -1;
  if (sign_col > 0) X.col(sign_col) = sign;
  if (v_col > 0) X.col(v_col) = v;
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(X);
  if (qr.rank() < p) return trend;  // sign(v) and v carry the same information
  const Eigen::VectorXd beta = qr.solve(r);
  const Eigen::VectorXd u = r - X * beta;
  trend.explained_fraction = std::max(0.0, 1.0 - u.squaredNorm() / tss);
  const Eigen::MatrixXd cov = CoefficientCovariance(X, u);
  auto test = [&](int c, double& value, double& se, double& p_value) {
    if (c < 0) return;
    value = beta(c);
    se = std::sqrt(std::max(cov(c, c), 0.0));
    p_value = se > 0.0 ? NormalTwoSided(value / se) : (value != 0.0 ? 0.0 : 1.0);
  };
  test(sign_col, trend.coulomb, trend.coulomb_se, trend.coulomb_p);
  test(v_col, trend.viscous, trend.viscous_se, trend.viscous_p);
  return trend;
}

LagTrend ResidualVersusCommandLag(const double* residual, const double* command_rate, int n,
                                  double rate_hz, double max_lag_s) {
  CheckSeries(residual, n, "ResidualVersusCommandLag: residual");
  CheckSeries(command_rate, n, "ResidualVersusCommandLag: command_rate");
  CheckRate(rate_hz, "ResidualVersusCommandLag");
  if (!(max_lag_s >= 0.0) || !std::isfinite(max_lag_s)) {
    throw std::invalid_argument("ResidualVersusCommandLag: max_lag_s must be >= 0 and finite");
  }
  LagTrend trend;
  Eigen::Map<const Eigen::VectorXd> r_raw(residual, n);
  Eigen::Map<const Eigen::VectorXd> dc_raw(command_rate, n);
  const Eigen::VectorXd r = r_raw.array() - r_raw.mean();
  const Eigen::VectorXd dc = dc_raw.array() - dc_raw.mean();
  const double rr = r.squaredNorm();
  const double cc = dc.squaredNorm();
  if (!(rr > 0.0) || !(cc > 0.0)) return trend;

  // Lag 0's least-squares delay, r = -tau dc + u, with a Newey-West standard error.
  const double b = r.dot(dc) / cc;
  trend.delay_s = -b;
  const Eigen::VectorXd u = r - b * dc;
  trend.delay_se_s = std::sqrt(std::max(CoefficientCovariance(dc, u)(0, 0), 0.0));

  // corr(r(t), dc(t - lag)) over the samples both cover; prefix sums give each lag's norms.
  const int max_lag =
      static_cast<int>(std::min<long>(std::lround(std::min(max_lag_s * rate_hz, n / 4.0)), n / 4));
  std::vector<double> r2(n + 1, 0.0), c2(n + 1, 0.0);
  for (int i = 0; i < n; ++i) {
    r2[i + 1] = r2[i] + r(i) * r(i);
    c2[i + 1] = c2[i] + dc(i) * dc(i);
  }
  int best_lag = 0;
  double best = 0.0;
  for (int lag = -max_lag; lag <= max_lag; ++lag) {
    const int t0 = std::max(0, lag);
    const int t1 = std::min(n, n + lag);
    const double norm = (r2[t1] - r2[t0]) * (c2[t1 - lag] - c2[t0 - lag]);
    if (!(norm > 0.0)) continue;
    const double corr = r.segment(t0, t1 - t0).dot(dc.segment(t0 - lag, t1 - t0)) / std::sqrt(norm);
    if (std::abs(corr) > std::abs(best)) {
      best = corr;
      best_lag = lag;
    }
  }
  trend.lag_s = best_lag / rate_hz;
  trend.correlation = best;

  // Effective sample size: the product r dc scatters by its Bartlett long-run variance, not by
  // var(r) var(dc) / n as for independent samples; never more than the samples themselves.
  const int t0 = std::max(0, best_lag);
  const int overlap = std::min(n, n + best_lag) - t0;
  const Eigen::VectorXd rs = r.segment(t0, overlap);
  const Eigen::VectorXd cs = dc.segment(t0 - best_lag, overlap);
  Eigen::VectorXd g = rs.cwiseProduct(cs);
  g.array() -= g.mean();
  const double long_run = LongRunSum(g)(0, 0);
  double n_eff = overlap;
  if (long_run > 0.0) n_eff = std::min(n_eff, rs.squaredNorm() * cs.squaredNorm() / long_run);
  if (n_eff > 3.0 && std::abs(best) < 1.0) {
    const double z = std::atanh(best) * std::sqrt(n_eff - 3.0);
    trend.p_value = std::min(1.0, (2.0 * max_lag + 1.0) * NormalTwoSided(z));
  } else if (std::abs(best) >= 1.0) {
    trend.p_value = 0.0;
  }
  return trend;
}

}  // namespace flexbench::identify::dynamic
