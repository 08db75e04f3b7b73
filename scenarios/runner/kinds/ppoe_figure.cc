#include "scenarios/runner/kinds/ppoe_figure.h"

#include <algorithm>

#include "render/plot.h"

namespace flexbench::scenarios {

void DrawPpoeFigure(const PpoeFigure& figure, const std::string& png_path) {
  render::Figure fig(700, 700);
  render::Axes& ax = fig.axes();
  ax.title = "PPOE 80% region (blue) and Monte-Carlo samples (green), " + figure.title;
  ax.x_label = "x [m]";
  ax.y_label = "y [m]";
  ax.legend_position = render::LegendPosition::kBottomLeft;
  const auto xs = [](const std::vector<Vec3>& p) {
    std::vector<double> v;
    for (const Vec3& q : p) v.push_back(q.x());
    return v;
  };
  const auto ys = [](const std::vector<Vec3>& p) {
    std::vector<double> v;
    for (const Vec3& q : p) v.push_back(q.y());
    return v;
  };
  render::Series& region =
      ax.AddScatter("PPOE 80% boundary", xs(figure.boundary), ys(figure.boundary));
  region.color = {40, 90, 220};
  region.marker = render::Marker::kCircle;
  region.marker_size = 1;
  render::Series& samples = ax.AddScatter("Monte Carlo", xs(figure.samples), ys(figure.samples));
  samples.color = {30, 170, 60};
  samples.marker = render::Marker::kCircle;
  samples.marker_size = 2;
  render::Series& arm = ax.AddLine("arm", xs(figure.arm), ys(figure.arm));
  arm.color = {40, 40, 40};
  arm.marker = render::Marker::kCircle;
  arm.marker_size = 5;
  arm.line_width = 3;
  // Equal scales on both axes, so the banana keeps its shape.
  double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
  for (const auto* set : {&figure.arm, &figure.samples, &figure.boundary}) {
    for (const Vec3& p : *set) {
      x0 = std::min(x0, p.x());
      x1 = std::max(x1, p.x());
      y0 = std::min(y0, p.y());
      y1 = std::max(y1, p.y());
    }
  }
  const double half = 0.55 * std::max(x1 - x0, y1 - y0);
  const double cx = 0.5 * (x0 + x1), cy = 0.5 * (y0 + y1);
  ax.x_min = cx - half;
  ax.x_max = cx + half;
  ax.y_min = cy - half;
  ax.y_max = cy + half;
  fig.SavePng(png_path);
}

}  // namespace flexbench::scenarios
