// A small deterministic PNG plotter (OpenCV drawing): figures with one or more axes, line and
// scatter series with optional error bars, reference lines, ticks, labels, legends. The same
// data gives the same bytes. Non-finite points are skipped (they break a line).
//
//   render::Figure fig(900, 600);
//   render::Axes& ax = fig.axes();
//   ax.title = "End-effector deflection";
//   ax.x_label = "reach [m]";
//   ax.y_label = "deflection [cm]";
//   ax.AddLine("forward", reach, defl_cm).marker = render::Marker::kCircle;
//   ax.AddHLine(3.0, "gate");
//   fig.SavePng("deflection.png");
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "render/image.h"

namespace flexbench::render {

struct Rgb {
  std::uint8_t r = 0;
  std::uint8_t g = 0;
  std::uint8_t b = 0;
};

// Ten distinguishable colours (matplotlib's tab10), cycled.
Rgb PaletteColor(int index);

enum class Marker { kNone, kCircle, kSquare, kTriangle, kDiamond, kCross };
enum class LineStyle { kNone, kSolid, kDashed };
enum class LegendPosition { kTopLeft, kTopRight, kBottomLeft, kBottomRight };

struct Series {
  std::string label;  // empty: not in the legend
  std::vector<double> x;
  std::vector<double> y;
  std::vector<double> y_err;  // symmetric error bars; empty: none
  Rgb color;
  LineStyle line = LineStyle::kSolid;
  Marker marker = Marker::kNone;
  int line_width = 2;
  int marker_size = 4;  // radius in pixels
  // > 0: each point is a bar from 0 to y this wide (x units), filled with a light tint of
  // `color` (no line is drawn between points; error bars still are).
  double bar_width = 0.0;
  // Text drawn just above each point or bar (its value, say); empty, or "" for a point: none.
  std::vector<std::string> point_labels;
};

// A horizontal (or vertical) reference line across the axes, e.g. a gate threshold.
struct RefLine {
  double value = 0.0;
  bool vertical = false;
  std::string label;
  Rgb color{120, 120, 120};
  LineStyle line = LineStyle::kDashed;
};

struct Axes {
  std::string title;
  std::string x_label;
  std::string y_label;
  // Fixed limits; unset: from the data (and reference lines), padded and snapped to ticks.
  std::optional<double> x_min, x_max, y_min, y_max;
  std::vector<Series> series;
  std::vector<RefLine> ref_lines;
  // y on a log10 scale: ticks at powers of ten (with 2 and 5 between over few decades), values
  // <= 0 below the axes, bars rising from the bottom edge. Small values beside large ones stay
  // visible.
  bool y_log = false;
  // Names for the x ticks at 0, 1, 2 ... (categories such as estimators); other ticks unlabelled.
  std::vector<std::string> x_tick_labels;
  bool grid = true;
  bool legend = true;
  LegendPosition legend_position = LegendPosition::kTopLeft;

  // Adds a series with the next palette colour.
  Series& AddLine(const std::string& label, std::vector<double> x, std::vector<double> y);
  Series& AddScatter(const std::string& label, std::vector<double> x, std::vector<double> y);
  Series& AddBars(const std::string& label, std::vector<double> x, std::vector<double> y,
                  double width = 0.6);
  RefLine& AddHLine(double y, const std::string& label = "");
  RefLine& AddVLine(double x, const std::string& label = "");
};

class Figure {
 public:
  // A figure of width x height pixels holding a rows x cols grid of axes.
  Figure(int width_px, int height_px, int rows = 1, int cols = 1);

  Axes& axes(int row = 0, int col = 0);
  const Axes& axes(int row = 0, int col = 0) const;
  std::string title;  // across the top, optional

  // RGB image of the figure.
  Image Render() const;
  // Render() written as PNG; throws InputError naming the path when it cannot be written.
  void SavePng(const std::string& path) const;

 private:
  int width_;
  int height_;
  int rows_;
  int cols_;
  std::vector<Axes> axes_;
};

// A table of coloured cells (a heat map): colour from each value on a log or linear scale
// (viridis), a text per cell, and a thick red outline on marked cells.
struct Heatmap {
  std::string title;
  std::vector<std::string> row_labels;
  std::vector<std::string> col_labels;
  std::vector<std::vector<double>> value;      // rows x cols; non-finite: grey
  std::vector<std::vector<std::string>> text;  // optional, rows x cols
  std::vector<std::vector<char>> marked;       // optional, rows x cols
  bool log_scale = true;
  std::string note;  // one line under the table
};

// Heat maps side by side in one PNG of width x height pixels. Throws InputError naming the
// path when it cannot be written, or when a panel's tables do not match its labels.
void SaveHeatmapsPng(const std::vector<Heatmap>& panels, int width_px, int height_px,
                     const std::string& path);

// "Nice" tick values covering [lo, hi] (steps of 1, 2 or 5 times a power of ten), about
// `target` of them.
std::vector<double> NiceTicks(double lo, double hi, int target = 6);

}  // namespace flexbench::render
