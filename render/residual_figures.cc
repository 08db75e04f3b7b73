#include "render/residual_figures.h"

#include "render/plot.h"

namespace flexbench::render {
namespace {

Axes& Prepare(Figure* fig, const FigureText& text) {
  fig->title = text.title;
  Axes& ax = fig->axes();
  ax.x_label = text.x_label;
  ax.y_label = text.y_label;
  ax.legend_position = LegendPosition::kTopRight;
  return ax;
}

}  // namespace

void SaveRowsAndCurve(const std::string& path, const FigureText& text, const std::vector<double>& x,
                      const std::vector<double>& z, const std::vector<double>& cx,
                      const std::vector<double>& cz) {
  Figure fig(900, 560);
  Axes& ax = Prepare(&fig, text);
  ax.AddScatter("rows", x, z).marker = Marker::kCircle;
  ax.AddLine("fitted", cx, cz);
  fig.SavePng(path);
}

void SaveBeforeAfter(const std::string& path, const FigureText& text, const std::vector<double>& x,
                     const std::vector<double>& before, const std::vector<double>& after) {
  Figure fig(900, 560);
  Axes& ax = Prepare(&fig, text);
  ax.AddScatter("declared model", x, before).marker = Marker::kCircle;
  ax.AddScatter("with identified effects", x, after).marker = Marker::kSquare;
  ax.y_min = 0.0;
  fig.SavePng(path);
}

}  // namespace flexbench::render
