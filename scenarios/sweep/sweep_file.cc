#include "scenarios/sweep/sweep_file.h"

#include <algorithm>
#include <cctype>
#include <set>

#include "sim/config.h"

namespace flexbench::scenarios::sweep {
namespace {

constexpr size_t kMaxRuns = 1000000;

const std::set<std::string>& ValueStats() {
  static const std::set<std::string> s{"mean", "std",    "median",  "min",
                                       "max",  "ci_low", "ci_high", "n"};
  return s;
}
const std::set<std::string>& GateStats() {
  static const std::set<std::string> s{"pass_fraction", "wilson_low", "wilson_high"};
  return s;
}

std::string Trim(const std::string& s) {
  size_t a = 0;
  size_t b = s.size();
  while (a < b && std::isspace(static_cast<unsigned char>(s[a]))) ++a;
  while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1]))) --b;
  return s.substr(a, b - a);
}

bool IsPath(const std::string& s) {
  if (s.empty() || s.front() == '.' || s.back() == '.' || s.find("..") != std::string::npos) {
    return false;
  }
  return std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '-';
  });
}

// A point's folder name part: the value's text with anything outside [A-Za-z0-9._-] as '_'.
std::string FolderSafe(const std::string& s) {
  std::string out;
  for (char c : s) {
    out +=
        std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-' ? c : '_';
  }
  return out;
}

std::vector<std::uint64_t> ParseSeeds(const ConfigNode& node) {
  std::vector<std::uint64_t> seeds;
  if (node.IsMap()) {
    const ConfigNode from = node.Child("from");
    const ConfigNode to = node.Child("to");
    const int a = from.AsInt();
    const int b = to.AsInt();
    if (a < 0) from.Fail("seeds must be >= 0");
    if (a > b)
      to.Fail("seed range is empty: from " + std::to_string(a) + " > to " + std::to_string(b));
    // In 64 bits: `to` may be the largest int, where an int counter would wrap and never end.
    const std::int64_t first = a;
    const std::int64_t last = b;
    if (last - first >= static_cast<std::int64_t>(kMaxRuns)) to.Fail("more than 1000000 seeds");
    for (std::int64_t s = first; s <= last; ++s) seeds.push_back(static_cast<std::uint64_t>(s));
  } else {
    for (const ConfigNode& s : node.Items()) {
      if (s.AsInt() < 0) s.Fail("seeds must be >= 0");
      seeds.push_back(static_cast<std::uint64_t>(s.AsInt()));
    }
    if (seeds.empty()) node.Fail("no seeds");
    std::set<std::uint64_t> unique(seeds.begin(), seeds.end());
    if (unique.size() != seeds.size()) node.Fail("a seed is listed twice");
  }
  return seeds;
}

std::string KeyValue(const std::string& key, const ConfigNode& value) {
  return key + "=" + value.AsYamlText();
}

std::string ParseSweepName(const ConfigNode& name) {
  const std::string text = name.AsString();
  if (text.empty() || FolderSafe(text) != text || text.size() > 200) {
    name.Fail("must be a plain name of letters, digits, '.', '_' and '-'");
  }
  return text;
}

std::vector<std::string> ParseFixedSet(const ConfigNode& set) {
  std::vector<std::string> out;
  for (const std::string& key : set.Keys()) out.push_back(KeyValue(key, set.Child(key)));
  return out;
}

SweepAxis ParseAxis(const std::string& key, const ConfigNode& values) {
  if (!IsPath(key)) values.Fail("a grid key must be a dotted scenario key");
  SweepAxis axis{key, {}};
  for (const ConfigNode& v : values.Items()) axis.values.push_back(v.AsYamlText());
  if (axis.values.empty()) values.Fail("empty list of values");
  std::set<std::string> unique(axis.values.begin(), axis.values.end());
  if (unique.size() != axis.values.size()) values.Fail("a value is listed twice");
  return axis;
}

std::vector<SweepAxis> ParseGrid(const ConfigNode& grid) {
  const std::vector<std::string> keys = grid.Keys();
  if (keys.empty()) grid.Fail("empty grid: name at least one key with a list of values");
  std::vector<SweepAxis> axes;
  for (const std::string& key : keys) axes.push_back(ParseAxis(key, grid.Child(key)));
  return axes;
}

