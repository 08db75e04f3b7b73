#include "scenarios/runner/summary_command.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <utility>

#include "estimators/error.h"
#include "scenarios/runner/report.h"
#include "scenarios/runner/runner.h"
#include "sim/config.h"

namespace fs = std::filesystem;

namespace flexbench::scenarios {
namespace {

struct Unit {
  const char* suffix;
  double scale;
  const char* shown;
};

// The suffixes the scenarios' metric names use, longest first where one ends another.
constexpr Unit kUnits[] = {{"_mm", 1.0, "mm"},     {"_px", 1.0, "px"},    {"_deg", 1.0, "deg"},
                           {"_mrad", 1.0, "mrad"}, {"_rad", 1e3, "mrad"}, {"_pct", 1.0, "%"},
                           {"_frac", 1e2, "%"},    {"_s", 1.0, "s"},      {"_m", 1e3, "mm"}};

bool EndsWith(const std::string& s, const std::string& end) {
  return s.size() > end.size() && s.compare(s.size() - end.size(), end.size(), end) == 0;
}

// The metric's own name: the last dotted part of the path, inside any statistic's brackets
// ("mean(estimators.fk.metrics.err_m)" -> "err_m").
std::string LeafName(const std::string& metric) {
  size_t end = metric.size();
  while (end > 0 &&
         !(std::isalnum(static_cast<unsigned char>(metric[end - 1])) || metric[end - 1] == '_')) {
    --end;
  }
  size_t start = end;
  while (start > 0 && (std::isalnum(static_cast<unsigned char>(metric[start - 1])) ||
                       metric[start - 1] == '_')) {
    --start;
  }
  return metric.substr(start, end - start);
}

const Unit* UnitOf(const std::string& leaf) {
  for (const Unit& u : kUnits) {
    if (EndsWith(leaf, u.suffix)) return &u;
  }
  return nullptr;
}

// What the metric is about: the estimator it belongs to, if any, and its name without the
// unit.
std::string Label(const std::string& metric, const std::string& leaf, const Unit* unit) {
  std::string label = unit ? leaf.substr(0, leaf.size() - std::string(unit->suffix).size()) : leaf;
  const std::string key = "estimators.";
  const size_t at = metric.find(key);
  if (at != std::string::npos) {
    const size_t start = at + key.size();
    const size_t dot = metric.find('.', start);
    if (dot != std::string::npos) label = metric.substr(start, dot - start) + " " + label;
  }
  return label;
}

bool IsNumber(const Json& v) { return v.is_number() && !v.is_boolean(); }

std::string Size(std::uintmax_t bytes) {
  char b[32];
  if (bytes < (1u << 20)) {
    std::snprintf(b, sizeof(b), "%.0f KB", bytes / 1024.0);
  } else {
    std::snprintf(b, sizeof(b), "%.1f MB", bytes / 1048576.0);
  }
  return b;
}

std::uintmax_t FolderBytes(const fs::path& dir) {
  std::uintmax_t total = 0;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    std::error_code size_ec;
    if (it->is_regular_file(size_ec)) {
      const std::uintmax_t n = it->file_size(size_ec);
      if (!size_ec) total += n;
    }
  }
  return total;
}

// A run's timing.total_s; -1 when its summary does not hold one.
double RunSeconds(const Json& summary) {
  if (!summary.contains("timing") || !summary["timing"].is_object()) return -1;
  const Json& timing = summary["timing"];
  return timing.contains("total_s") && IsNumber(timing["total_s"]) ? timing["total_s"].get<double>()
                                                                   : -1;
}

// The runs' own times, summed over the run folders below `dir` (a sweep's work, not its wall
// time: its runs share the cores).
double RunSecondsInside(const fs::path& dir) {
  double total = 0.0;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    if (it->path().filename() != "summary.json") continue;
    try {
      total += std::max(0.0, RunSeconds(ReadResultJson(it->path())));
    } catch (const InputError&) {
      // A run that is not a result adds no time; collect has already reported it.
    }
  }
  return total;
}

// j[key] when it is a string, else `otherwise`: a result of the wrong shape is still listed.
std::string Text(const Json& j, const char* key, const std::string& otherwise) {
  return j.contains(key) && j[key].is_string() ? j[key].get<std::string>() : otherwise;
}

void CountGates(const Json& gates, ResultRow* row) {
  if (!gates.is_array()) return;
  for (const Json& g : gates) {
    if (!g.is_object()) continue;
    ++row->gates_total;
    if (g.contains("passed") && g["passed"].is_boolean() && g["passed"].get<bool>()) {
      ++row->gates_passed;
    }
  }
}

}  // namespace

