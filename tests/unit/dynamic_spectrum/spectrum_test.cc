// Motion diagnostics on synthetic residuals: Welch's PSD keeps the variance, a sinusoid on noise is
// found with its frequency and amplitude, and each test's p-value is calibrated (its false-positive
// rate over many noise-only seeds stays at or below alpha), for white and for serially correlated
// residuals.
#include "scenarios/identify/dynamic/spectrum.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace flexbench::identify::dynamic {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::vector<double> WhiteNoise(std::mt19937& rng, int n, double sigma) {
  std::normal_distribution<double> normal(0.0, sigma);
  std::vector<double> x(n);
  for (double& v : x) v = normal(rng);
  return x;
}

// AR(1) noise of stationary standard deviation sigma: a residual that is serially correlated, as
// a rollout's residual is.
std::vector<double> Ar1Noise(std::mt19937& rng, int n, double phi, double sigma) {
  std::normal_distribution<double> normal(0.0, sigma * std::sqrt(1.0 - phi * phi));
  std::vector<double> x(n);
  double state = normal(rng) / std::sqrt(1.0 - phi * phi);
  for (double& v : x) v = state = phi * state + normal(rng);
  return x;
}

// A smooth random motion: a few sinusoids between f_lo and f_hi (Hz), its value and derivative.
struct Smooth {
  std::vector<double> amplitude, omega, phase;
  double Value(double t) const {
    double s = 0.0;
    for (size_t i = 0; i < omega.size(); ++i) s += amplitude[i] * std::sin(omega[i] * t + phase[i]);
    return s;
  }
  double Rate(double t) const {
    double s = 0.0;
    for (size_t i = 0; i < omega.size(); ++i) {
      s += amplitude[i] * omega[i] * std::cos(omega[i] * t + phase[i]);
    }
    return s;
  }
};
Smooth RandomSmooth(std::mt19937& rng, double f_lo, double f_hi) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Smooth s;
  for (int i = 0; i < 4; ++i) {
    s.amplitude.push_back(0.5 + unit(rng));
    s.omega.push_back(2.0 * kPi * (f_lo + (f_hi - f_lo) * unit(rng)));
    s.phase.push_back(2.0 * kPi * unit(rng));
  }
  return s;
}

TEST(DynamicSpectrum, WelchOfWhiteNoiseKeepsItsVariance) {
  std::mt19937 rng(11);
  const double sigma = 0.7, rate_hz = 500.0;
  const std::vector<double> x = WhiteNoise(rng, 8192, sigma);
  const Spectrum s = Welch(x.data(), static_cast<int>(x.size()), rate_hz, 256);
  ASSERT_EQ(s.psd.size(), 129u);
  EXPECT_EQ(s.windows, 63);
  EXPECT_DOUBLE_EQ(s.df_hz, rate_hz / 256);
  EXPECT_DOUBLE_EQ(s.frequency_hz.back(), rate_hz / 2);
  // Welch's dof for Hann at 50 %: 2K / (1 + 2 (1 - 1/K) / 36).
  EXPECT_NEAR(s.dof, 2.0 * 63 / (1.0 + 2.0 * (1.0 - 1.0 / 63) / 36.0), 1e-9);
  EXPECT_NEAR(s.bin_correlation, 1.0 + 2.0 * (4.0 / 9 + 1.0 / 36), 1e-9);
  // Parseval: the mean one-sided PSD times the band rate_hz / 2 is the variance (DC excluded: the
  // mean removed per window leaves it near zero).
  const double mean_psd =
      std::accumulate(s.psd.begin() + 1, s.psd.end() - 1, 0.0) / (s.psd.size() - 2);
  std::printf("white noise: mean PSD * rate / 2 = %.4f, variance %.4f\n", mean_psd * rate_hz / 2,
              sigma * sigma);
  EXPECT_NEAR(mean_psd * rate_hz / 2 / (sigma * sigma), 1.0, 0.03);
}

