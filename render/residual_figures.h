// The identification's two figures: a residual's structure against the variable that exposes it
// (the rows and the fitted curve), and the validation residual before and after the fit.
#pragma once

#include <string>
#include <vector>

namespace flexbench::render {

struct FigureText {
  std::string title, x_label, y_label;
};

// Rows (x, z) as circles and the fitted curve (cx, cz) as a line, into a PNG at `path`.
void SaveRowsAndCurve(const std::string& path, const FigureText& text, const std::vector<double>& x,
                      const std::vector<double>& z, const std::vector<double>& cx,
                      const std::vector<double>& cz);

// Each row's residual under the declared model (circles) and with the identified effects
// (squares), from 0 up, into a PNG at `path`.
void SaveBeforeAfter(const std::string& path, const FigureText& text, const std::vector<double>& x,
                     const std::vector<double>& before, const std::vector<double>& after);

}  // namespace flexbench::render
