// The `render:` and `detector:` blocks every rendering scenario shares.
//
//   render: {mode: fast}                 # quality (default) or fast
//   detector: {family: tag36h11, decimate: 1.0, sigma: 0.0, threads: 1, min_edge_px: 0,
//              max_view_angle_deg: 90, border_margin_px: 0}
#pragma once

#include "render/renderer.h"
#include "render/tag_detector.h"
#include "sim/config.h"

namespace flexbench::scenarios {

// `fallback` when the file has no render block.
render::RenderMode ParseRenderMode(const ConfigNode& root, render::RenderMode fallback);

// DetectorSettings' defaults for every key the file leaves out.
render::DetectorSettings ParseDetectorSettings(const ConfigNode& root);

}  // namespace flexbench::scenarios