TEST(DynamicSpectrum, OneWindowIsTheDirectTransformOfTheHannWindowedSamples) {
  // One window: the PSD is the DFT's power, summed directly here, scaled as documented.
  std::mt19937 rng(13);
  const int n = 64;
  const double rate_hz = 50.0;
  const std::vector<double> x = WhiteNoise(rng, n, 1.0);
  const Spectrum s = Welch(x.data(), n, rate_hz, n);
  ASSERT_EQ(s.windows, 1);
  const double mean = std::accumulate(x.begin(), x.end(), 0.0) / n;
  double power = 0.0;
  std::vector<double> w(n);
  for (int t = 0; t < n; ++t) {
    w[t] = 0.5 - 0.5 * std::cos(2.0 * kPi * t / n);
    power += w[t] * w[t];
  }
  for (int k = 0; k <= n / 2; ++k) {
    double re = 0.0, im = 0.0;
    for (int t = 0; t < n; ++t) {
      re += (x[t] - mean) * w[t] * std::cos(2.0 * kPi * k * t / n);
      im -= (x[t] - mean) * w[t] * std::sin(2.0 * kPi * k * t / n);
    }
    const double fold = (k == 0 || k == n / 2) ? 1.0 : 2.0;
    EXPECT_NEAR(s.psd[k], fold * (re * re + im * im) / (rate_hz * power), 1e-12) << "bin " << k;
  }
}

TEST(DynamicSpectrum, WindowIsAPowerOfTwoAtMostTheSamples) {
  std::mt19937 rng(12);
  const std::vector<double> x = WhiteNoise(rng, 100, 1.0);
  EXPECT_EQ(Welch(x.data(), 100, 10.0, 1000).psd.size(), 64u / 2 + 1);  // 64 <= 100
  EXPECT_EQ(Welch(x.data(), 100, 10.0, 40).psd.size(), 32u / 2 + 1);    // 32 <= 40
  EXPECT_EQ(Welch(x.data(), 100, 10.0, 40).windows, 1 + (100 - 32) / 16);
}

TEST(DynamicSpectrum, SinusoidOnNoiseIsFoundWithItsFrequencyAndAmplitude) {
  const double rate_hz = 500.0, amplitude = 0.2, sigma = 0.5;
  const int n = 16384, window = 512;
  const double df = rate_hz / window;
  // On a bin, a quarter and half a bin off: the amplitude must not depend on the scalloping.
  for (double offset : {0.0, 0.25, 0.5}) {
    std::mt19937 rng(21);
    const double f0 = (38.0 + offset) * df;
    std::vector<double> x = WhiteNoise(rng, n, sigma);
    for (int i = 0; i < n; ++i) x[i] += amplitude * std::sin(2.0 * kPi * f0 * i / rate_hz + 0.3);
    const Spectrum s = Welch(x.data(), n, rate_hz, window);
    const std::vector<SpectrumPeak> peaks = FindPeaks(s, 0.01, 5);
    ASSERT_FALSE(peaks.empty()) << "offset " << offset;
    const SpectrumPeak& p = peaks.front();
    std::printf("sinusoid %.3f Hz (+%.2f bin), A %.3f: found %.3f Hz, A %.4f, ratio %.1f, p %.2g\n",
                f0, offset, amplitude, p.frequency_hz, p.amplitude, p.power_ratio, p.p_value);
    EXPECT_NEAR(p.frequency_hz, f0, df);
    EXPECT_NEAR(p.amplitude / amplitude, 1.0, 0.10);
    EXPECT_LT(p.p_value, 1e-6);
    for (size_t i = 1; i < peaks.size(); ++i) {
      EXPECT_GT(std::abs(peaks[i].frequency_hz - f0), 2 * df);  // merged into the main peak
    }
  }
}

