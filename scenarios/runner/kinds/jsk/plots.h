// The jsk kinds' figures: joint plots in the style of the particle-filter paper's Fig. 6 and the
// axis helpers the kinds' own figures share.
#pragma once

#include <string>
#include <vector>

#include "render/plot.h"
#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/kinds/jsk/trace.h"

namespace flexbench::scenarios::jsk {

// Joint plots in the style of the paper's Fig. 6: per joint the estimate's mean and 95% band
// (thin lines of the same colour), the reference (grey, dashed) and, when given, the truth
// (black); the last panel the end-effector error. Saved as frames/<file>.
void PlotJointBands(const Rig& rig, const std::string& title, const std::vector<Trace>& traces,
                    const std::vector<std::vector<double>>* truth,
                    const std::vector<std::vector<double>>& reference, const std::string& path,
                    const std::string& x_label);

// Fits an axes' limits to its series: x from the first to the last sample, y from 0 (or the
// data's minimum when negative or when !from_zero) to the maximum with head room for the
// legend, ignoring the first `skip` samples of each series (the flat prior's first steps).
void FitAxes(render::Axes* ax, size_t skip = 5, double headroom = 0.4, bool from_zero = true);
// A dashed, thin line for the comparison runs (labels containing "bootstrap" or "_n2048").
void StyleComparison(render::Series* s);

// Angles in degrees, for plotting.
std::vector<double> ToDeg(const std::vector<double>& rad);
// The end-effector error of every trace in cm, for plotting.
std::vector<double> ToCm(const std::vector<double>& m);

}  // namespace flexbench::scenarios::jsk
