#include "scenarios/runner/kinds/jsk/plots.h"

#include <algorithm>
#include <cmath>

namespace flexbench::scenarios::jsk {

void FitAxes(render::Axes* ax, size_t skip, double headroom, bool from_zero) {
  double x0 = 1e300, x1 = -1e300, y0 = from_zero ? 0.0 : 1e300, y1 = -1e300;
  for (const render::Series& s : ax->series) {
    if (s.x.empty()) continue;
    x0 = std::min(x0, s.x.front());
    x1 = std::max(x1, s.x.back());
    for (size_t i = std::min(skip, s.y.size() / 10); i < s.y.size(); ++i) {
      if (!std::isfinite(s.y[i])) continue;
      y0 = std::min(y0, s.y[i]);
      y1 = std::max(y1, s.y[i]);
    }
  }
  if (x1 > x0) {
    ax->x_min = x0;
    ax->x_max = x1;
  }
  if (y1 > y0) {
    ax->y_min = from_zero && y0 >= 0.0 ? y0 : y0 - 0.05 * (y1 - y0);
    ax->y_max = y1 + headroom * (y1 - y0);
  }
}

void StyleComparison(render::Series* s) {
  if (s->label.find("bootstrap") != std::string::npos ||
      s->label.find("_n2048") != std::string::npos) {
    s->line = render::LineStyle::kDashed;
    s->line_width = 1;
  }
}

namespace {

// The x axis every panel of a joint plot shares: the first trace's time span.
struct TimeAxis {
  double t_min, t_max;
  std::string label;
  void Apply(render::Axes* ax) const {
    ax->x_min = t_min;
    ax->x_max = t_max;
    ax->x_label = label;
  }
};

// Joint j: the reference, the truth when given and every trace's mean and 95% band.
void JointPanel(const Rig& rig, int j, const TimeAxis& x, const std::vector<Trace>& traces,
                const std::vector<std::vector<double>>* truth,
                const std::vector<std::vector<double>>& reference, render::Axes* ax_out) {
  render::Axes& ax = *ax_out;
  x.Apply(&ax);
  ax.title = rig.joint_names()[j];
  ax.y_label = "angle [deg]";
  ax.legend_position = render::LegendPosition::kTopLeft;
  const std::vector<double>& t = traces.front().t;
  render::Series& ref = ax.AddLine("reference", t, ToDeg(reference[j]));
  ref.color = render::Rgb{140, 140, 140};
  ref.line = render::LineStyle::kDashed;
  if (truth) {
    render::Series& tr = ax.AddLine("truth (effective)", t, ToDeg((*truth)[j]));
    tr.color = render::Rgb{0, 0, 0};
  }
  // Head room above the data for the legend.
  // (The first steps, where the prior of [PF eq. 29] is still flat, do not set the range.)
  double lo = 1e300, hi = -1e300;
  const auto extend = [&](const std::vector<double>& v) {
    for (size_t i = std::min<size_t>(5, v.size() / 10); i < v.size(); ++i) {
      if (std::isfinite(v[i])) lo = std::min(lo, Deg(v[i])), hi = std::max(hi, Deg(v[i]));
    }
  };
  extend(reference[j]);
  if (truth) extend((*truth)[j]);
  for (const Trace& tr : traces) extend(tr.lower[j]), extend(tr.upper[j]);
  if (hi > lo) {
    ax.y_min = lo - 0.05 * (hi - lo);
    ax.y_max = hi + 0.6 * (hi - lo);
  }
  for (size_t e = 0; e < traces.size(); ++e) {
    const render::Rgb c = render::PaletteColor(static_cast<int>(e));
    render::Series& m =
        ax.AddLine(traces[e].label + " mean", traces[e].t, ToDeg(traces[e].mean[j]));
    m.color = c;
    render::Series& lower = ax.AddLine(traces.size() == 1 ? "95% interval" : "", traces[e].t,
                                       ToDeg(traces[e].lower[j]));
    lower.color = c;
    lower.line_width = 1;
    render::Series& upper = ax.AddLine("", traces[e].t, ToDeg(traces[e].upper[j]));
    upper.color = c;
    upper.line_width = 1;
  }
}

// The end-effector position error of every trace.
void EndEffectorPanel(const TimeAxis& x, const std::vector<Trace>& traces, render::Axes* ax) {
  x.Apply(ax);
  ax->title = "end-effector position error";
  double ee_max = 1e-3;
  ax->y_label = "error [cm]";
  for (size_t e = 0; e < traces.size(); ++e) {
    const std::vector<double> cm = ToCm(traces[e].ee_err_m);
    render::Series& s = ax->AddLine(traces[e].label, traces[e].t, cm);
    s.color = render::PaletteColor(static_cast<int>(e));
    for (size_t i = std::min<size_t>(5, cm.size() / 10); i < cm.size(); ++i) {
      ee_max = std::max(ee_max, cm[i]);
    }
  }
  ax->y_min = 0.0;
  ax->y_max = 1.35 * ee_max;
}

// The effective sample size of the particle filters.
void EssPanel(const TimeAxis& x, const std::vector<Trace>& traces, render::Axes* e) {
  x.Apply(e);
  e->title = "effective sample size (before resampling)";
  e->y_label = "ESS";
  e->y_min = 0.0;
  double ess_max = 1.0;
  for (size_t k = 0; k < traces.size(); ++k) {
    render::Series& s = e->AddLine(traces[k].label, traces[k].t, traces[k].ess);
    s.color = render::PaletteColor(static_cast<int>(k));
    for (double v : traces[k].ess) ess_max = std::max(ess_max, v);
  }
  e->y_max = 1.3 * ess_max;
}

// Estimators without particles: the angle each one adds to the reference (its estimate of the
// deflection, or its failure).
void DeflectionPanel(const Rig& rig, const std::string& x_label, const std::vector<Trace>& traces,
                     const std::vector<std::vector<double>>& reference, render::Axes* d) {
  d->title = "estimate minus reference";
  d->x_label = x_label;
  d->y_label = "angle [deg]";
  for (int j = 0; j < rig.nq(); ++j) {
    for (const Trace& tr : traces) {
      std::vector<double> diff(tr.t.size());
      for (size_t i = 0; i < diff.size(); ++i) {
        diff[i] = Deg(AngleError(tr.mean[j][i], reference[j][i]));
      }
      d->AddLine(rig.joint_names()[j], tr.t, diff).color = render::PaletteColor(j);
    }
  }
  FitAxes(d, 0, 0.5, /*from_zero=*/false);
}

}  // namespace

std::vector<double> ToDeg(const std::vector<double>& rad) {
  std::vector<double> out(rad.size());
  for (size_t i = 0; i < rad.size(); ++i) out[i] = Deg(rad[i]);
  return out;
}

std::vector<double> ToCm(const std::vector<double>& m) {
  std::vector<double> out(m.size());
  for (size_t i = 0; i < m.size(); ++i) out[i] = 100.0 * m[i];
  return out;
}

void PlotJointBands(const Rig& rig, const std::string& title, const std::vector<Trace>& traces,
                    const std::vector<std::vector<double>>* truth,
                    const std::vector<std::vector<double>>& reference, const std::string& path,
                    const std::string& x_label) {
  const int nq = rig.nq();
  const int cols = 3;
  const int rows = (nq + 1 + cols - 1) / cols;
  render::Figure fig(1500, 430 * rows, rows, cols);
  fig.title = title;
  const std::vector<double>& t = traces.front().t;
  const TimeAxis x{t.empty() ? 0.0 : t.front(), t.empty() ? 1.0 : t.back(), x_label};
  for (int j = 0; j < nq; ++j) {
    JointPanel(rig, j, x, traces, truth, reference, &fig.axes(j / cols, j % cols));
  }
  EndEffectorPanel(x, traces, &fig.axes(nq / cols, nq % cols));
  // The effective sample size of the particle filters, when a panel is left.
  const bool any_pf = std::any_of(traces.begin(), traces.end(), [](const Trace& tr) {
    return std::any_of(tr.ess.begin(), tr.ess.end(), [](double e) { return e > 0.0; });
  });
  if (nq + 1 < rows * cols) {
    render::Axes* last = &fig.axes((nq + 1) / cols, (nq + 1) % cols);
    if (any_pf) {
      EssPanel(x, traces, last);
    } else {
      DeflectionPanel(rig, x_label, traces, reference, last);
    }
  }
  fig.SavePng(path);
}

}  // namespace flexbench::scenarios::jsk
