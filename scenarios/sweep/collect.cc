#include "scenarios/sweep/collect.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "render/plot.h"
#include "scenarios/runner/gates.h"
#include "scenarios/runner/output.h"
#include "scenarios/sweep/stats.h"

namespace fs = std::filesystem;

namespace flexbench::scenarios::sweep {
namespace {

using MetricRow = std::map<std::string, double>;

// Numeric and boolean leaves of `j` as "prefix.a.b" -> value.
void Flatten(const Json& j, const std::string& prefix, MetricRow* out) {
  if (j.is_object()) {
    for (auto it = j.begin(); it != j.end(); ++it) {
      Flatten(it.value(), prefix.empty() ? it.key() : prefix + "." + it.key(), out);
    }
  } else if (j.is_boolean()) {
    (*out)[prefix] = j.get<bool>() ? 1.0 : 0.0;
  } else if (j.is_number()) {
    (*out)[prefix] = j.get<double>();
  }
}

// A run's scalar metrics under the names gates use: metrics.* without the prefix, and
// estimators.*.
MetricRow Metrics(const Json& summary) {
  MetricRow row;
  if (summary.contains("metrics")) Flatten(summary["metrics"], "", &row);
  if (summary.contains("estimators")) Flatten(summary["estimators"], "estimators", &row);
  return row;
}

std::map<std::string, bool> ScenarioGates(const Json& summary) {
  std::map<std::string, bool> g;
  if (!summary.contains("gates")) return g;
  for (const Json& row : summary["gates"]) {
    g[row.value("name", "")] = row.value("passed", false);
  }
  return g;
}

std::string Num(double v) { return std::isfinite(v) ? Json(v).dump() : ""; }

std::string CsvField(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

// The column name a gate path names: "metrics.x" is "x".
std::string Column(const std::string& path, const std::set<std::string>& columns) {
  if (columns.count(path) || path.rfind("metrics.", 0) != 0) return path;
  return path.substr(8);
}

Json SummaryJson(const SampleSummary& s) {
  return Json{{"n", s.n},     {"mean", s.mean}, {"std", s.std},       {"median", s.median},
              {"min", s.min}, {"max", s.max},   {"ci_low", s.ci_low}, {"ci_high", s.ci_high}};
}

Json ProportionJson(const Proportion& p) {
  return Json{{"passes", p.passes},
              {"n", p.n},
              {"pass_fraction", p.fraction},
              {"wilson_low", p.wilson_low},
              {"wilson_high", p.wilson_high}};
}

struct PointData {
  std::vector<MetricRow> metrics;  // successful runs, seed order
  std::vector<std::map<std::string, bool>> gates;
};

// Value of a statistic at one point: NaN when no run has it.
double Evaluate(const Statistic& s, const PointData& d, const std::set<std::string>& columns,
                const std::string& seed_key, int resamples, Json* point_json) {
  if (s.of_gate) {
    int passes = 0, n = 0;
    for (const auto& g : d.gates) {
      const auto it = g.find(s.path);
      if (it == g.end()) continue;
      ++n;
      passes += it->second ? 1 : 0;
    }
    const Proportion p = WilsonInterval(passes, n);
    (*point_json)["gates"][s.path] = ProportionJson(p);
    return s.stat == "pass_fraction" ? p.fraction
           : s.stat == "wilson_low"  ? p.wilson_low
                                     : p.wilson_high;
  }
  const std::string a = Column(s.path, columns);
  const std::string b = s.divisor.empty() ? "" : Column(s.divisor, columns);
  std::vector<double> x;
  for (const MetricRow& r : d.metrics) {
    const auto ia = r.find(a);
    if (ia == r.end()) continue;
    if (b.empty()) {
      x.push_back(ia->second);
      continue;
    }
    const auto ib = r.find(b);
    if (ib != r.end() && ib->second != 0.0) x.push_back(ia->second / ib->second);
  }
  const std::string key = b.empty() ? a : "ratio(" + a + ", " + b + ")";
  const SampleSummary sum = Summarize(x, StableHash((seed_key + "|" + key).c_str()), resamples);
  if (!b.empty()) (*point_json)["ratios"][key] = SummaryJson(sum);
  const Json j = SummaryJson(sum);
  const Json& v = j[s.stat];
  return v.is_number() ? v.get<double>() : NAN;
}

bool Compare(double v, const std::string& op, double t) {
  if (!std::isfinite(v) || !std::isfinite(t)) return false;
  if (op == "<") return v < t;
  if (op == "<=") return v <= t;
  if (op == ">") return v > t;
  if (op == ">=") return v >= t;
  if (op == "==") return v == t;
  return v != t;
}

void CheckStatisticExists(const SweepGate& g, const Statistic& s,
                          const std::set<std::string>& columns,
                          const std::set<std::string>& gate_names) {
  const auto fail = [&](const std::string& what) {
    throw InputError(g.where + ": gate '" + CapForMessage(g.name) + "': " + what);
  };
  if (s.of_gate) {
    if (!gate_names.count(s.path)) {
      fail("'" + CapForMessage(s.path) + "' is not a gate of any run's results");
    }
    return;
  }
  for (const std::string* p : {&s.path, &s.divisor}) {
    if (p->empty() || columns.count(Column(*p, columns))) continue;
    fail("metric '" + CapForMessage(*p) + "' is in no run's results (a typo? see sweep.csv)");
  }
}

}  // namespace

std::string LogPath(const SweepRun& run, const std::vector<SweepPoint>& points) {
  return "logs/" + points[run.point].name + "/seed_" + std::to_string(run.seed) + ".log";
}

std::string FailurePath(const SweepRun& run, const std::vector<SweepPoint>& points) {
  return "failed/" + points[run.point].name + "/seed_" + std::to_string(run.seed) + ".json";
}

std::vector<RunOutcome> ReadOutcomes(const fs::path& out, const std::vector<SweepPoint>& points,
                                     const std::vector<SweepRun>& runs, const RunKeys& keys,
                                     std::map<std::string, size_t>* stale) {
  std::vector<RunOutcome> outcomes(runs.size());
  for (size_t i = 0; i < runs.size(); ++i) {
    RunOutcome& o = outcomes[i];
    const fs::path summary = out / runs[i].dir / "summary.json";
    std::error_code ec;
    bool current = fs::is_regular_file(summary, ec);
    if (current) {
      const std::string why = StaleReason(out / runs[i].dir, keys.Of(runs[i]));
      if (!why.empty()) {
        ++(*stale)[why];
        current = false;
      }
    }
    if (current) {
      std::ifstream in(summary);
      o.summary = Json::parse(in, nullptr, false);
      if (o.summary.is_discarded()) {
        throw InputError(summary.string() +
                         ": not valid JSON (a damaged run folder; remove it "
                         "and run the sweep again)");
      }
      o.present = o.ok = true;
      continue;
    }
    const fs::path failure = out / FailurePath(runs[i], points);
    if (fs::is_regular_file(failure, ec)) {
      std::ifstream in(failure);
      o.failure = Json::parse(in, nullptr, false);
      if (o.failure.is_discarded()) o.failure = Json{{"error", "unreadable failure record"}};
      o.present = true;
    }
  }
  return outcomes;
}

namespace {

// What the runs gave, by run and by point; the metric and scenario-gate columns over all runs.
struct Gathered {
  std::vector<PointData> data;
  std::vector<MetricRow> rows;
  std::vector<std::map<std::string, bool>> gate_rows;
  std::set<std::string> columns, gate_names;
};

Gathered Gather(const std::vector<SweepPoint>& points, const std::vector<SweepRun>& runs,
                const std::vector<RunOutcome>& outcomes, Collected* c) {
  Gathered g;
  g.data.resize(points.size());
  g.rows.resize(runs.size());
  g.gate_rows.resize(runs.size());
  for (size_t i = 0; i < runs.size(); ++i) {
    if (!outcomes[i].ok) continue;
    g.rows[i] = Metrics(outcomes[i].summary);
    g.gate_rows[i] = ScenarioGates(outcomes[i].summary);
    for (const auto& [k, v] : g.rows[i]) g.columns.insert(k);
    for (const auto& [k, v] : g.gate_rows[i]) g.gate_names.insert(k);
    g.data[runs[i].point].metrics.push_back(g.rows[i]);
    if (runs[i].point == 0) c->first_point.emplace_back(runs[i].seed, g.rows[i]);
    g.data[runs[i].point].gates.push_back(g.gate_rows[i]);
  }
  return g;
}

// sweep.csv: a row per run in the sweep's order; the failed runs, and how many succeeded.
std::string SweepCsv(const SweepSpec& spec, const std::vector<SweepPoint>& points,
                     const std::vector<SweepRun>& runs, const std::vector<RunOutcome>& outcomes,
                     const Gathered& gd, Json* failed, int* succeeded) {
  const std::set<std::string>& columns = gd.columns;
  const std::set<std::string>& gate_names = gd.gate_names;
  std::ostringstream csv;
  csv << "point,seed,status,exit_code";
  for (const SweepAxis& a : spec.grid) csv << "," << CsvField(a.key);
  for (const std::string& col : columns) csv << "," << CsvField(col);
  for (const std::string& g : gate_names) csv << "," << CsvField("gate." + g);
  csv << "\n";
  for (size_t i = 0; i < runs.size(); ++i) {
    const RunOutcome& o = outcomes[i];
    const SweepPoint& p = points[runs[i].point];
    const std::string status = o.ok ? "ok" : o.present ? "failed" : "missing";
    csv << p.name << "," << runs[i].seed << "," << status << ",";
    if (o.ok) {
      csv << 0;
      ++*succeeded;
    } else if (o.present && o.failure.contains("exit_code") && o.failure["exit_code"].is_number()) {
      csv << o.failure["exit_code"].get<int>();
    }
    for (const std::string& v : p.values) csv << "," << CsvField(v);
    for (const std::string& col : columns) {
      const auto it = gd.rows[i].find(col);
      csv << "," << (it == gd.rows[i].end() ? "" : Num(it->second));
    }
    for (const std::string& g : gate_names) {
      const auto it = gd.gate_rows[i].find(g);
      csv << "," << (it == gd.gate_rows[i].end() ? "" : it->second ? "1" : "0");
    }
    csv << "\n";
    if (!o.ok) {
      Json f{{"point", p.name}, {"seed", runs[i].seed}, {"status", status}};
      if (o.present) f.update(o.failure);
      failed->push_back(f);
    }
  }
  return csv.str();
}

// Per point: its overrides, every metric's statistics and every scenario gate's pass fraction.
Json PointsJson(const SweepSpec& spec, const std::vector<SweepPoint>& points, const Gathered& gd) {
  const std::vector<PointData>& data = gd.data;
  const std::set<std::string>& columns = gd.columns;
  const std::set<std::string>& gate_names = gd.gate_names;
  Json point_list = Json::array();
  for (size_t p = 0; p < points.size(); ++p) {
    Json pj;
    pj["point"] = points[p].name;
    Json set = Json::object();
    for (size_t a = 0; a < spec.grid.size(); ++a) set[spec.grid[a].key] = points[p].values[a];
    pj["set"] = set;
    pj["runs"] = spec.seeds.size();
    pj["succeeded"] = data[p].metrics.size();
    pj["metrics"] = Json::object();
    for (const std::string& col : columns) {
      std::vector<double> x;
      for (const MetricRow& r : data[p].metrics) {
        const auto it = r.find(col);
        if (it != r.end()) x.push_back(it->second);
      }
      pj["metrics"][col] = SummaryJson(
          Summarize(x, StableHash((points[p].name + "|" + col).c_str()), spec.bootstrap_resamples));
    }
    pj["gates"] = Json::object();
    for (const std::string& g : gate_names) {
      Statistic s{"pass_fraction", g, "", true, ""};
      Evaluate(s, data[p], columns, points[p].name, spec.bootstrap_resamples, &pj);
    }
    point_list.push_back(pj);
  }
  return point_list;
}

// The sweep's own gates, point by point (their statistics land in point_list too).
Json SweepGatesJson(const SweepSpec& spec, const std::vector<SweepPoint>& points,
                    const Gathered& gd, Json& point_list, Collected* c) {
  const std::vector<PointData>& data = gd.data;
  const std::set<std::string>& columns = gd.columns;
  Json gates = Json::array();
  for (const SweepGate& g : spec.gates) {
    for (size_t p = 0; p < points.size(); ++p) {
      if (!g.point.empty() && g.point != points[p].name) continue;
      Json& pj = point_list[p];
      const double v =
          Evaluate(g.metric, data[p], columns, points[p].name, spec.bootstrap_resamples, &pj);
      double t = g.threshold;
      Json row{
          {"name", g.name}, {"metric", g.metric.text}, {"op", g.op}, {"point", points[p].name}};
      if (g.threshold_is_statistic) {
        t = g.scale * Evaluate(g.threshold_metric, data[p], columns, points[p].name,
                               spec.bootstrap_resamples, &pj);
        row["threshold_metric"] = g.threshold_metric.text;
        row["threshold_scale"] = g.scale;
      }
      row["threshold"] = t;
      row["value"] = v;
      const bool passed = Compare(v, g.op, t);
      row["passed"] = passed;
      c->gates_passed = c->gates_passed && passed;
      gates.push_back(row);
    }
  }
  return gates;
}

}  // namespace

Collected Collect(const SweepSpec& spec, const std::vector<SweepPoint>& points,
                  const std::vector<SweepRun>& runs, const std::vector<RunOutcome>& outcomes) {
  Collected c;
  const Gathered gd = Gather(points, runs, outcomes, &c);
  for (const SweepGate& g : spec.gates) {
    CheckStatisticExists(g, g.metric, gd.columns, gd.gate_names);
    if (g.threshold_is_statistic) {
      CheckStatisticExists(g, g.threshold_metric, gd.columns, gd.gate_names);
    }
  }
  Json failed = Json::array();
  int succeeded = 0;
  c.csv = SweepCsv(spec, points, runs, outcomes, gd, &failed, &succeeded);
  // aggregate.json: every metric and scenario gate per point, then the sweep's gates.
  Json agg;
  agg["sweep"] = spec.name;
  agg["seeds"] = spec.seeds;
  agg["runs"] = runs.size();
  agg["succeeded"] = succeeded;
  agg["failed"] = failed;
  agg["bootstrap_resamples"] = spec.bootstrap_resamples;
  Json point_list = PointsJson(spec, points, gd);
  const Json gates = SweepGatesJson(spec, points, gd, point_list, &c);
  agg["points"] = point_list;
  agg["gates"] = gates;
  agg["gates_passed"] = c.gates_passed;
  c.aggregate = agg;
  return c;
}

namespace {

double AsNumber(const std::string& text, bool* ok) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  *ok = end && *end == '\0' && !text.empty() && std::isfinite(v);
  return v;
}

const Json* PointMetric(const Json& point, const std::string& path) {
  const Json& m = point["metrics"];
  if (m.contains(path)) return &m[path];
  if (path.rfind("metrics.", 0) == 0 && m.contains(path.substr(8))) return &m[path.substr(8)];
  return nullptr;
}

double Field(const Json* s, const char* key) {
  return s && (*s)[key].is_number() ? (*s)[key].get<double>() : NAN;
}

// A plotted metric as a reader names it: "naive_ekf pos_err_final" for
// estimators.naive_ekf.metrics.pos_err_final_m, in mm; the unit from the name's suffix.
struct MetricName {
  std::string label;     // the legend's
  std::string quantity;  // the name without estimator and unit
  std::string unit;      // "" none
  double scale = 1.0;    // stored value -> shown value
};

MetricName Describe(const std::string& path) {
  MetricName n;
  std::string rest = path;
  std::string who;
  if (rest.rfind("estimators.", 0) == 0) {
    rest = rest.substr(11);
    who = rest.substr(0, rest.find('.'));
    rest = rest.find('.') == std::string::npos ? "" : rest.substr(rest.find('.') + 1);
  }
  if (rest.rfind("metrics.", 0) == 0) rest = rest.substr(8);
  static const struct {
    const char* suffix;
    const char* unit;
    double scale;
  } kUnits[] = {{"_m", "mm", 1e3},
                {"_deg", "deg", 1.0},
                {"_px", "px", 1.0},
                {"_s", "s", 1.0},
                {"_rad", "rad", 1.0}};
  n.quantity = rest;
  for (const auto& u : kUnits) {
    const std::string sfx = u.suffix;
    if (rest.size() > sfx.size() && rest.compare(rest.size() - sfx.size(), sfx.size(), sfx) == 0) {
      n.quantity = rest.substr(0, rest.size() - sfx.size());
      n.unit = u.unit;
      n.scale = u.scale;
      break;
    }
  }
  n.label = who.empty() ? n.quantity : who + " " + n.quantity;
  return n;
}

// The y axis' label: the one quantity and unit all plotted metrics share, else what they share.
std::string YLabel(const std::vector<std::string>& metrics) {
  std::set<std::string> quantities, units;
  for (const std::string& m : metrics) {
    const MetricName n = Describe(m);
    quantities.insert(n.quantity);
    units.insert(n.unit);
  }
  const std::string unit =
      units.size() == 1 ? (units.begin()->empty() ? "" : " [" + *units.begin() + "]") : "";
  if (units.size() > 1) return "value [units in the legend]";
  return (quantities.size() == 1 ? *quantities.begin() : std::string("value")) + unit;
}

// The legend's name of a metric: with its unit when the axis cannot give one.
std::string LegendName(const std::string& metric, const std::vector<std::string>& metrics) {
  std::set<std::string> units;
  for (const std::string& m : metrics) units.insert(Describe(m).unit);
  const MetricName n = Describe(metric);
  return n.label + (units.size() > 1 && !n.unit.empty() ? " [" + n.unit + "]" : "");
}

std::vector<double> Scaled(std::vector<double> v, double scale) {
  for (double& x : v) x *= scale;
  return v;
}

// The plotted metrics: the plot's, else those the value gates name.
std::vector<std::string> PlotMetrics(const SweepSpec& spec) {
  if (!spec.plot_metrics.empty()) return spec.plot_metrics;
  std::vector<std::string> m;
  for (const SweepGate& g : spec.gates) {
    if (g.metric.of_gate) continue;
    for (const std::string& p : {g.metric.path, g.metric.divisor}) {
      if (!p.empty() && std::find(m.begin(), m.end(), p) == m.end()) m.push_back(p);
    }
  }
  return m;
}

// Metric over the swept parameter (mean, with its CI as dashed lines in the same colour); one
// line per metric and combination of the other axes.
void PlotGrid(const SweepSpec& spec, const std::vector<SweepPoint>& points, const Json& agg,
              const std::vector<std::string>& metrics, render::Axes* ax) {
  const std::string x_key = spec.plot_x.empty() ? spec.grid.front().key : spec.plot_x;
  size_t xa = 0;
  while (spec.grid[xa].key != x_key) ++xa;
  bool numeric = true;
  for (const std::string& v : spec.grid[xa].values) {
    bool ok = false;
    AsNumber(v, &ok);
    numeric = numeric && ok;
  }
  ax->x_label = x_key + (numeric ? "" : " (value index)");
  std::map<std::string, std::vector<size_t>> groups;  // other axes' values -> points
  for (size_t p = 0; p < points.size(); ++p) {
    std::string rest;
    for (size_t a = 0; a < spec.grid.size(); ++a) {
      if (a != xa)
        rest += (rest.empty() ? "" : ", ") + spec.grid[a].key + "=" + points[p].values[a];
    }
    groups[rest].push_back(p);
  }
  int colour = 0;
  for (const std::string& metric : metrics) {
    for (const auto& [rest, ps] : groups) {
      std::vector<double> x, mean, lo, hi;
      for (size_t p : ps) {
        const std::string& v = points[p].values[xa];
        bool ok = false;
        const size_t idx = std::find(spec.grid[xa].values.begin(), spec.grid[xa].values.end(), v) -
                           spec.grid[xa].values.begin();
        x.push_back(numeric ? AsNumber(v, &ok) : static_cast<double>(idx));
        const Json* s = PointMetric(agg["points"][p], metric);
        mean.push_back(Field(s, "mean"));
        lo.push_back(Field(s, "ci_low"));
        hi.push_back(Field(s, "ci_high"));
      }
      const render::Rgb c = render::PaletteColor(colour++);
      const double k = Describe(metric).scale;
      const std::string label = LegendName(metric, metrics) + (rest.empty() ? "" : ", " + rest);
      render::Series& m = ax->AddLine(label + " mean", x, Scaled(mean, k));
      m.color = c;
      m.marker = render::Marker::kCircle;
      for (const auto* band : {&lo, &hi}) {
        render::Series& b = ax->AddLine(band == &lo ? label + " 95% CI" : "", x, Scaled(*band, k));
        b.color = c;
        b.line = render::LineStyle::kDashed;
        b.line_width = 1;
      }
    }
  }
}

// Without a grid: every run's value over its seed, with the mean and its CI as lines.
void PlotSeeds(const SweepSpec& spec, const Json& agg, const Collected& col,
               const std::vector<std::string>& metrics, render::Axes* ax) {
  ax->x_label = "seed";
  int colour = 0;
  for (const std::string& metric : metrics) {
    const Json* s = PointMetric(agg["points"][0], metric);
    const render::Rgb c = render::PaletteColor(colour++);
    std::vector<double> sx, sy;
    for (const auto& [seed, row] : col.first_point) {
      auto it = row.find(metric);
      if (it == row.end() && metric.rfind("metrics.", 0) == 0) it = row.find(metric.substr(8));
      if (it == row.end()) continue;
      sx.push_back(static_cast<double>(seed));
      sy.push_back(it->second);
    }
    const double k = Describe(metric).scale;
    const std::string label = LegendName(metric, metrics);
    render::Series& runs = ax->AddScatter(label + " per run", sx, Scaled(sy, k));
    runs.color = c;
    runs.marker = render::Marker::kCircle;
    std::vector<double> x(spec.seeds.begin(), spec.seeds.end());
    const double lo = k * Field(s, "ci_low"), hi = k * Field(s, "ci_high");
    const double mean = k * Field(s, "mean");
    render::Series& m = ax->AddLine(label + " mean", {x.front(), x.back()}, {mean, mean});
    m.color = c;
    for (double b : {lo, hi}) {
      render::Series& l =
          ax->AddLine(b == lo ? label + " 95% CI" : "", {x.front(), x.back()}, {b, b});
      l.color = c;
      l.line = render::LineStyle::kDashed;
      l.line_width = 1;
    }
  }
}

}  // namespace

void WriteCollected(const fs::path& out, const SweepSpec& spec,
                    const std::vector<SweepPoint>& points, const Collected& c) {
  WriteFileAtomic(out / "sweep.csv", c.csv);
  WriteFileAtomic(out / "aggregate.json",
                  c.aggregate.dump(2, ' ', false, Json::error_handler_t::replace) + "\n");
  const std::vector<std::string> metrics = PlotMetrics(spec);
  if (metrics.empty()) return;
  render::Figure fig(1000, 620);
  render::Axes& ax = fig.axes();
  ax.title = spec.name + ": mean over seeds with its 95% bootstrap CI";
  ax.y_label = YLabel(metrics);
  if (spec.grid.empty()) {
    PlotSeeds(spec, c.aggregate, c, metrics, &ax);
  } else {
    PlotGrid(spec, points, c.aggregate, metrics, &ax);
  }
  const fs::path tmp = out / "sweep.png.tmp.png";
  fig.SavePng(tmp.string());
  fs::rename(tmp, out / "sweep.png");
}

}  // namespace flexbench::scenarios::sweep