// A number, or {metric: STAT(ARG), scale: S} compared with the gate's metric.
void ParseThreshold(const ConfigNode& t, SweepGate* gate) {
  if (t.IsMap()) {
    gate->threshold_is_statistic = true;
    gate->threshold_metric = ParseStatistic(t.GetString("metric"), t.Child("metric").Where());
    gate->scale = t.GetDouble("scale", 1.0);
  } else {
    gate->threshold = t.AsDouble();
  }
}

// `names` holds the names of the gates before this one.
SweepGate ParseGate(const ConfigNode& g, std::set<std::string>* names) {
  SweepGate gate;
  gate.where = g.Where();
  gate.name = g.GetString("name");
  if (!names->insert(gate.name).second) g.Child("name").Fail("gate name used twice");
  gate.metric = ParseStatistic(g.GetString("metric"), g.Child("metric").Where());
  const ConfigNode op = g.Child("op");
  gate.op = op.AsString();
  static const std::set<std::string> ops{"<", "<=", ">", ">=", "==", "!="};
  if (!ops.count(gate.op)) op.Fail("unknown operator '" + gate.op + "'");
  ParseThreshold(g.Child("threshold"), &gate);
  gate.point = g.GetString("point", "");
  return gate;
}

std::vector<SweepGate> ParseGates(const ConfigNode& gates) {
  std::vector<SweepGate> out;
  std::set<std::string> names;
  for (const ConfigNode& g : gates.Items()) out.push_back(ParseGate(g, &names));
  return out;
}

// The plot's x must be a key of the already parsed grid.
void ParsePlot(const ConfigNode& plot, SweepSpec* spec) {
  for (const ConfigNode& m : plot.Child("metrics").Items()) {
    if (!IsPath(m.AsString())) m.Fail("not a metric path");
    spec->plot_metrics.push_back(m.AsString());
  }
  spec->plot_x = plot.GetString("x", "");
  if (!spec->plot_x.empty() &&
      std::none_of(spec->grid.begin(), spec->grid.end(),
                   [&](const SweepAxis& a) { return a.key == spec->plot_x; })) {
    plot.Child("x").Fail("not a grid key");
  }
}

int ParseBootstrapResamples(const ConfigNode& b) {
  const int resamples = b.AsInt();
  if (resamples < 100 || resamples > 100000) b.Fail("must be between 100 and 100000");
  return resamples;
}

// Checks that need the whole file: the run count, and that a gate's point is one of the grid's.
void CheckSweepSize(const ConfigNode& root, const SweepSpec& spec) {
  // Every partial product stays at most kMaxRuns, so none can wrap (64 keys of two values
  // would make 2^64, that is 0).
  size_t runs = spec.seeds.size();
  for (const SweepAxis& a : spec.grid) {
    if (a.values.size() > kMaxRuns / runs) {
      root.Fail("more than 1000000 runs (seeds times the grid's points)");
    }
    runs *= a.values.size();
  }
  const std::vector<SweepPoint> expanded = ExpandPoints(spec);
  for (const SweepGate& g : spec.gates) {
    if (g.point.empty()) continue;
    if (std::none_of(expanded.begin(), expanded.end(),
                     [&](const SweepPoint& p) { return p.name == g.point; })) {
      throw InputError(g.where + ": gate '" + g.name + "': point '" + CapForMessage(g.point) +
                       "' is not a point of this sweep");
    }
  }
}

}  // namespace

