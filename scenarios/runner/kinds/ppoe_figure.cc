#include "scenarios/runner/kinds/ppoe_figure.h"

namespace flexbench::scenarios {

void DrawPpoeFigure(const PpoeFigure& figure, const std::string& png_path) {}

}  // namespace flexbench::scenarios