std::string Headline(const Json& gates) {
  if (!gates.is_array()) return "";
  const Json* chosen = nullptr;
  for (const bool need_unit : {true, false}) {
    for (const Json& g : gates) {
      if (!g.is_object() || !g.contains("value") || !IsNumber(g["value"])) continue;
      if (!g.contains("metric") || !g["metric"].is_string()) continue;
      if (need_unit && !UnitOf(LeafName(g["metric"].get<std::string>()))) continue;
      chosen = &g;
      break;
    }
    if (chosen) break;
  }
  if (!chosen) return "";
  // A sweep's statistic wraps the metric: "ci_high(ratio(a_m, b_m))" is about a; a ratio and
  // the fraction of runs passing a gate have no unit.
  const std::string text = (*chosen)["metric"].get<std::string>();
  std::string statistic;
  size_t open = 0;
  for (size_t p = text.find('('); p != std::string::npos; p = text.find('(', open)) {
    statistic += text.substr(open, p - open) + " ";
    open = p + 1;
  }
  const std::string metric = text.substr(open, text.find_first_of(",)", open) - open);
  const std::string leaf = LeafName(metric);
  const bool unitless = statistic.find("ratio") != std::string::npos ||
                        statistic.find("pass_fraction") != std::string::npos;
  const Unit* unit = unitless ? nullptr : UnitOf(leaf);
  const double v = (*chosen)["value"].get<double>() * (unit ? unit->scale : 1.0);
  char b[48];
  std::snprintf(b, sizeof(b), "%.3g", v);
  return statistic + Label(metric, leaf, unit) + " " + b +
         (unit ? std::string(" ") + unit->shown : "");
}

ResultRow ReadResultRow(const fs::path& dir) {
  ResultRow row;
  row.folder = dir.string();
  std::error_code ec;
  Json j;
  if (fs::is_regular_file(dir / "summary.json", ec)) {
    j = ReadResultJson(dir / "summary.json");
    row.scenario = Text(j, "scenario", "(unnamed)");
    row.seconds = RunSeconds(j);
  } else if (fs::is_regular_file(dir / "aggregate.json", ec)) {
    j = ReadResultJson(dir / "aggregate.json");
    row.scenario = "sweep " + Text(j, "sweep", "(unnamed)");
    row.seconds = RunSecondsInside(dir);
    row.summed = true;
  } else {
    throw InputError(CapForMessage(row.folder) +
                     ": not a flexbench result (no summary.json or aggregate.json)");
  }
  const Json gates = j.contains("gates") ? j["gates"] : Json::array();
  CountGates(gates, &row);
  row.headline = Headline(gates);
  row.bytes = FolderBytes(dir);
  return row;
}

std::string FormatResultTable(const std::vector<ResultRow>& rows) {
  bool summed = false;
  std::vector<std::vector<std::string>> cells = {
      {"scenario", "gates", "headline", "time", "size", "folder"}};
  for (const ResultRow& r : rows) {
    char t[32] = "-";
    if (r.seconds >= 0) std::snprintf(t, sizeof(t), "%.1f s%s", r.seconds, r.summed ? "*" : "");
    summed = summed || r.summed;
    cells.push_back({r.scenario,
                     std::to_string(r.gates_passed) + "/" + std::to_string(r.gates_total) +
                         (r.gates_passed < r.gates_total ? " FAIL" : ""),
                     r.headline.empty() ? "-" : r.headline, t, Size(r.bytes), r.folder});
  }
  std::vector<size_t> width(cells[0].size(), 0);
  for (const auto& line : cells) {
    for (size_t c = 0; c < line.size(); ++c) width[c] = std::max(width[c], line[c].size());
  }
  std::string out;
  for (const auto& line : cells) {
    std::string text;
    for (size_t c = 0; c < line.size(); ++c) {
      std::string cell = line[c];
      if (c + 1 < line.size()) cell.resize(width[c] + 2, ' ');
      text += cell;
    }
    out += text + "\n";
  }
  if (summed) out += "* a sweep's time is the sum of its runs' times\n";
  return out;
}

std::string FormatResultTsv(const ResultRow& row) {
  return row.scenario + "\t" + std::to_string(row.gates_passed) + "\t" +
         std::to_string(row.gates_total) + "\t" + row.headline;
}

int SummaryCommand(const std::vector<std::string>& dirs, bool tsv) {
  try {
    std::vector<ResultRow> rows;
    for (const std::string& d : dirs) rows.push_back(ReadResultRow(d));
    if (tsv) {
      for (const ResultRow& r : rows) std::cout << FormatResultTsv(r) << "\n";
    } else {
      std::cout << FormatResultTable(rows);
    }
    return kExitOk;
  } catch (const std::exception& e) {
    return ReportError(e);
  }
}

}  // namespace flexbench::scenarios
