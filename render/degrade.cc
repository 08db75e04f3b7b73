#include "render/degrade.h"

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "estimators/error.h"

namespace flexbench::render {
namespace {

std::uint8_t ClampToByte(double v) {
  // Round half up after clipping (the clipped value is non-negative, so +0.5 and truncation
  // round; cheaper than lround in this per-pixel loop).
  return static_cast<std::uint8_t>(std::clamp(v, 0.0, 255.0) + 0.5);
}

}  // namespace

double Uniform01(std::mt19937_64& rng) {
  return static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0);  // 2^-53
}

void ValidateDegradation(const Degradation& deg, const std::string& key) {
  if (!(deg.noise_std >= 0.0)) throw InputError(key + ".noise_std: must be >= 0");
  if (!(deg.blur_sigma_px >= 0.0)) throw InputError(key + ".blur_sigma_px: must be >= 0");
  if (!(deg.gain > 0.0)) throw InputError(key + ".gain: must be > 0");
  if (!std::isfinite(deg.offset)) throw InputError(key + ".offset: must be finite");
  if (!(deg.occlusion_probability >= 0.0 && deg.occlusion_probability <= 1.0)) {
    throw InputError(key + ".occlusion_probability: must be in [0, 1]");
  }
  if (!(deg.occlusion_size_px >= 0.0)) throw InputError(key + ".occlusion_size_px: must be >= 0");
}

double GrayNoiseStd(const Degradation& deg, int channels) {
  if (channels == 1) return deg.noise_std;
  return deg.noise_std * std::sqrt(0.299 * 0.299 + 0.587 * 0.587 + 0.114 * 0.114);
}

DegradationReport ApplyDegradation(const Degradation& deg, std::mt19937_64& rng, Image* image,
                                   const PixelRect* roi) {
  DegradationReport report;
  const int w = image->width;
  const int h = image->height;
  const int ch = image->channels;

  // 1. Occlusion: something in the scene in front of the tag. Three draws always, whether or
  // not the frame is occluded, so later frames see the same stream either way.
  {
    const double draw = Uniform01(rng);
    const double ux = Uniform01(rng);
    const double uy = Uniform01(rng);
    const double gray = Uniform01(rng);
    if (draw < deg.occlusion_probability && deg.occlusion_size_px > 0.0) {
      const PixelRect area = roi ? *roi : PixelRect{0, 0, w, h};
      const double cx = area.x0 + ux * std::max(0, area.x1 - area.x0);
      const double cy = area.y0 + uy * std::max(0, area.y1 - area.y0);
      const double half = 0.5 * deg.occlusion_size_px;
      PixelRect r{static_cast<int>(std::floor(cx - half)), static_cast<int>(std::floor(cy - half)),
                  static_cast<int>(std::ceil(cx + half)), static_cast<int>(std::ceil(cy + half))};
      r.x0 = std::clamp(r.x0, 0, w);
      r.x1 = std::clamp(r.x1, 0, w);
      r.y0 = std::clamp(r.y0, 0, h);
      r.y1 = std::clamp(r.y1, 0, h);
      const std::uint8_t value = ClampToByte(255.0 * gray);
      for (int y = r.y0; y < r.y1; ++y) {
        std::fill(image->Row(y) + r.x0 * ch, image->Row(y) + r.x1 * ch, value);
      }
      report.occluded = r.x1 > r.x0 && r.y1 > r.y0;
      report.occluder = r;
    }
  }

  // 2. Blur: optics act on the irradiance before the sensor adds noise.
  if (deg.blur_sigma_px > 0.0) {
    cv::Mat m(h, w, ch == 1 ? CV_8UC1 : CV_8UC3, image->data.data());
    cv::Mat blurred;
    cv::GaussianBlur(m, blurred, cv::Size(0, 0), deg.blur_sigma_px, deg.blur_sigma_px,
                     cv::BORDER_REFLECT_101);
    blurred.copyTo(m);
  }

  // 3. Exposure and 4. sensor noise, in one pass and one rounding to 8 bits. Marsaglia's polar
  // method gives two independent normals per accepted pair of uniforms, without trigonometry
  // (about a third cheaper than Box-Muller here); both are used.
  const bool exposure = deg.gain != 1.0 || deg.offset != 0.0;
  if (!exposure && deg.noise_std == 0.0) return report;
  const size_t n = image->data.size();
  std::uint8_t* px = image->data.data();
  for (size_t i = 0; i < n; i += 2) {
    double z0 = 0.0;
    double z1 = 0.0;
    if (deg.noise_std > 0.0) {
      double u = 0.0;
      double v = 0.0;
      double s2 = 0.0;
      do {
        u = 2.0 * Uniform01(rng) - 1.0;
        v = 2.0 * Uniform01(rng) - 1.0;
        s2 = u * u + v * v;
      } while (s2 >= 1.0 || s2 == 0.0);
      const double f = deg.noise_std * std::sqrt(-2.0 * std::log(s2) / s2);
      z0 = u * f;
      z1 = v * f;
    }
    px[i] = ClampToByte(deg.gain * px[i] + deg.offset + z0);
    if (i + 1 < n) px[i + 1] = ClampToByte(deg.gain * px[i + 1] + deg.offset + z1);
  }
  return report;
}

}  // namespace flexbench::render
