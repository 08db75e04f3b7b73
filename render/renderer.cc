#include "render/renderer.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "estimators/error.h"
#include "render/gl_context.h"
#include "sim/mujoco_model.h"

namespace flexbench::render {

RenderMode ParseRenderMode(const std::string& text, const std::string& key) {
  if (text == "quality") return RenderMode::kQuality;
  if (text == "fast") return RenderMode::kFast;
  throw InputError(key + ": unknown render mode '" + text + "' (expected quality or fast)");
}

struct Renderer::Impl {
  mjvScene scene;
  mjvCamera camera;
  mjvOption option;
  mjrContext context;
  std::vector<unsigned char> rgb_flipped;
};

Renderer::Renderer(const mjModel* m, RenderMode mode)
    : impl_(std::make_unique<Impl>()),
      model_(m),
      width_(m->vis.global.offwidth),
      height_(m->vis.global.offheight) {
  // Sizes OSMesa cannot allocate end in mju_error or an OSMesa failure: the model's (bad
  // input), said before any GL call. LoadModel checked already; a model made otherwise has not.
  sim::CheckRenderSizes(m, "model");
  gl_renderer_ = EnsureGlContext();
  mjv_defaultScene(&impl_->scene);
  mjv_defaultCamera(&impl_->camera);
  mjv_defaultOption(&impl_->option);
  mjr_defaultContext(&impl_->context);
  // A MuJoCo error below throws (sim::InstallMujocoHandlers) and the destructor will not run:
  // free what was made so far.
  try {
    mjv_makeScene(m, &impl_->scene, 2000);
    // Multisampling is a property of the offscreen buffer, fixed at context creation; MuJoCo
    // reads it from the model, so set it for the call and restore it.
    mjModel* mutable_model = const_cast<mjModel*>(m);
    const int samples = m->vis.quality.offsamples;
    if (mode == RenderMode::kFast) mutable_model->vis.quality.offsamples = 0;
    try {
      mjr_makeContext(m, &impl_->context, mjFONTSCALE_100);
    } catch (...) {
      mutable_model->vis.quality.offsamples = samples;
      throw;
    }
    mutable_model->vis.quality.offsamples = samples;
    mjr_setBuffer(mjFB_OFFSCREEN, &impl_->context);
    if (impl_->context.currentBuffer != mjFB_OFFSCREEN) {
      throw std::runtime_error("OSMesa: offscreen framebuffer not available");
    }
    if (impl_->context.offWidth < width_ || impl_->context.offHeight < height_) {
      throw std::runtime_error("offscreen buffer smaller than the model's offwidth/offheight");
    }
  } catch (...) {
    mjr_freeContext(&impl_->context);
    mjv_freeScene(&impl_->scene);
    // The failed call's GL errors would be reported against the next context made.
    for (int i = 0; i < 16 && mjr_getError() != 0; ++i) {
    }
    throw;
  }
  impl_->scene.flags[mjRND_SHADOW] = mode == RenderMode::kQuality ? 1 : 0;
  impl_->camera.type = mjCAMERA_FIXED;
  impl_->rgb_flipped.resize(static_cast<size_t>(width_) * height_ * 3);
}

Renderer::~Renderer() {
  mjr_freeContext(&impl_->context);
  mjv_freeScene(&impl_->scene);
}

void Renderer::Draw(mjData* d, int cam_id) {
  EnsureGlContext();
  mjr_setBuffer(mjFB_OFFSCREEN, &impl_->context);
  impl_->camera.fixedcamid = cam_id;
  const mjrRect viewport{0, 0, width_, height_};
  mjv_updateScene(model_, d, &impl_->option, nullptr, &impl_->camera, mjCAT_ALL, &impl_->scene);
  mjr_render(viewport, &impl_->scene, &impl_->context);
  mjr_readPixels(impl_->rgb_flipped.data(), nullptr, viewport, &impl_->context);
}

// A frame of one colour is what the model and the camera make of it (a camera that sees
// nothing, a model flung out of view by a diverging simulation), so it is the input's fault:
// one line naming the camera and whether the state is finite. A GL context that draws nothing
// at all fails at the first frame of every scenario, with its renderer named.
void Renderer::ThrowConstantFrame(const mjData* d, int cam_id) const {
  bool finite = true;
  for (int i = 0; i < 3 * model_->nbody && finite; ++i) finite = std::isfinite(d->xpos[i]);
  const char* name = mj_id2name(model_, mjOBJ_CAMERA, cam_id);
  throw InputError(std::string("camera '") + (name ? name : std::to_string(cam_id).c_str()) +
                   "' sees nothing: its rendered frame is one colour (" +
                   (finite ? "the camera may point away from the model"
                           : "the model's body positions are not finite: a diverging simulation") +
                   "; GL renderer: " + gl_renderer_ + ")");
}

Image Renderer::RenderRgb(mjData* d, int cam_id) {
  Image image;
  RenderRgbInto(d, cam_id, &image);
  return image;
}

void Renderer::RenderRgbInto(mjData* d, int cam_id, Image* image) {
  Draw(d, cam_id);
  image->width = width_;
  image->height = height_;
  image->channels = 3;
  image->data.resize(impl_->rgb_flipped.size());
  // OpenGL's first row is the bottom of the picture.
  const size_t row = static_cast<size_t>(width_) * 3;
  for (int r = 0; r < height_; ++r) {
    std::copy_n(impl_->rgb_flipped.data() + (height_ - 1 - r) * row, row, image->Row(r));
  }
  if (IsConstant(*image)) ThrowConstantFrame(d, cam_id);
}

void Renderer::RenderGrayInto(mjData* d, int cam_id, Image* gray) {
  Draw(d, cam_id);
  // Flip and convert in one pass with ToGray's conversion (OpenCV's fixed-point BT.601), so
  // the result equals ToGray(RenderRgb(...)) byte for byte.
  Image bottom_up{width_, height_, 3, {}};
  bottom_up.data.swap(impl_->rgb_flipped);  // borrow the readback buffer, no copy
  const Image g = ToGray(bottom_up);
  bottom_up.data.swap(impl_->rgb_flipped);
  gray->width = width_;
  gray->height = height_;
  gray->channels = 1;
  gray->data.resize(static_cast<size_t>(width_) * height_);
  for (int r = 0; r < height_; ++r) {
    std::copy_n(g.Row(height_ - 1 - r), width_, gray->Row(r));
  }
  if (IsConstant(*gray)) ThrowConstantFrame(d, cam_id);
}

}  // namespace flexbench::render