TEST(DynamicSpectrum, MinHzAndMaxPeaksLimitTheSearch) {
  std::mt19937 rng(22);
  const double rate_hz = 200.0;
  const int n = 8192;
  std::vector<double> x = WhiteNoise(rng, n, 0.1);
  for (int i = 0; i < n; ++i) {
    const double t = i / rate_hz;
    x[i] += 0.5 * std::sin(2.0 * kPi * 5.0 * t) + 0.3 * std::sin(2.0 * kPi * 40.0 * t);
  }
  const Spectrum s = Welch(x.data(), n, rate_hz, 256);
  const std::vector<SpectrumPeak> both = FindPeaks(s, 0.01, 10);
  ASSERT_GE(both.size(), 2u);
  const std::vector<SpectrumPeak> one = FindPeaks(s, 0.01, 1);
  ASSERT_EQ(one.size(), 1u);
  const std::vector<SpectrumPeak> high = FindPeaks(s, 0.01, 10, 20.0);
  ASSERT_FALSE(high.empty());
  for (const SpectrumPeak& p : high) EXPECT_GE(p.frequency_hz, 20.0 - s.df_hz);
  EXPECT_NEAR(high.front().frequency_hz, 40.0, s.df_hz);
}

// Fraction of noise-only seeds with any peak at level alpha (4096 samples, window 256).
double PeakFalsePositiveRate(double alpha, double phi) {
  int hits = 0;
  const int seeds = 200;
  for (int seed = 0; seed < seeds; ++seed) {
    std::mt19937 rng(1000 + seed);
    const std::vector<double> x =
        phi == 0.0 ? WhiteNoise(rng, 4096, 1.0) : Ar1Noise(rng, 4096, phi, 1.0);
    const Spectrum s = Welch(x.data(), 4096, 100.0, 256);
    hits += !FindPeaks(s, alpha, 10).empty();
  }
  return static_cast<double>(hits) / seeds;
}

TEST(DynamicSpectrum, PeakPValuesAreCalibratedOnNoise) {
  const double white = PeakFalsePositiveRate(0.01, 0.0);
  const double white_loose = PeakFalsePositiveRate(0.2, 0.0);
  // Coloured floors: AR(1) 0.5 falls by 9 from DC to Nyquist, AR(1) 0.9 by 361 with a hump at DC
  // a few bins wide; the floor must follow both.
  const double coloured = PeakFalsePositiveRate(0.01, 0.5);
  const double steep = PeakFalsePositiveRate(0.01, 0.9);
  std::printf(
      "peaks, noise only, 200 seeds: any peak at alpha 0.01: white %.3f, AR(1) 0.5 %.3f, "
      "AR(1) 0.9 %.3f; at alpha 0.2: white %.3f\n",
      white, coloured, steep, white_loose);
  EXPECT_LE(white, 0.02);
  EXPECT_LE(coloured, 0.02);
  EXPECT_LE(steep, 0.02);
  // Bonferroni over correlated bins is conservative, but the test is not blind: the rate at 0.2
  // is within 3 binomial standard errors below (or at most that above) alpha.
  EXPECT_LE(white_loose, 0.28);
  EXPECT_GE(white_loose, 0.12);
}

TEST(DynamicSpectrum, CoulombFrictionIsFoundInTheResidual) {
  std::mt19937 rng(31);
  const int n = 4000;
  const double rate_hz = 100.0;
  const Smooth motion = RandomSmooth(rng, 0.05, 0.5);
  const std::vector<double> noise = WhiteNoise(rng, n, 0.5);
  std::vector<double> v(n), r(n);
  for (int i = 0; i < n; ++i) {
    v[i] = motion.Rate(i / rate_hz);
    r[i] = 0.3 * ((v[i] > 0) - (v[i] < 0)) + noise[i];
  }
  const VelocityTrend t = ResidualVersusVelocity(r.data(), v.data(), n, 8);
  std::printf("coulomb 0.3: %.4f +- %.4f (p %.2g), viscous %.4f +- %.4f (p %.2g), explained %.3f\n",
              t.coulomb, t.coulomb_se, t.coulomb_p, t.viscous, t.viscous_se, t.viscous_p,
              t.explained_fraction);
  EXPECT_NEAR(t.coulomb, 0.3, 3 * t.coulomb_se);
  EXPECT_LT(t.coulomb_se, 0.05);
  EXPECT_LT(t.coulomb_p, 1e-10);
  EXPECT_NEAR(t.viscous, 0.0, 4 * t.viscous_se);
  // Variance explained: 0.09 of 0.09 + 0.25.
  EXPECT_NEAR(t.explained_fraction, 0.09 / 0.34, 0.05);
  ASSERT_EQ(t.bin_count.size(), 8u);
  EXPECT_EQ(std::accumulate(t.bin_count.begin(), t.bin_count.end(), 0), n);
  for (int b = 0; b < 8; ++b) EXPECT_EQ(t.bin_count[b], n / 8);
  for (int b = 1; b < 8; ++b) EXPECT_GT(t.bin_velocity[b], t.bin_velocity[b - 1]);
  EXPECT_LT(t.bin_mean.front(), -0.15);
  EXPECT_GT(t.bin_mean.back(), 0.15);
}

