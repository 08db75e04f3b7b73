#include "render/gl_context.h"

#include <GL/osmesa.h>

#include <memory>
#include <mutex>
#include <stdexcept>
#include <vector>

namespace flexbench::render {
namespace {

struct OsMesaState {
  OSMesaContext context = nullptr;
  // The default framebuffer is never read (MuJoCo renders into its own offscreen FBO), but
  // OSMesa needs one to make the context current.
  std::vector<unsigned char> buffer;
  std::string renderer;
  ~OsMesaState() {
    if (context) OSMesaDestroyContext(context);
  }
};

}  // namespace

const std::string& EnsureGlContext() {
  static std::mutex mutex;
  static std::unique_ptr<OsMesaState> state;
  std::lock_guard<std::mutex> lock(mutex);
  if (!state) {
    auto s = std::make_unique<OsMesaState>();
    s->context = OSMesaCreateContextExt(OSMESA_RGBA, 24, 8, 0, nullptr);
    if (!s->context) throw std::runtime_error("OSMesa: cannot create an offscreen GL context");
    constexpr int kSize = 64;
    s->buffer.resize(kSize * kSize * 4);
    if (!OSMesaMakeCurrent(s->context, s->buffer.data(), GL_UNSIGNED_BYTE, kSize, kSize)) {
      throw std::runtime_error("OSMesa: cannot make the offscreen GL context current");
    }
    const GLubyte* name = glGetString(GL_RENDERER);
    s->renderer = name ? reinterpret_cast<const char*>(name) : "unknown";
    state = std::move(s);
  } else if (OSMesaGetCurrentContext() != state->context) {
    OSMesaMakeCurrent(state->context, state->buffer.data(), GL_UNSIGNED_BYTE, 64, 64);
  }
  return state->renderer;
}

}  // namespace flexbench::render
