// Offscreen rendering of MuJoCo scenes from MJCF cameras through OSMesa.
#pragma once

#include <mujoco/mujoco.h>

#include <memory>
#include <string>

#include "render/image.h"

namespace flexbench::render {

// quality: MuJoCo's defaults (multisampling, shadows). fast: no multisampling, no shadows;
// several times faster on the software rasteriser.
enum class RenderMode { kQuality, kFast };

// Parses "quality" / "fast"; throws InputError naming `key` otherwise.
RenderMode ParseRenderMode(const std::string& text, const std::string& key);

// Renders one model. The model must outlive the renderer, and its textures (ApplyTagTextures) are
// final when it is constructed. Frame size is the model's offwidth/offheight.
class Renderer {
 public:
  Renderer(const mjModel* m, RenderMode mode);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Renders camera `cam_id` for the state in `d` (positions must be current: mj_forward or
  // mj_kinematics). Returns RGB, top row first. Throws InputError when the frame is constant
  // (the camera sees nothing, or the model's state is not finite), naming the camera.
  Image RenderRgb(mjData* d, int cam_id);
  // The same into a caller-owned image whose buffer is reused from frame to frame.
  void RenderRgbInto(mjData* d, int cam_id, Image* rgb);
  // Grayscale (BT.601, as ToGray) straight from the readback: one pass, no RGB copy.
  void RenderGrayInto(mjData* d, int cam_id, Image* gray);

  int width() const { return width_; }
  int height() const { return height_; }
  // GL_RENDERER of the context, for the run's log.
  const std::string& gl_renderer() const { return gl_renderer_; }

 private:
  // Renders and reads the frame back (bottom row first) into the readback buffer.
  void Draw(mjData* d, int cam_id);

  struct Impl;
  std::unique_ptr<Impl> impl_;
  [[noreturn]] void ThrowConstantFrame(const mjData* d, int cam_id) const;
  const mjModel* model_;
  int width_;
  int height_;
  std::string gl_renderer_;
};

}  // namespace flexbench::render
