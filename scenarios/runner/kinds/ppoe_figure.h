// A panel of the PPOE paper's Fig. 3, top view (x right, y up, equal axes): the arm (joint
// positions joined by links), Monte-Carlo end-effector samples (green) and the boundary of the
// PPOE confidence region mapped through Exp (blue).
#pragma once

#include <string>
#include <vector>

#include "estimators/conventions.h"

namespace flexbench::scenarios {

struct PpoeFigure {
  std::string title;
  std::vector<Vec3> arm;
  std::vector<Vec3> samples;
  std::vector<Vec3> boundary;
};

void DrawPpoeFigure(const PpoeFigure& figure, const std::string& png_path);

}  // namespace flexbench::scenarios
