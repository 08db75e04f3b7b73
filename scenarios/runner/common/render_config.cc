#include "scenarios/runner/common/render_config.h"

namespace flexbench::scenarios {

render::RenderMode ParseRenderMode(const ConfigNode& root, render::RenderMode fallback) {
  const auto r = root.Optional("render");
  if (!r) return fallback;
  const ConfigNode mode = r->Child("mode");
  return render::ParseRenderMode(mode.AsString(), mode.WhereKey());
}

render::DetectorSettings ParseDetectorSettings(const ConfigNode& root) {
  render::DetectorSettings s;
  const auto d = root.Optional("detector");
  if (!d) return s;
  s.family = d->GetString("family", s.family);
  s.decimate = d->GetDouble("decimate", s.decimate);
  s.sigma = d->GetDouble("sigma", s.sigma);
  s.threads = d->GetInt("threads", s.threads);
  s.min_edge_px = d->GetDouble("min_edge_px", s.min_edge_px);
  s.max_view_angle_deg = d->GetDouble("max_view_angle_deg", s.max_view_angle_deg);
  s.border_margin_px = d->GetDouble("border_margin_px", s.border_margin_px);
  // Checked here, where the file's line or the --set is known: the detector names only the key.
  try {
    render::ValidateDetectorSettings(s);
  } catch (const InputError& e) {
    const std::string m = e.what();
    const std::string prefix = "detector.";
    const size_t colon = m.find(": ");
    if (m.compare(0, prefix.size(), prefix) == 0 && colon != std::string::npos) {
      const std::string key = m.substr(prefix.size(), colon - prefix.size());
      if (d->Has(key)) d->Child(key).Fail(m.substr(colon + 2));
    }
    d->Fail(m);
  }
  return s;
}

}  // namespace flexbench::scenarios
