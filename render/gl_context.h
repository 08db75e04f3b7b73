// A headless OpenGL context through OSMesa (Mesa's software rasteriser: no display, no GPU).
// It must be current before mjr_makeContext, which loads GL entry points from it.
#pragma once

#include <string>

namespace flexbench::render {

// Makes the process-wide OSMesa context current on the calling thread, creating it on first
// use. Throws std::runtime_error when OSMesa cannot create a context. Returns GL_RENDERER
// (e.g. "llvmpipe (LLVM 15.0.6, 256 bits)").
const std::string& EnsureGlContext();

}  // namespace flexbench::render