Statistic ParseStatistic(const std::string& text, const std::string& where) {
  Statistic s;
  s.text = text;
  const std::string t = Trim(text);
  const size_t open = t.find('(');
  const auto fail = [&](const std::string& why) {
    throw InputError(where + ": metric '" + CapForMessage(text) + "': " + why +
                     " (expected STAT(metric.path), STAT(ratio(A, B)) or "
                     "pass_fraction(GATE_NAME))");
  };
  if (open == std::string::npos || t.back() != ')') fail("not of the form STAT(ARG)");
  s.stat = Trim(t.substr(0, open));
  const std::string arg = Trim(t.substr(open + 1, t.size() - open - 2));
  s.of_gate = GateStats().count(s.stat) > 0;
  if (!s.of_gate && !ValueStats().count(s.stat)) fail("unknown statistic '" + s.stat + "'");
  if (arg.rfind("ratio(", 0) == 0) {
    if (s.of_gate) fail(s.stat + " takes a scenario gate's name, not a ratio");
    if (arg.back() != ')') fail("ratio( is not closed");
    const std::string inner = arg.substr(6, arg.size() - 7);
    const size_t comma = inner.find(',');
    if (comma == std::string::npos) fail("ratio takes two metric paths: ratio(A, B)");
    s.path = Trim(inner.substr(0, comma));
    s.divisor = Trim(inner.substr(comma + 1));
    if (!IsPath(s.path) || !IsPath(s.divisor)) fail("ratio's arguments must be metric paths");
  } else {
    s.path = arg;
    if (!IsPath(s.path)) fail("'" + CapForMessage(arg) + "' is not a metric path or gate name");
  }
  return s;
}

bool ParseRunFiles(const std::string& text, const std::string& option) {
  if (text == "all") return true;
  if (text == "summary") return false;
  throw InputError(option + " '" + CapForMessage(text) + "': expected all or summary");
}

SweepSpec LoadSweep(const std::string& path) {
  const ConfigNode root = ConfigNode::LoadFile(path);
  SweepSpec spec;
  spec.file = path;
  spec.name = ParseSweepName(root.Child("sweep"));
  spec.description = root.GetString("description", "");
  spec.scenario = root.ResolvePath(root.GetString("scenario"));
  spec.seeds = ParseSeeds(root.Child("seeds"));
  if (const auto set = root.Optional("set")) spec.set = ParseFixedSet(*set);
  if (const auto grid = root.Optional("grid")) spec.grid = ParseGrid(*grid);
  if (const auto gates = root.Optional("gates")) spec.gates = ParseGates(*gates);
  if (const auto plot = root.Optional("plot")) ParsePlot(*plot, &spec);
  if (const auto b = root.Optional("bootstrap_resamples")) {
    spec.bootstrap_resamples = ParseBootstrapResamples(*b);
  }
  if (const auto f = root.Optional("run_files")) {
    try {
      spec.run_data_files = ParseRunFiles(f->AsString(), "run_files");
    } catch (const InputError& e) {
      f->Fail(e.what());
    }
  }
  if (const auto f = root.Optional("frames")) {
    try {
      spec.frames = ParseFrameOutput(f->AsString(), "frames");
    } catch (const InputError& e) {
      f->Fail(e.what());
    }
  }
  root.CheckNoUnknownKeys();
  CheckSweepSize(root, spec);
  return spec;
}

std::vector<SweepPoint> ExpandPoints(const SweepSpec& spec) {
  std::vector<SweepPoint> points(1);
  for (const SweepAxis& axis : spec.grid) {
    std::vector<SweepPoint> next;
    for (const SweepPoint& p : points) {
      for (const std::string& v : axis.values) {
        SweepPoint q = p;
        q.set.push_back(axis.key + "=" + v);
        q.values.push_back(v);
        q.name += (q.name.empty() ? "" : "__") + FolderSafe(axis.key + "=" + v);
        next.push_back(q);
      }
    }
    points = next;
  }
  for (size_t i = 0; i < points.size(); ++i) {
    if (points[i].name.empty()) points[i].name = "base";
    // Long or colliding names (values that differ only in unsafe characters) get an index.
    if (points[i].name.size() > 120) points[i].name = "p" + std::to_string(i);
  }
  std::set<std::string> seen;
  for (size_t i = 0; i < points.size(); ++i) {
    if (!seen.insert(points[i].name).second) {
      points[i].name = "p" + std::to_string(i) + "__" + points[i].name;
      seen.insert(points[i].name);
    }
  }
  return points;
}

std::vector<SweepRun> ExpandRuns(const SweepSpec& spec, const std::vector<SweepPoint>& points) {
  std::vector<SweepRun> runs;
  for (size_t p = 0; p < points.size(); ++p) {
    for (std::uint64_t seed : spec.seeds) {
      runs.push_back({p, seed, "runs/" + points[p].name + "/seed_" + std::to_string(seed)});
    }
  }
  return runs;
}

}  // namespace flexbench::scenarios::sweep
