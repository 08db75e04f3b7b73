// Camera frames at a fixed rate inside a simulation.
//
// FrameClock only does the timing: given the simulation time it says whether a frame is due
// and stamps it. Frame k is due at start + k / rate (computed from k, so no rounding drift
// accumulates over long runs); a simulation step that jumps over several frame times yields
// one frame, stamped with the latest due slot, and the skipped ones are counted.
//
// CameraStream adds the rendering: one MJCF camera of a Renderer, RGB and gray frames, and the
// seeded degradations of render/degrade.h with the stream's own random stream.
#pragma once

#include <mujoco/mujoco.h>

#include <cstdint>
#include <optional>
#include <random>

#include "render/degrade.h"
#include "render/image.h"
#include "render/renderer.h"

namespace flexbench::render {

struct FrameStamp {
  std::int64_t index = 0;       // frame number, 0, 1, 2, ... (skipped slots included)
  double nominal_time_s = 0.0;  // start + index / rate
  double time_s = 0.0;          // simulation time at which the frame was taken
};

class FrameClock {
 public:
  // Throws InputError for a rate that is not positive and finite.
  explicit FrameClock(double rate_hz, double start_s = 0.0);

  // True when the next frame's time has come (within a tolerance of 1e-9 s, so a step that
  // lands on the frame time up to rounding counts).
  bool Due(double t_s) const;
  // Takes the frame due at `t_s` (call only when Due(t_s)).
  FrameStamp Take(double t_s);

  double rate_hz() const { return rate_hz_; }
  double next_time_s() const { return SlotTime(next_index_); }
  std::int64_t skipped() const { return skipped_; }

 private:
  double SlotTime(std::int64_t k) const { return start_s_ + static_cast<double>(k) / rate_hz_; }

  double rate_hz_;
  double start_s_;
  std::int64_t next_index_ = 0;
  std::int64_t skipped_ = 0;
};

struct CameraFrame {
  FrameStamp stamp;
  Image rgb;
  Image gray;
  DegradationReport degradation;
  // Pixel-noise standard deviation of `gray` (gray levels), for TagDetector's covariance.
  double gray_noise_std = 0.0;
};

class CameraStream {
 public:
  // `renderer` must outlive the stream. `seed` seeds the degradation stream (derive it from the
  // scenario seed).
  CameraStream(Renderer* renderer, int cam_id, double rate_hz, const Degradation& degradation,
               std::uint64_t seed);

  bool Due(double t_s) const { return clock_.Due(t_s); }
  // Renders the camera for the state in `d` (positions current), degrades, stamps. `roi` is
  // where an occluder may fall (see ApplyDegradation).
  CameraFrame Capture(mjData* d, double t_s, const PixelRect* roi = nullptr);
  // Capture when a frame is due, nothing otherwise.
  std::optional<CameraFrame> Poll(mjData* d, double t_s, const PixelRect* roi = nullptr);

  const FrameClock& clock() const { return clock_; }
  int cam_id() const { return cam_id_; }

 private:
  Renderer* renderer_;
  int cam_id_;
  FrameClock clock_;
  Degradation degradation_;
  std::mt19937_64 rng_;
};

}  // namespace flexbench::render