TEST(DynamicSpectrum, ViscousFrictionIsFoundInTheResidual) {
  std::mt19937 rng(32);
  const int n = 4000;
  const Smooth motion = RandomSmooth(rng, 0.05, 0.5);
  const std::vector<double> noise = WhiteNoise(rng, n, 0.5);
  std::vector<double> v(n), r(n);
  for (int i = 0; i < n; ++i) {
    v[i] = motion.Rate(i / 100.0);
    r[i] = 0.2 * v[i] + 0.1 + noise[i];  // with an offset, which the intercept takes
  }
  const VelocityTrend t = ResidualVersusVelocity(r.data(), v.data(), n, 10);
  std::printf("viscous 0.2: %.4f +- %.4f (p %.2g), coulomb %.4f +- %.4f\n", t.viscous, t.viscous_se,
              t.viscous_p, t.coulomb, t.coulomb_se);
  EXPECT_NEAR(t.viscous, 0.2, 3 * t.viscous_se);
  EXPECT_LT(t.viscous_p, 1e-10);
  EXPECT_NEAR(t.coulomb, 0.0, 4 * t.coulomb_se);
}

// Fractions of noise-only seeds with coulomb_p, viscous_p < alpha, for a residual with lag-one
// autocorrelation phi.
std::pair<double, double> VelocityFalsePositiveRate(double alpha, double phi) {
  int coulomb = 0, viscous = 0;
  const int seeds = 200, n = 4000;
  for (int seed = 0; seed < seeds; ++seed) {
    std::mt19937 rng(2000 + seed);
    const Smooth motion = RandomSmooth(rng, 0.05, 0.5);
    const std::vector<double> r = phi == 0.0 ? WhiteNoise(rng, n, 0.5) : Ar1Noise(rng, n, phi, 0.5);
    std::vector<double> v(n);
    for (int i = 0; i < n; ++i) v[i] = motion.Rate(i / 100.0);
    const VelocityTrend t = ResidualVersusVelocity(r.data(), v.data(), n, 8);
    coulomb += t.coulomb_p < alpha;
    viscous += t.viscous_p < alpha;
  }
  return {static_cast<double>(coulomb) / seeds, static_cast<double>(viscous) / seeds};
}

TEST(DynamicSpectrum, VelocityPValuesAreCalibratedOnNoise) {
  const auto [coulomb, viscous] = VelocityFalsePositiveRate(0.01, 0.0);
  // Serially correlated (about 20 samples): ordinary standard errors would be about 6 times too
  // small; Newey-West's keep the rate near alpha.
  const auto [coulomb_ar, viscous_ar] = VelocityFalsePositiveRate(0.01, 0.9);
  std::printf(
      "velocity, noise only, 200 seeds, alpha 0.01: white coulomb %.3f viscous %.3f; "
      "AR(1) 0.9 coulomb %.3f viscous %.3f\n",
      coulomb, viscous, coulomb_ar, viscous_ar);
  EXPECT_LE(coulomb, 0.03);
  EXPECT_LE(viscous, 0.03);
  EXPECT_LE(coulomb_ar, 0.05);
  EXPECT_LE(viscous_ar, 0.05);
}

