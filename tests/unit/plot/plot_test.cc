// render/plot: deterministic bytes, ticks, what gets drawn where.
#include "render/plot.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include "estimators/error.h"
#include "tests/common/test_util.h"

namespace flexbench::render {
namespace {

// The pixels of a bar of colour `c` (bars are filled with the colour lightened by 60%).
int Tinted(const Image& img, Rgb c) {
  const auto t = [](int v) { return static_cast<int>(std::lround(v + 0.6 * (255 - v))); };
  int n = 0;
  for (size_t i = 0; i + 2 < img.data.size(); i += 3) {
    n += std::abs(img.data[i] - t(c.r)) <= 1 && std::abs(img.data[i + 1] - t(c.g)) <= 1 &&
         std::abs(img.data[i + 2] - t(c.b)) <= 1;
  }
  return n;
}

Figure MakeFigure() {
  Figure fig(800, 400, 1, 2);
  fig.title = "test figure";
  Axes& a = fig.axes(0, 0);
  a.title = "lines";
  a.x_label = "x [m]";
  a.y_label = "y [cm]";
  std::vector<double> x, y, e;
  for (int i = 0; i < 20; ++i) {
    x.push_back(0.05 * i);
    y.push_back(std::sin(0.3 * i));
    e.push_back(0.1);
  }
  a.AddLine("sine", x, y).marker = Marker::kCircle;
  a.AddScatter("points", x, std::vector<double>(x.size(), 0.5)).y_err = e;
  a.AddHLine(0.8, "limit");
  Axes& b = fig.axes(0, 1);
  b.AddLine("dashed", {0, 1, 2}, {3, 1, 2}).line = LineStyle::kDashed;
  b.legend_position = LegendPosition::kBottomRight;
  return fig;
}

TEST(Plot, SameDataSameBytes) {
  const Image a = MakeFigure().Render();
  const Image b = MakeFigure().Render();
  EXPECT_EQ(a.data, b.data);
  testing::TempDir tmp;
  MakeFigure().SavePng((tmp.path() / "a.png").string());
  MakeFigure().SavePng((tmp.path() / "b.png").string());
  const std::string pa = testing::ReadFile(tmp.path() / "a.png");
  EXPECT_GT(pa.size(), 1000u);
  EXPECT_EQ(pa, testing::ReadFile(tmp.path() / "b.png"));
}

TEST(Plot, DrawsSeriesInTheirColours) {
  const Image img = MakeFigure().Render();
  ASSERT_EQ(img.width, 800);
  ASSERT_EQ(img.height, 400);
  ASSERT_EQ(img.channels, 3);
  const auto count = [&](Rgb c) {
    int n = 0;
    for (size_t i = 0; i + 2 < img.data.size(); i += 3) {
      n += img.data[i] == c.r && img.data[i + 1] == c.g && img.data[i + 2] == c.b;
    }
    return n;
  };
  EXPECT_GT(count(PaletteColor(0)), 200);  // first series, left axes
  EXPECT_GT(count(PaletteColor(1)), 50);   // scatter
  EXPECT_FALSE(IsConstant(img));
  // White background in the corners.
  EXPECT_EQ(img.data[0], 255);
  EXPECT_EQ(img.data[img.data.size() - 1], 255);
}

// Bars start at 0: their filled areas are in proportion to their heights, and a bar drawn
// from 0 to a negative value is not lost.
TEST(Plot, BarAreasFollowTheirHeights) {
  Figure fig(500, 400);
  Axes& a = fig.axes();
  a.y_min = -2.0;
  a.y_max = 4.0;
  a.AddBars("one", {0.0}, {1.0});
  a.AddBars("three", {1.0}, {3.0}).y_err = {0.5};
  a.AddBars("minus", {2.0}, {-1.5});
  a.legend = false;
  const Image img = fig.Render();
  const int one = Tinted(img, PaletteColor(0));
  const int three = Tinted(img, PaletteColor(1));
  const int minus = Tinted(img, PaletteColor(2));
  ASSERT_GT(one, 100);
  EXPECT_NEAR(static_cast<double>(three) / one, 3.0, 0.3);
  EXPECT_NEAR(static_cast<double>(minus) / one, 1.5, 0.2);
}

// On a log axis a bar's height is log10 of its value over the bottom edge: 0.07 beside 4 (a
// fiftieth, a sliver on a linear axis) keeps a height in proportion to its decades.
TEST(Plot, LogAxisBarsRiseFromTheBottomEdgeByDecades) {
  Figure fig(500, 400);
  Axes& a = fig.axes();
  a.y_log = true;
  a.y_min = 0.01;
  a.y_max = 100.0;
  a.AddBars("big", {0.0}, {10.0});
  a.AddBars("small", {1.0}, {0.1});
  a.AddBars("zero", {2.0}, {0.0});  // below the axes: not drawn
  a.legend = false;
  const Image img = fig.Render();
  const int big = Tinted(img, PaletteColor(0));
  const int small = Tinted(img, PaletteColor(1));
  ASSERT_GT(small, 100);
  // 10 is 3 decades above 0.01, 0.1 one decade.
  EXPECT_NEAR(static_cast<double>(big) / small, 3.0, 0.3);
  EXPECT_EQ(Tinted(img, PaletteColor(2)), 0);
}

TEST(Plot, PointLabelsAreDrawnAboveTheirPoints) {
  Figure fig(400, 300);
  Axes& a = fig.axes();
  a.legend = false;
  a.AddBars("b", {0.0, 1.0}, {1.0, 2.0});
  const Image without = fig.Render();
  a.series.back().point_labels = {"1.00", ""};
  const Image with = fig.Render();
  int changed = 0;
  for (size_t i = 0; i < with.data.size(); ++i) changed += with.data[i] != without.data[i];
  EXPECT_GT(changed, 20);
}

TEST(Plot, NonFinitePointsAreSkipped) {
  Figure fig(300, 200);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  fig.axes().AddLine("gappy", {0, 1, 2, 3}, {0, nan, 2, 3});
  EXPECT_NO_THROW(fig.Render());
  Figure empty(300, 200);
  EXPECT_NO_THROW(empty.Render());  // no data: default limits
}

TEST(Plot, NiceTicks) {
  const auto expect_ticks = [](const std::vector<double>& got, const std::vector<double>& want) {
    ASSERT_EQ(got.size(), want.size());
    for (size_t i = 0; i < got.size(); ++i) EXPECT_NEAR(got[i], want[i], 1e-12);
  };
  expect_ticks(NiceTicks(0.0, 1.0, 5), {0.0, 0.2, 0.4, 0.6, 0.8, 1.0});
  expect_ticks(NiceTicks(-3.2, 7.9, 6), {-2.0, 0.0, 2.0, 4.0, 6.0});
  expect_ticks(NiceTicks(0.013, 0.0191, 4), {0.014, 0.016, 0.018});
}

TEST(Plot, HeatmapsAreDeterministicAndCheckTheirShape) {
  Heatmap h;
  h.title = "error";
  h.row_labels = {"a", "b"};
  h.col_labels = {"none", "effect"};
  h.value = {{1.0, 10.0}, {1.0, std::numeric_limits<double>::quiet_NaN()}};
  h.text = {{"1", "10"}, {"1", "nan"}};
  h.marked = {{0, 1}, {0, 0}};
  const auto dir = std::filesystem::temp_directory_path();
  const std::string p1 = (dir / "flexbench_heat_1.png").string();
  const std::string p2 = (dir / "flexbench_heat_2.png").string();
  SaveHeatmapsPng({h, h}, 600, 260, p1);
  SaveHeatmapsPng({h, h}, 600, 260, p2);
  const std::string a = testing::ReadFile(p1);
  EXPECT_GT(a.size(), 1000u);
  EXPECT_EQ(a, testing::ReadFile(p2));
  std::filesystem::remove(p2);
  h.value[1].pop_back();  // a row shorter than the column labels
  EXPECT_THROW(SaveHeatmapsPng({h}, 600, 260, p2), InputError);
  EXPECT_FALSE(std::filesystem::exists(p2));
  std::filesystem::remove(p1);
}

}  // namespace
}  // namespace flexbench::render
