// What a dynamic fit's residual still shows, located: a peak of a channel's spectrum (a mode the
// model lacks: its frequency, and the IMU or joint that shows it), a residual that follows a
// joint's velocity (friction), one that follows its command's rate (a servo delay), one that
// grows while a joint reverses (friction at low speed: Stribeck's breakaway, stiction). Each
// finding is significant (p below alpha, Bonferroni over the channels) and large enough to matter
// (its share of the channel's residual).
#pragma once

#include <string>
#include <vector>

#include "scenarios/identify/dynamic/fit.h"
#include "scenarios/identify/dynamic/spectrum.h"

namespace flexbench::identify::dynamic {

struct DiagnoseOptions {
  double alpha = 1e-3;
  int window = 256;              // Welch window, samples (256 or more keeps the peaks calibrated)
  double min_power_ratio = 8.0;  // a peak this far above the floor
  double min_velocity_share = 0.05;  // of the channel's residual variance
  // Sizes calibrated on the shipped scenarios' 16-seed sweeps: with the truth's own effects the
  // largest correlation was 0.21 and the largest reversal ratio 2.3; the Stribeck truth's
  // smallest reversal ratio was 19.
  double min_lag_correlation = 0.3;
  double max_lag_s = 0.1;
  // A joint "reverses" while its speed is below this; the residual's mean square there against
  // elsewhere (friction at low speed the model lacks: Stribeck's breakaway, stiction).
  double reversal_speed = 0.05;
  double min_reversal_ratio = 4.0;
};

struct MotionFinding {
  std::string kind;     // spectrum_peak, velocity_trend, command_lag, reversal
  std::string channel;  // "encoder link2_pitch_joint", "gyro imu2 y", ...
  double p_value = 1.0;
  double frequency_hz = 0.0;  // spectrum_peak
  double size = 0.0;          // peak amplitude, explained share, or correlation
  std::string text;           // one line for the log and the report
};

struct ChannelSpectrum {
  std::string channel;
  Spectrum spectrum;
};

struct ChannelLevel {
  std::string channel;
  double rms = 0.0;  // the residual's, in its stream's noise
};

struct MotionDiagnostics {
  std::vector<MotionFinding> findings;  // smallest p first
  std::vector<ChannelSpectrum> spectra;
  std::vector<ChannelLevel> levels;  // every channel, largest first
};

// Diagnoses `prediction` (a rollout of `problem`'s log) channel by channel.
MotionDiagnostics Diagnose(const DynamicProblem& problem, const Prediction& prediction,
                           const DiagnoseOptions& options = {});

}  // namespace flexbench::identify::dynamic