// A residual of a missing servo delay: the arm follows c(t - tau), the model c(t). The command
// moves at 0.1 .. 1 Hz, slow enough next to tau = 20 ms that the first-order estimate's bias,
// (w tau)^2 / 6 at most 0.26 %, stays well below its standard error.
struct DelayCase {
  std::vector<double> residual, command_rate;
};
DelayCase MakeDelay(std::mt19937& rng, int n, double rate_hz, double tau_s, double noise,
                    double phi) {
  const Smooth command = RandomSmooth(rng, 0.1, 1.0);
  DelayCase d;
  d.residual = phi == 0.0 ? WhiteNoise(rng, n, noise) : Ar1Noise(rng, n, phi, noise);
  d.command_rate.resize(n);
  for (int i = 0; i < n; ++i) {
    const double t = i / rate_hz;
    d.residual[i] += command.Value(t - tau_s) - command.Value(t);
    d.command_rate[i] = command.Rate(t);
  }
  return d;
}

TEST(DynamicSpectrum, MissingServoDelayIsEstimated) {
  const double rate_hz = 500.0, tau_s = 0.020;
  const int n = 10000;
  std::mt19937 rng(41);
  const DelayCase d = MakeDelay(rng, n, rate_hz, tau_s, 0.02, 0.0);
  const LagTrend t =
      ResidualVersusCommandLag(d.residual.data(), d.command_rate.data(), n, rate_hz, 0.1);
  std::printf("delay 20 ms: %.3f +- %.3f ms; lag %.1f ms, correlation %.3f, p %.2g\n",
              1e3 * t.delay_s, 1e3 * t.delay_se_s, 1e3 * t.lag_s, t.correlation, t.p_value);
  EXPECT_NEAR(t.delay_s, tau_s, 3 * t.delay_se_s);
  EXPECT_LT(t.delay_se_s, 0.05 * tau_s);
  EXPECT_LT(t.correlation, -0.5);
  EXPECT_LT(t.p_value, 1e-6);
  // c(t - tau) - c(t) is the command rate averaged over [t - tau, t]: centred tau / 2 back.
  EXPECT_NEAR(t.lag_s, tau_s / 2, tau_s);

  // Over seeds, with a serially correlated remainder: the standard error covers the truth.
  int outside = 0;
  const int seeds = 100;
  for (int seed = 0; seed < seeds; ++seed) {
    std::mt19937 r(3000 + seed);
    const DelayCase c = MakeDelay(r, n, rate_hz, tau_s, 0.02, 0.9);
    const LagTrend e =
        ResidualVersusCommandLag(c.residual.data(), c.command_rate.data(), n, rate_hz, 0.1);
    outside += std::abs(e.delay_s - tau_s) > 3 * e.delay_se_s;
  }
  std::printf("delay, AR(1) 0.9 remainder, %d seeds: %d outside 3 se\n", seeds, outside);
  EXPECT_LE(outside, 3);
}

TEST(DynamicSpectrum, DelayIsFirstOrderInTheCommandsFrequency) {
  // One sinusoid of angular frequency w, noise-free, 20 whole periods: the least-squares delay is
  // sin(w tau) / w, as the header says.
  const double rate_hz = 500.0, tau_s = 0.020;
  const int n = 10000;
  for (double f_hz : {1.0, 4.0}) {
    const double w = 2.0 * kPi * f_hz;
    std::vector<double> r(n), dc(n);
    for (int i = 0; i < n; ++i) {
      const double t = i / rate_hz;
      r[i] = std::sin(w * (t - tau_s)) - std::sin(w * t);
      dc[i] = w * std::cos(w * t);
    }
    const LagTrend t = ResidualVersusCommandLag(r.data(), dc.data(), n, rate_hz, 0.05);
    std::printf("delay 20 ms, command at %.0f Hz: %.4f ms, sin(w tau) / w = %.4f ms\n", f_hz,
                1e3 * t.delay_s, 1e3 * std::sin(w * tau_s) / w);
    EXPECT_NEAR(t.delay_s, std::sin(w * tau_s) / w, 1e-6);
  }
}

