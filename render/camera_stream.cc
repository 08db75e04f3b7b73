#include "render/camera_stream.h"

#include <cmath>

#include "estimators/error.h"

namespace flexbench::render {
namespace {
constexpr double kTimeTolerance = 1e-9;
}  // namespace

FrameClock::FrameClock(double rate_hz, double start_s) : rate_hz_(rate_hz), start_s_(start_s) {
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) {
    throw InputError("camera rate: must be a positive number of frames per second");
  }
  if (!std::isfinite(start_s)) throw InputError("camera start time: must be finite");
}

bool FrameClock::Due(double t_s) const { return t_s >= next_time_s() - kTimeTolerance; }

FrameStamp FrameClock::Take(double t_s) {
  // The latest slot not after t: the frame a camera triggered at `rate` would deliver now.
  std::int64_t k = next_index_;
  const std::int64_t latest =
      static_cast<std::int64_t>(std::floor((t_s - start_s_ + kTimeTolerance) * rate_hz_));
  if (latest > k) {
    skipped_ += latest - k;
    k = latest;
  }
  FrameStamp stamp;
  stamp.index = k;
  stamp.nominal_time_s = SlotTime(k);
  stamp.time_s = t_s;
  next_index_ = k + 1;
  return stamp;
}

CameraStream::CameraStream(Renderer* renderer, int cam_id, double rate_hz,
                           const Degradation& degradation, std::uint64_t seed)
    : renderer_(renderer), cam_id_(cam_id), clock_(rate_hz), degradation_(degradation), rng_(seed) {
  ValidateDegradation(degradation_);
}

CameraFrame CameraStream::Capture(mjData* d, double t_s, const PixelRect* roi) {
  CameraFrame frame;
  frame.stamp = clock_.Take(t_s);
  frame.rgb = renderer_->RenderRgb(d, cam_id_);
  frame.degradation = ApplyDegradation(degradation_, rng_, &frame.rgb, roi);
  frame.gray = ToGray(frame.rgb);
  frame.gray_noise_std = GrayNoiseStd(degradation_, 3);
  return frame;
}

std::optional<CameraFrame> CameraStream::Poll(mjData* d, double t_s, const PixelRect* roi) {
  if (!clock_.Due(t_s)) return std::nullopt;
  return Capture(d, t_s, roi);
}

}  // namespace flexbench::render
