// Motion diagnostics: structure that a dynamic model's residual (measured minus model, along a
// recorded moving-arm log, uniformly sampled) keeps when the model lacks an effect.
//   - Welch / FindPeaks: a periodic residual (a resonance, a transmission ripple) is a peak of its
//     power spectral density above the noise floor.
//   - ResidualVersusVelocity: missing friction is a residual odd in the velocity's sign (Coulomb)
//     or growing with the velocity (viscous).
//   - ResidualVersusCommandLag: a missing servo delay is a residual proportional to the command's
//     rate.
// Residuals of rollouts are serially correlated, so the regressions' standard errors are
// heteroscedasticity-and-autocorrelation consistent (Newey-West: Bartlett kernel, Andrews' AR(1)
// plug-in bandwidth from the products regressor x residual) and the correlation test's effective
// sample size comes from the same long-run variance of residual x command rate; with white
// residuals both reduce to the ordinary ones (samples, not effective samples, cap the latter).
// Bad input (null pointer, n < 8, a non-finite sample, a non-positive rate) throws
// std::invalid_argument; a constant residual gives no peak and p-values of 1.
#pragma once
#include <vector>

namespace flexbench::identify::dynamic {

// One-sided power spectral density (signal units^2 / Hz): the integral over [0, rate_hz / 2] is
// the variance. Welch's method: Hann windows of `window` samples (rounded down to a power of two,
// at most n, at least 8), 50 % overlap, each window's mean removed.
struct Spectrum {
  double rate_hz = 0;
  double df_hz = 0;  // bin spacing, rate_hz / window
  std::vector<double> frequency_hz;
  std::vector<double> psd;
  int windows = 0;
  // Degrees of freedom of each bin's estimate (2 per window, fewer since overlapping windows are
  // correlated): a noise-only bin is psd_mean * chi2(dof) / dof.
  double dof = 0;
  // Neighbouring noise bins are correlated through the window: the mean of many adjacent bins
  // scatters as if there were this many times fewer (1 + 2 sum_j corr_j, corr_j the correlation
  // of the powers of bins j apart; 1 + 2 (4/9 + 1/36) for Hann). The noise floor's scatter uses it.
  double bin_correlation = 0;
};
Spectrum Welch(const double* x, int n, double rate_hz, int window);

// A peak of the PSD above its noise floor. The floor at a bin is a line fitted to the log PSD over
// the bins around it (+-8, mirrored at DC and Nyquist), leaving out the bin's own +-2 (robust to
// the peak itself) and bins far above a running median (other peaks): it follows a coloured
// residual's sloping floor. Under noise alone psd / floor is taken as F(dof, dof_floor): the
// bin's chi2(dof) / dof (Spectrum::dof, Welch's equivalent dof for the overlap) over the floor's
// own scatter (dof_floor from the fit's weights and the bins' correlation). p_value is
// Bonferroni-corrected over the bins searched: 3 .. window/2 - 3 and at least min_hz (a peak's
// +-2 bins clear of DC, where a slow drift piles up, and of Nyquist). Only local maxima count;
// peaks within +-2 bins of a stronger one merge into it. Calibration (noise only, white and AR(1)
// with coefficients -0.5 .. 0.97, 500 seeds each, 1024 to 32768 samples): with windows of 256
// samples or more the rate of any peak at alpha = 1 % was at most 1.4 %; with 64 or 128 samples
// and hundreds of windows a curved floor gave up to 5.4 %: use windows of 256 or more.
struct SpectrumPeak {
  double frequency_hz = 0;  // power-weighted centroid of the peak's +-2 bins
  double amplitude = 0;     // of a sinusoid with the excess power of the peak's +-2 bins
  double power_ratio = 0;   // psd / floor at the peak bin
  double p_value = 1;
};
// Peaks with p_value < alpha, smallest p first, at most max_peaks.
std::vector<SpectrumPeak> FindPeaks(const Spectrum& s, double alpha, int max_peaks,
                                    double min_hz = 0.0);

// Residual r (any unit) against one joint's velocity v (unit/s): equal-count bins of v sorted
// (the bin's mean v and mean r), and the least-squares fit r ~ c + coulomb sign(v) + viscous v.
// The intercept c keeps an offset the model lacks (a gravity or bias error) out of the Coulomb
// term when the motion spends more time in one direction. p-values are two-sided, normal
// approximation with the Newey-West standard errors; a term whose regressor is constant (the
// velocity never changes sign) or collinear with the others is not tested (p = 1).
// explained_fraction: the share of the residual's variance (about its mean) the two terms explain.
struct VelocityTrend {
  std::vector<double> bin_velocity;
  std::vector<double> bin_mean;
  std::vector<int> bin_count;
  double coulomb = 0, coulomb_se = 0, coulomb_p = 1;
  double viscous = 0, viscous_se = 0, viscous_p = 1;
  double explained_fraction = 0;
};
VelocityTrend ResidualVersusVelocity(const double* residual, const double* velocity, int n,
                                     int bins);

// Residual r against the commanded joint's rate dc/dt, sampled at rate_hz.
// Sign convention: delay_s > 0 means the arm lags the command. The arm then follows c(t - tau)
// while a model without the delay follows c(t), so r = c(t - tau) - c(t) ~ -tau dc/dt and
// delay_s = -<r, dc> / <dc, dc> (both with their means removed: an offset is not a delay). It is
// first order in tau: for a command at angular frequency w it gives sin(w tau) / w, low by
// (w tau)^2 / 6 relative (1 % at 2 Hz and 20 ms).
// lag_s > 0 means the residual follows the command rate later: the lag of the largest |corr(r(t),
// dc(t - lag))| over [-max_lag_s, max_lag_s]. A delay the model lacks gives a negative correlation
// near lag tau / 2 (c(t - tau) - c(t) is -tau times the mean of dc over [t - tau, t]), 0 for a
// small one. p_value: Fisher's z with the effective sample size, Bonferroni over the lags searched.
struct LagTrend {
  double lag_s = 0;
  double correlation = 0;
  double p_value = 1;
  double delay_s = 0;
  double delay_se_s = 0;
};
LagTrend ResidualVersusCommandLag(const double* residual, const double* command_rate, int n,
                                  double rate_hz, double max_lag_s);

}  // namespace flexbench::identify::dynamic
