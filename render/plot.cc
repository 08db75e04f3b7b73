#include "render/plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "estimators/error.h"

namespace flexbench::render {
namespace {

constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;
constexpr double kTickFont = 0.42;
constexpr double kLabelFont = 0.5;
constexpr double kTitleFont = 0.6;
const cv::Scalar kBlack(0, 0, 0);
const cv::Scalar kAxisGray(90, 90, 90);
const cv::Scalar kGridGray(228, 228, 228);
const cv::Scalar kWhite(255, 255, 255);

// The Mat holds RGB (not OpenCV's usual BGR): colours are given in RGB order.
cv::Scalar ToScalar(const Rgb& c) { return cv::Scalar(c.r, c.g, c.b); }
// A bar's fill: the series colour 60% of the way to white, so error bars and outlines show.
cv::Scalar Tint(const Rgb& c) {
  return cv::Scalar(c.r + 0.6 * (255 - c.r), c.g + 0.6 * (255 - c.g), c.b + 0.6 * (255 - c.b));
}

double NiceStep(double raw) {
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / p;
  const double nice = f <= 1.0 ? 1.0 : f <= 2.0 ? 2.0 : f <= 5.0 ? 5.0 : 10.0;
  return nice * p;
}

std::string TickLabel(double v, double step) {
  int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
  if (decimals > 6) decimals = 6;
  if (std::abs(v) < step * 1e-6) v = 0.0;  // no "-0"
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", decimals, v);
  return buf;
}

// A value as "%g" prints it: a log axis' ticks (0.01, 2e-05, 100).
std::string ValueLabel(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

cv::Size TextSize(const std::string& text, double scale, int thickness = 1) {
  int baseline = 0;
  return cv::getTextSize(text, kFont, scale, thickness, &baseline);
}

void PutText(cv::Mat& img, const std::string& text, cv::Point org, double scale,
             const cv::Scalar& color = kBlack, int thickness = 1) {
  cv::putText(img, text, org, kFont, scale, color, thickness, cv::LINE_AA);
}

// Text rotated 90 degrees counter-clockwise, centred at `center`.
void PutTextVertical(cv::Mat& img, const std::string& text, cv::Point center, double scale) {
  if (text.empty()) return;
  int baseline = 0;
  const cv::Size s = cv::getTextSize(text, kFont, scale, 1, &baseline);
  cv::Mat patch(s.height + baseline + 4, s.width + 4, img.type(), kWhite);
  PutText(patch, text, cv::Point(2, s.height + 2), scale);
  cv::Mat rotated;
  cv::rotate(patch, rotated, cv::ROTATE_90_COUNTERCLOCKWISE);
  cv::Rect r(center.x - rotated.cols / 2, center.y - rotated.rows / 2, rotated.cols, rotated.rows);
  r &= cv::Rect(0, 0, img.cols, img.rows);
  if (r.width <= 0 || r.height <= 0) return;
  cv::Mat dst = img(r);
  cv::min(dst, rotated(cv::Rect(0, 0, r.width, r.height)), dst);
}

void DrawSegment(cv::Mat& img, cv::Point a, cv::Point b, const cv::Scalar& color, int width,
                 LineStyle style, const cv::Rect& clip) {
  if (style == LineStyle::kNone) return;
  cv::Point p = a, q = b;
  if (!cv::clipLine(clip, p, q)) return;
  if (style == LineStyle::kSolid) {
    cv::line(img, p, q, color, width, cv::LINE_AA);
    return;
  }
  const double len = std::hypot(q.x - p.x, q.y - p.y);
  const double dash = 8.0, gap = 5.0;
  for (double s = 0.0; s < len; s += dash + gap) {
    const double e = std::min(len, s + dash);
    const cv::Point u(static_cast<int>(std::lround(p.x + (q.x - p.x) * s / len)),
                      static_cast<int>(std::lround(p.y + (q.y - p.y) * s / len)));
    const cv::Point v(static_cast<int>(std::lround(p.x + (q.x - p.x) * e / len)),
                      static_cast<int>(std::lround(p.y + (q.y - p.y) * e / len)));
    cv::line(img, u, v, color, width, cv::LINE_AA);
  }
}

void DrawMarker(cv::Mat& img, cv::Point c, Marker marker, int r, const cv::Scalar& color) {
  switch (marker) {
    case Marker::kNone:
      return;
    case Marker::kCircle:
      cv::circle(img, c, r, color, cv::FILLED, cv::LINE_AA);
      return;
    case Marker::kSquare:
      cv::rectangle(img, cv::Point(c.x - r, c.y - r), cv::Point(c.x + r, c.y + r), color,
                    cv::FILLED, cv::LINE_AA);
      return;
    case Marker::kTriangle:
    case Marker::kDiamond: {
      std::vector<cv::Point> pts;
      if (marker == Marker::kTriangle) {
        pts = {{c.x, c.y - r - 1}, {c.x + r + 1, c.y + r}, {c.x - r - 1, c.y + r}};
      } else {
        pts = {{c.x, c.y - r - 1}, {c.x + r + 1, c.y}, {c.x, c.y + r + 1}, {c.x - r - 1, c.y}};
      }
      cv::fillConvexPoly(img, pts, color, cv::LINE_AA);
      return;
    }
    case Marker::kCross:
      cv::line(img, cv::Point(c.x - r, c.y - r), cv::Point(c.x + r, c.y + r), color, 2,
               cv::LINE_AA);
      cv::line(img, cv::Point(c.x - r, c.y + r), cv::Point(c.x + r, c.y - r), color, 2,
               cv::LINE_AA);
      return;
  }
}

struct Range {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void Add(double v) {
    if (!std::isfinite(v)) return;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
};

// Padded, tick-snapped limits and their ticks.
std::vector<double> ResolveLimits(Range r, std::optional<double> fixed_lo,
                                  std::optional<double> fixed_hi, double* lo, double* hi) {
  if (!(r.lo <= r.hi)) {
    r.lo = 0.0;
    r.hi = 1.0;
  }
  if (fixed_lo) r.lo = *fixed_lo;
  if (fixed_hi) r.hi = *fixed_hi;
  if (r.hi - r.lo <= 0.0) {
    const double d = std::abs(r.lo) > 0 ? 0.5 * std::abs(r.lo) : 0.5;
    if (!fixed_lo) r.lo -= d;
    if (!fixed_hi) r.hi += d;
    if (r.hi <= r.lo) r.hi = r.lo + 1.0;
  }
  const double pad = 0.04 * (r.hi - r.lo);
  double a = fixed_lo ? *fixed_lo : r.lo - pad;
  double b = fixed_hi ? *fixed_hi : r.hi + pad;
  const double step = NiceStep((b - a) / 6.0);
  if (!fixed_lo) a = std::floor(a / step + 1e-9) * step;
  if (!fixed_hi) b = std::ceil(b / step - 1e-9) * step;
  *lo = a;
  *hi = b;
  std::vector<double> ticks;
  const long k0 = static_cast<long>(std::ceil(a / step - 1e-9));
  const long k1 = static_cast<long>(std::floor(b / step + 1e-9));
  for (long k = k0; k <= k1; ++k) ticks.push_back(k * step);
  return ticks;
}

// Limits whole decades apart (in log10 units) and ticks at 1, (2, 5,) 10 ... in data units.
std::vector<double> ResolveLogLimits(Range r, std::optional<double> fixed_lo,
                                     std::optional<double> fixed_hi, double* lo, double* hi) {
  if (!(r.lo <= r.hi)) r.lo = 0.0, r.hi = 1.0;
  if (fixed_lo && *fixed_lo > 0) r.lo = std::log10(*fixed_lo);
  if (fixed_hi && *fixed_hi > 0) r.hi = std::log10(*fixed_hi);
  *lo = std::floor(r.lo + 1e-9);
  *hi = std::max(*lo + 1.0, std::ceil(r.hi - 1e-9));
  const bool fine = *hi - *lo <= 3.0;
  std::vector<double> ticks;
  for (long d = std::lround(*lo); d <= std::lround(*hi); ++d) {
    for (double m : {1.0, 2.0, 5.0}) {
      if ((m == 1.0 || fine) && d + std::log10(m) <= *hi + 1e-9)
        ticks.push_back(m * std::pow(10.0, d));
    }
  }
  return ticks;
}

// The plot area of one axes in its cell and the data-to-pixel map (y0, y1 in log10 units on a
// log axis).
struct PlotArea {
  cv::Rect area;
  double x0 = 0.0, x1 = 1.0, y0 = 0.0, y1 = 1.0;
  bool y_log = false;
  std::vector<double> xt, yt;  // ticks
  int px(double x) const {
    return static_cast<int>(std::lround(area.x + (x - x0) / (x1 - x0) * area.width));
  }
  int py(double y) const {
    // On a log axis a value <= 0 lies a decade below the axes (clipped there).
    if (y_log) y = y > 0.0 ? std::log10(y) : y0 - 1.0;
    return static_cast<int>(std::lround(area.y + area.height - (y - y0) / (y1 - y0) * area.height));
  }
  // Where bars start: zero, or the bottom edge of a log axis.
  double y_base() const { return y_log ? std::pow(10.0, y0) : 0.0; }
};

// Room for the title, tick labels and axis labels; limits from the data, bars, error bars and
// reference lines unless the axes fix them.
PlotArea Layout(const Axes& ax, const cv::Rect& cell) {
  const int left = cell.x + 74;
  const int right = cell.x + cell.width - 18;
  const int top = cell.y + (ax.title.empty() ? 14 : 36);
  const int bottom = cell.y + cell.height - (ax.x_label.empty() ? 30 : 52);
  PlotArea pa;
  pa.area = cv::Rect(left, top, std::max(10, right - left), std::max(10, bottom - top));
  pa.y_log = ax.y_log;
  Range xr, yr;
  // On a log axis only positive values set the range, in log10 units.
  const auto add_y = [&](double y) {
    if (!ax.y_log) yr.Add(y);
    if (ax.y_log && y > 0.0) yr.Add(std::log10(y));
  };
  for (const Series& s : ax.series) {
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      xr.Add(s.x[i]);
      if (s.bar_width > 0.0) {
        xr.Add(s.x[i] - 0.5 * s.bar_width);
        xr.Add(s.x[i] + 0.5 * s.bar_width);
        if (!ax.y_log) yr.Add(0.0);
      }
      const double e = i < s.y_err.size() && std::isfinite(s.y_err[i]) ? s.y_err[i] : 0.0;
      add_y(s.y[i] - e);
      add_y(s.y[i] + e);
    }
  }
  for (const RefLine& l : ax.ref_lines) {
    if (l.vertical) xr.Add(l.value);
    if (!l.vertical) add_y(l.value);
  }
  pa.xt = ResolveLimits(xr, ax.x_min, ax.x_max, &pa.x0, &pa.x1);
  pa.yt = ax.y_log ? ResolveLogLimits(yr, ax.y_min, ax.y_max, &pa.y0, &pa.y1)
                   : ResolveLimits(yr, ax.y_min, ax.y_max, &pa.y0, &pa.y1);
  return pa;
}

void DrawGrid(cv::Mat& img, const Axes& ax, const PlotArea& pa) {
  const cv::Rect& area = pa.area;
  const double xstep = pa.xt.size() > 1 ? pa.xt[1] - pa.xt[0] : 1.0;
  const double ystep = pa.yt.size() > 1 ? pa.yt[1] - pa.yt[0] : 1.0;
  for (double t : pa.xt) {
    const int x = pa.px(t);
    if (ax.grid) cv::line(img, {x, area.y}, {x, area.y + area.height}, kGridGray, 1);
    cv::line(img, {x, area.y + area.height}, {x, area.y + area.height + 5}, kAxisGray, 1);
    const long k = std::lround(t);
    const bool named = !ax.x_tick_labels.empty();
    const std::string label =
        !named ? TickLabel(t, xstep)
        : std::abs(t - k) < 1e-9 && k >= 0 && k < static_cast<long>(ax.x_tick_labels.size())
            ? ax.x_tick_labels[k]
            : "";
    const cv::Size s = TextSize(label, kTickFont);
    PutText(img, label, {x - s.width / 2, area.y + area.height + 8 + s.height}, kTickFont);
  }
  for (double t : pa.yt) {
    const int y = pa.py(t);
    if (ax.grid) cv::line(img, {area.x, y}, {area.x + area.width, y}, kGridGray, 1);
    cv::line(img, {area.x - 5, y}, {area.x, y}, kAxisGray, 1);
    const std::string label = pa.y_log ? ValueLabel(t) : TickLabel(t, ystep);
    const cv::Size s = TextSize(label, kTickFont);
    PutText(img, label, {area.x - 8 - s.width, y + s.height / 2}, kTickFont);
  }
}

void DrawRefLines(cv::Mat& img, const Axes& ax, const PlotArea& pa) {
  const cv::Rect& area = pa.area;
  for (const RefLine& l : ax.ref_lines) {
    const cv::Scalar c = ToScalar(l.color);
    if (l.vertical) {
      const int x = pa.px(l.value);
      DrawSegment(img, {x, area.y}, {x, area.y + area.height}, c, 1, l.line, area);
      if (!l.label.empty()) PutText(img, l.label, {x + 4, area.y + 14}, kTickFont, c);
    } else {
      const int y = pa.py(l.value);
      DrawSegment(img, {area.x, y}, {area.x + area.width, y}, c, 1, l.line, area);
      if (!l.label.empty()) {
        const cv::Size s = TextSize(l.label, kTickFont);
        PutText(img, l.label, {area.x + area.width - s.width - 4, y - 4}, kTickFont, c);
      }
    }
  }
}

// Bars, error bars, lines, markers (non-finite points skipped).
void DrawSeries(cv::Mat& img, const Series& s, const PlotArea& pa) {
  const cv::Rect& area = pa.area;
  const cv::Scalar c = ToScalar(s.color);
  const size_t n = std::min(s.x.size(), s.y.size());
  const auto finite = [&](size_t i) { return std::isfinite(s.x[i]) && std::isfinite(s.y[i]); };
  for (size_t i = 0; s.bar_width > 0.0 && i < n; ++i) {
    if (!finite(i)) continue;
    const cv::Rect bar = cv::Rect(cv::Point(pa.px(s.x[i] - 0.5 * s.bar_width), pa.py(pa.y_base())),
                                  cv::Point(pa.px(s.x[i] + 0.5 * s.bar_width), pa.py(s.y[i]))) &
                         area;
    if (bar.area() == 0) continue;
    cv::rectangle(img, bar, Tint(s.color), cv::FILLED);
    cv::rectangle(img, bar, c, 1);
  }
  for (size_t i = 0; i < n && i < s.y_err.size(); ++i) {
    if (!finite(i) || !std::isfinite(s.y_err[i])) continue;
    const int x = pa.px(s.x[i]);
    const cv::Point a(x, pa.py(s.y[i] - s.y_err[i])), b(x, pa.py(s.y[i] + s.y_err[i]));
    DrawSegment(img, a, b, c, 1, LineStyle::kSolid, area);
    DrawSegment(img, {x - 3, a.y}, {x + 3, a.y}, c, 1, LineStyle::kSolid, area);
    DrawSegment(img, {x - 3, b.y}, {x + 3, b.y}, c, 1, LineStyle::kSolid, area);
  }
  for (size_t i = 1; s.bar_width <= 0.0 && i < n; ++i) {
    if (!finite(i - 1) || !finite(i)) continue;
    DrawSegment(img, {pa.px(s.x[i - 1]), pa.py(s.y[i - 1])}, {pa.px(s.x[i]), pa.py(s.y[i])}, c,
                s.line_width, s.line, area);
  }
  for (size_t i = 0; i < n; ++i) {
    if (!finite(i)) continue;
    const cv::Point p(pa.px(s.x[i]), pa.py(s.y[i]));
    if (area.contains(p)) DrawMarker(img, p, s.marker, s.marker_size, c);
  }
  for (size_t i = 0; i < n && i < s.point_labels.size(); ++i) {
    if (!finite(i) || s.point_labels[i].empty()) continue;
    const cv::Size ts = TextSize(s.point_labels[i], kTickFont);
    // Above the point, kept inside the axes.
    const int y = std::clamp(pa.py(s.y[i]) - s.marker_size - 5, area.y + ts.height + 2,
                             area.y + area.height - 3);
    PutText(img, s.point_labels[i], {pa.px(s.x[i]) - ts.width / 2, y}, kTickFont);
  }
}

void DrawLabels(cv::Mat& img, const Axes& ax, const cv::Rect& cell, const cv::Rect& area) {
  if (!ax.title.empty()) {
    const cv::Size s = TextSize(ax.title, kTitleFont);
    PutText(img, ax.title, {area.x + (area.width - s.width) / 2, cell.y + 24}, kTitleFont);
  }
  if (!ax.x_label.empty()) {
    const cv::Size s = TextSize(ax.x_label, kLabelFont);
    PutText(img, ax.x_label, {area.x + (area.width - s.width) / 2, cell.y + cell.height - 12},
            kLabelFont);
  }
  PutTextVertical(img, ax.y_label, {cell.x + 14, area.y + area.height / 2}, kLabelFont);
}

// A box in the chosen corner: one row per labelled series (its swatch or line, its marker).
void DrawLegend(cv::Mat& img, const Axes& ax, const cv::Rect& area) {
  std::vector<const Series*> entries;
  for (const Series& s : ax.series) {
    if (!s.label.empty()) entries.push_back(&s);
  }
  if (!ax.legend || entries.empty()) return;
  int text_w = 0;
  for (const Series* s : entries) text_w = std::max(text_w, TextSize(s->label, kTickFont).width);
  const int row_h = 18;
  const int box_w = 44 + text_w;
  const int box_h = 8 + row_h * static_cast<int>(entries.size());
  const bool at_right = ax.legend_position == LegendPosition::kTopRight ||
                        ax.legend_position == LegendPosition::kBottomRight;
  const bool at_bottom = ax.legend_position == LegendPosition::kBottomLeft ||
                         ax.legend_position == LegendPosition::kBottomRight;
  const int bx = at_right ? area.x + area.width - box_w - 8 : area.x + 8;
  const int by = at_bottom ? area.y + area.height - box_h - 8 : area.y + 8;
  const cv::Rect box(bx, by, box_w, box_h);
  cv::rectangle(img, box, kWhite, cv::FILLED);
  cv::rectangle(img, box, cv::Scalar(180, 180, 180), 1);
  for (size_t i = 0; i < entries.size(); ++i) {
    const Series& s = *entries[i];
    const int y = by + 4 + row_h * static_cast<int>(i) + row_h / 2;
    const cv::Scalar c = ToScalar(s.color);
    if (s.bar_width > 0.0) {
      const cv::Rect swatch(bx + 10, y - 6, 18, 12);
      cv::rectangle(img, swatch, Tint(s.color), cv::FILLED);
      cv::rectangle(img, swatch, c, 1);
    } else {
      DrawSegment(img, {bx + 6, y}, {bx + 32, y}, c, s.line_width,
                  s.line == LineStyle::kNone ? LineStyle::kNone : s.line, box);
    }
    DrawMarker(img, {bx + 19, y}, s.marker, s.marker_size, c);
    PutText(img, s.label, {bx + 38, y + 5}, kTickFont);
  }
}

void DrawAxes(cv::Mat& img, const Axes& ax, const cv::Rect& cell) {
  const PlotArea pa = Layout(ax, cell);
  DrawGrid(img, ax, pa);
  DrawRefLines(img, ax, pa);
  for (const Series& s : ax.series) DrawSeries(img, s, pa);
  cv::rectangle(img, pa.area, kAxisGray, 1);
  DrawLabels(img, ax, cell, pa.area);
  DrawLegend(img, ax, pa.area);
}

}  // namespace

Rgb PaletteColor(int index) {
  static const Rgb kPalette[] = {{31, 119, 180},  {255, 127, 14}, {44, 160, 44},   {214, 39, 40},
                                 {148, 103, 189}, {140, 86, 75},  {227, 119, 194}, {127, 127, 127},
                                 {188, 189, 34},  {23, 190, 207}};
  const int n = static_cast<int>(sizeof(kPalette) / sizeof(kPalette[0]));
  return kPalette[((index % n) + n) % n];
}

Series& Axes::AddLine(const std::string& label, std::vector<double> x, std::vector<double> y) {
  Series s;
  s.label = label;
  s.x = std::move(x);
  s.y = std::move(y);
  s.color = PaletteColor(static_cast<int>(series.size()));
  series.push_back(std::move(s));
  return series.back();
}

Series& Axes::AddScatter(const std::string& label, std::vector<double> x, std::vector<double> y) {
  Series& s = AddLine(label, std::move(x), std::move(y));
  s.line = LineStyle::kNone;
  s.marker = Marker::kCircle;
  return s;
}

Series& Axes::AddBars(const std::string& label, std::vector<double> x, std::vector<double> y,
                      double width) {
  Series& s = AddLine(label, std::move(x), std::move(y));
  s.line = LineStyle::kNone;
  s.bar_width = width;
  return s;
}

RefLine& Axes::AddHLine(double y, const std::string& label) {
  RefLine l;
  l.value = y;
  l.label = label;
  ref_lines.push_back(l);
  return ref_lines.back();
}

RefLine& Axes::AddVLine(double x, const std::string& label) {
  RefLine& l = AddHLine(x, label);
  l.vertical = true;
  return l;
}

Figure::Figure(int width_px, int height_px, int rows, int cols)
    : width_(width_px), height_(height_px), rows_(rows), cols_(cols) {
  if (width_px < 100 || height_px < 100 || rows < 1 || cols < 1) {
    throw std::invalid_argument("Figure: at least 100x100 px and one row and column");
  }
  axes_.resize(static_cast<size_t>(rows) * cols);
}

Axes& Figure::axes(int row, int col) { return axes_.at(static_cast<size_t>(row) * cols_ + col); }
const Axes& Figure::axes(int row, int col) const {
  return axes_.at(static_cast<size_t>(row) * cols_ + col);
}

Image Figure::Render() const {
  cv::Mat img(height_, width_, CV_8UC3, kWhite);
  int top = 0;
  if (!title.empty()) {
    const cv::Size s = TextSize(title, kTitleFont + 0.1);
    PutText(img, title, {(width_ - s.width) / 2, 26}, kTitleFont + 0.1);
    top = 36;
  }
  const int cell_w = width_ / cols_;
  const int cell_h = (height_ - top) / rows_;
  for (int r = 0; r < rows_; ++r) {
    for (int c = 0; c < cols_; ++c) {
      DrawAxes(img, axes(r, c), cv::Rect(c * cell_w, top + r * cell_h, cell_w, cell_h));
    }
  }
  Image out;
  out.width = width_;
  out.height = height_;
  out.channels = 3;
  out.data.assign(img.data, img.data + static_cast<size_t>(width_) * height_ * 3);
  return out;
}

void Figure::SavePng(const std::string& path) const { WritePng(Render(), path); }

std::vector<double> NiceTicks(double lo, double hi, int target) {
  if (!(hi > lo)) return {lo};
  const double step = NiceStep((hi - lo) / std::max(1, target));
  std::vector<double> ticks;
  const long k0 = static_cast<long>(std::ceil(lo / step - 1e-9));
  const long k1 = static_cast<long>(std::floor(hi / step + 1e-9));
  for (long k = k0; k <= k1; ++k) ticks.push_back(k * step);
  return ticks;
}

}  // namespace flexbench::render

namespace flexbench::render {
namespace {

cv::Scalar Viridis(double t) {
  static const double k[5][3] = {
      {68, 1, 84}, {59, 82, 139}, {33, 145, 140}, {94, 201, 98}, {253, 231, 37}};
  t = std::clamp(t, 0.0, 1.0) * 4.0;
  const int i = std::min(3, static_cast<int>(t));
  const double f = t - i;
  return cv::Scalar(k[i][0] + f * (k[i + 1][0] - k[i][0]), k[i][1] + f * (k[i + 1][1] - k[i][1]),
                    k[i][2] + f * (k[i + 1][2] - k[i][2]));
}

void DrawHeatmap(cv::Mat& img, const Heatmap& h, const cv::Rect& cell) {
  const int rows = static_cast<int>(h.row_labels.size());
  const int cols = static_cast<int>(h.col_labels.size());
  if (static_cast<int>(h.value.size()) != rows) throw InputError("heat map: value rows");
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  const auto scaled = [&](double v) { return h.log_scale ? std::log10(v) : v; };
  for (const auto& r : h.value) {
    if (static_cast<int>(r.size()) != cols) throw InputError("heat map: value columns");
    for (double v : r) {
      if (!std::isfinite(v) || (h.log_scale && v <= 0)) continue;
      lo = std::min(lo, scaled(v));
      hi = std::max(hi, scaled(v));
    }
  }
  if (!(hi > lo)) hi = lo + 1.0;
  int label_w = 0;
  for (const auto& l : h.row_labels) label_w = std::max(label_w, TextSize(l, kTickFont).width);
  const int left = cell.x + label_w + 14;
  const int top = cell.y + 40;
  const int right = cell.x + cell.width - 10;
  const int bottom = cell.y + cell.height - 76;
  const int cw = (right - left) / std::max(1, cols);
  const int ch = (bottom - top) / std::max(1, rows);
  const cv::Size ts = TextSize(h.title, kTitleFont);
  PutText(img, h.title, {cell.x + (cell.width - ts.width) / 2, cell.y + 24}, kTitleFont);
  for (int r = 0; r < rows; ++r) {
    const cv::Size s = TextSize(h.row_labels[r], kTickFont);
    PutText(img, h.row_labels[r], {left - s.width - 8, top + r * ch + ch / 2 + s.height / 2},
            kTickFont);
    for (int c = 0; c < cols; ++c) {
      const double v = h.value[r][c];
      const bool ok = std::isfinite(v) && !(h.log_scale && v <= 0);
      const double t = ok ? (scaled(v) - lo) / (hi - lo) : 0.0;
      const cv::Rect box(left + c * cw, top + r * ch, cw, ch);
      cv::rectangle(img, box, ok ? Viridis(t) : cv::Scalar(200, 200, 200), cv::FILLED);
      cv::rectangle(img, box, kWhite, 1);
      if (!h.marked.empty() && h.marked[r][c]) {
        cv::rectangle(img, cv::Rect(box.x + 2, box.y + 2, box.width - 4, box.height - 4),
                      cv::Scalar(220, 30, 30), 3);
      }
      if (!h.text.empty() && !h.text[r][c].empty()) {
        const cv::Size s = TextSize(h.text[r][c], kTickFont);
        PutText(img, h.text[r][c], {box.x + (cw - s.width) / 2, box.y + (ch + s.height) / 2},
                kTickFont, ok && t < 0.6 ? kWhite : kBlack);
      }
    }
  }
  // Labels wider than their column are staggered over two lines.
  bool stagger = false;
  for (const auto& l : h.col_labels) stagger |= TextSize(l, kTickFont).width > cw - 6;
  for (int c = 0; c < cols; ++c) {
    const cv::Size s = TextSize(h.col_labels[c], kTickFont);
    PutText(img, h.col_labels[c],
            {left + c * cw + (cw - s.width) / 2, bottom + 20 + (stagger && c % 2 ? 16 : 0)},
            kTickFont);
  }
  if (!h.note.empty()) PutText(img, h.note, {left, bottom + 58}, kTickFont);
}

}  // namespace

void SaveHeatmapsPng(const std::vector<Heatmap>& panels, int width_px, int height_px,
                     const std::string& path) {
  cv::Mat img(height_px, width_px, CV_8UC3, kWhite);
  const int w = width_px / std::max<int>(1, panels.size());
  for (size_t i = 0; i < panels.size(); ++i) {
    DrawHeatmap(img, panels[i], cv::Rect(static_cast<int>(i) * w, 0, w, height_px));
  }
  Image out;
  out.width = width_px;
  out.height = height_px;
  out.channels = 3;
  out.data.assign(img.data, img.data + static_cast<size_t>(width_px) * height_px * 3);
  WritePng(out, path);
}

}  // namespace flexbench::render
