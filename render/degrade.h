// Seeded image degradations of a rendered frame: occlusion, optical blur, exposure change and
// sensor noise, applied in that (physical) order. Every random draw comes from a caller-owned
// std::mt19937_64 (seeded from the scenario seed), and the Gaussian draws are made here from the
// engine's raw 64-bit output rather than through std::normal_distribution, whose algorithm the
// standard leaves to the library: the same seed gives the same bytes with any C++ library.
#pragma once

#include <random>
#include <string>

#include "render/image.h"

namespace flexbench::render {

struct Degradation {
  // Additive white Gaussian noise, standard deviation in gray levels (0..255), per channel,
  // added after exposure and before rounding to 8 bits (the sensor's read noise).
  double noise_std = 0.0;
  // Gaussian blur (defocus / motion), sigma in pixels; 0 is off.
  double blur_sigma_px = 0.0;
  // Exposure: out = gain * in + offset (gray levels), clipped to [0, 255].
  double gain = 1.0;
  double offset = 0.0;
  // With this probability per frame, one opaque rectangle (a uniformly random gray level)
  // covers part of the frame: a square of side occlusion_size_px centred at a uniformly random
  // point of the region of interest (the whole frame unless the caller gives one).
  double occlusion_probability = 0.0;
  double occlusion_size_px = 0.0;
};

// An axis-aligned pixel rectangle [x0, x1) x [y0, y1).
struct PixelRect {
  int x0 = 0;
  int y0 = 0;
  int x1 = 0;
  int y1 = 0;
};

// What ApplyDegradation did to one frame (for logs and CSVs).
struct DegradationReport {
  bool occluded = false;
  PixelRect occluder;
};

// Throws InputError naming `key` (e.g. "degradation.noise_std") for a negative noise or blur,
// a non-positive gain, a probability outside [0, 1] or a negative occluder size.
void ValidateDegradation(const Degradation& deg, const std::string& key = "degradation");

// Degrades `image` (gray or RGB) in place. `roi`, when given, is where an occluder may be
// centred (e.g. the bounding box of the tags in view). The draws from `rng` never depend on
// pixel values, so a frame's content does not change the noise of later frames.
DegradationReport ApplyDegradation(const Degradation& deg, std::mt19937_64& rng, Image* image,
                                   const PixelRect* roi = nullptr);

// Standard deviation of the noise in the BT.601 gray image (ToGray) when the noise was added
// independently to each channel of an RGB image: sigma * sqrt(0.299^2 + 0.587^2 + 0.114^2).
// For a gray image it is `noise_std` itself.
double GrayNoiseStd(const Degradation& deg, int channels);

// A uniform draw in [0, 1) with 53 random bits.
double Uniform01(std::mt19937_64& rng);

}  // namespace flexbench::render