TEST(DynamicSpectrum, LagPValuesAreCalibratedOnNoise) {
  const double rate_hz = 500.0;
  const int n = 10000, seeds = 200;
  int white = 0, correlated = 0;
  for (int seed = 0; seed < seeds; ++seed) {
    std::mt19937 rng(4000 + seed);
    const DelayCase w = MakeDelay(rng, n, rate_hz, 0.0, 0.05, 0.0);
    white += ResidualVersusCommandLag(w.residual.data(), w.command_rate.data(), n, rate_hz, 0.1)
                 .p_value < 0.01;
    const DelayCase c = MakeDelay(rng, n, rate_hz, 0.0, 0.05, 0.9);
    correlated +=
        ResidualVersusCommandLag(c.residual.data(), c.command_rate.data(), n, rate_hz, 0.1)
            .p_value < 0.01;
  }
  std::printf("lag, noise only, %d seeds, alpha 0.01: white %.3f, AR(1) 0.9 %.3f\n", seeds,
              static_cast<double>(white) / seeds, static_cast<double>(correlated) / seeds);
  EXPECT_LE(white, 0.03 * seeds);
  EXPECT_LE(correlated, 0.05 * seeds);
}

TEST(DynamicSpectrum, BadInputThrowsAndConstantResidualIsNotAFinding) {
  std::vector<double> x(64, 1.0), v(64);
  for (int i = 0; i < 64; ++i) v[i] = std::sin(0.3 * i);
  EXPECT_THROW(Welch(x.data(), 7, 100.0, 8), std::invalid_argument);
  EXPECT_THROW(Welch(nullptr, 64, 100.0, 8), std::invalid_argument);
  EXPECT_THROW(Welch(x.data(), 64, 0.0, 8), std::invalid_argument);
  EXPECT_THROW(Welch(x.data(), 64, 100.0, 4), std::invalid_argument);
  std::vector<double> bad = x;
  bad[17] = std::numeric_limits<double>::quiet_NaN();
  try {
    Welch(bad.data(), 64, 100.0, 16);
    ADD_FAILURE() << "NaN accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("sample 17"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ResidualVersusVelocity(x.data(), bad.data(), 64, 4), std::invalid_argument);
  EXPECT_THROW(ResidualVersusVelocity(x.data(), v.data(), 64, 0), std::invalid_argument);
  EXPECT_THROW(ResidualVersusCommandLag(bad.data(), v.data(), 64, 100.0, 0.1),
               std::invalid_argument);
  EXPECT_THROW(ResidualVersusCommandLag(x.data(), v.data(), 64, 100.0, -1.0),
               std::invalid_argument);

  EXPECT_TRUE(FindPeaks(Welch(x.data(), 64, 100.0, 16), 0.01, 5).empty());
  const VelocityTrend t = ResidualVersusVelocity(x.data(), v.data(), 64, 4);
  EXPECT_EQ(t.coulomb_p, 1.0);
  EXPECT_EQ(t.viscous_p, 1.0);
  EXPECT_EQ(t.bin_count.size(), 4u);
  const LagTrend l = ResidualVersusCommandLag(x.data(), v.data(), 64, 100.0, 0.1);
  EXPECT_EQ(l.p_value, 1.0);
  EXPECT_EQ(l.delay_s, 0.0);

  // A velocity that never changes sign has no Coulomb term to test; the viscous one still is.
  std::mt19937 rng(51);
  std::vector<double> r = WhiteNoise(rng, 64, 1.0), forward(64);
  for (int i = 0; i < 64; ++i) forward[i] = 1.0 + 0.5 * std::sin(0.3 * i);
  const VelocityTrend f = ResidualVersusVelocity(r.data(), forward.data(), 64, 4);
  EXPECT_EQ(f.coulomb_p, 1.0);
  EXPECT_GT(f.viscous_se, 0.0);
}

}  // namespace
}  // namespace flexbench::identify::dynamic
