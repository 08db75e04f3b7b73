#include "scenarios/runner/report.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <utility>

#include "estimators/error.h"
#include "estimators/format.h"
#include "scenarios/runner/output.h"
#include "scenarios/runner/runner.h"
#include "scenarios/runner/scenario_kind.h"

namespace fs = std::filesystem;

namespace flexbench::scenarios {
namespace {

constexpr const char* kReportName = "report.html";

// Inline only: the page must render offline and identically everywhere.
constexpr const char* kStyle = R"(
body{font-family:sans-serif;margin:24px;color:#222;background:#fff;max-width:1400px}
h1{font-size:24px;margin:0 0 4px}h2{font-size:19px;margin:28px 0 8px;border-bottom:1px solid #ccc}
h3{font-size:16px;margin:18px 0 6px}
table{border-collapse:collapse;margin:6px 0 12px;font-size:13px}
th,td{border:1px solid #bbb;padding:3px 8px;text-align:left;vertical-align:top;max-width:36em;
overflow-wrap:anywhere}
th{background:#eef1f5}
td.num{text-align:right;font-family:monospace;white-space:nowrap;overflow-wrap:normal}
tr.pass td.verdict{background:#d8f0d8;color:#15561a;font-weight:bold}
tr.fail td.verdict{background:#f6d5d5;color:#8a1414;font-weight:bold}
pre{margin:0;background:#f4f4f4;border:1px solid #ddd;padding:8px;white-space:pre-wrap;
word-break:break-all}
figure{margin:12px 0 20px;padding:8px;border:1px solid #ddd;display:inline-block;max-width:96%;
vertical-align:top}
figure img{max-width:100%;max-height:900px;display:block}
figcaption{font-size:13px;margin-top:6px;color:#333}
table.kv td{max-width:none}table.kv th{white-space:nowrap}.scroll{overflow-x:auto}.muted{color:#666}
li{font-family:monospace;font-size:13px}
ul.answer li,ul.notes li,.warnings li{font-family:sans-serif;font-size:14px;margin:3px 0}
ul.notes li{font-size:13px;color:#333}table.answer{font-size:14px}
table.answer td:first-child{white-space:nowrap}
span.also{display:block;white-space:normal;max-width:24em;font-size:12px;color:#555}
p.verdict{font-size:16px;background:#eef4fb;border-left:4px solid #3a6ea5;padding:6px 10px}
.warnings{background:#fff3cd;border:2px solid #d39e00;padding:8px 12px;margin:10px 0}
details{margin:6px 0 12px}summary{cursor:pointer;color:#1a4d80}
)";

std::string Num(double v) {
  if (!std::isfinite(v)) return std::isnan(v) ? "NaN" : (v > 0 ? "inf" : "-inf");
  return ShortNum(v);
}

// A JSON value as table text (escaped): numbers to 6 significant digits, short arrays inline,
// null as a dash (what NaN becomes in JSON).
std::string Cell(const Json& v) {
  if (v.is_null()) return "&mdash;";
  if (v.is_boolean()) return v.get<bool>() ? "true" : "false";
  if (v.is_number_integer() || v.is_number_unsigned()) return v.dump();
  if (v.is_number()) return Num(v.get<double>());
  if (v.is_string()) return HtmlEscape(v.get<std::string>());
  if (v.is_array()) {
    constexpr size_t kShown = 8;
    std::string s = "[";
    for (size_t i = 0; i < v.size() && i < kShown; ++i) {
      s += (i ? ", " : "") + (v[i].is_structured() ? std::string("&hellip;") : Cell(v[i]));
    }
    if (v.size() > kShown) s += ", &hellip; (" + std::to_string(v.size()) + " values)";
    return s + "]";
  }
  return HtmlEscape(v.dump(-1, ' ', false, Json::error_handler_t::replace));
}

bool IsNumeric(const Json& v) { return v.is_number() || v.is_null(); }

std::string Td(const Json& v) {
  return std::string(IsNumeric(v) ? "<td class=\"num\">" : "<td>") + Cell(v) + "</td>";
}

// Leaves of `j` as ("a.b.c", value) in document order; arrays are leaves.
void Flatten(const Json& j, const std::string& prefix,
             std::vector<std::pair<std::string, Json>>* out) {
  if (!j.is_object()) {
    out->emplace_back(prefix, j);
    return;
  }
  for (auto it = j.begin(); it != j.end(); ++it) {
    Flatten(it.value(), prefix.empty() ? it.key() : prefix + "." + it.key(), out);
  }
}

// A result file as `flatten` and the tables use it: a JSON object, read within the caps of
// report.h. Deeper nesting is refused while parsing (the tables recurse through it).
Json ReadJson(const fs::path& path) {
  const std::string shown = CapForMessage(path.string());
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) throw InputError(shown + ": cannot read");
  if (!fs::is_regular_file(st)) throw InputError(shown + ": not a regular file");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) throw InputError(shown + ": cannot read: " + ec.message());
  if (size > kMaxResultJsonBytes) {
    throw InputError(shown + ": " + std::to_string(size) + " bytes, more than the " +
                     std::to_string(kMaxResultJsonBytes) + " a result file may have");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(shown + ": cannot read");
  std::stringstream ss;
  ss << in.rdbuf();
  Json j;
  try {
    j = Json::parse(ss.str(), [&shown](int depth, Json::parse_event_t, Json&) {
      if (depth > kMaxResultJsonDepth) {
        throw InputError(shown + ": nested more than " + std::to_string(kMaxResultJsonDepth) +
                         " levels deep");
      }
      return true;
    });
  } catch (const Json::parse_error& e) {
    throw InputError(shown + ": not JSON (" + e.what() + ")");
  }
  if (!j.is_object()) throw InputError(shown + ": expected a JSON object at the top level");
  return j;
}

// --- Shape checks ---------------------------------------------------------------------------
// The pages read result files leniently (a missing key is a dash), but a key of the wrong type
// would stop them with a JSON type error: it is bad input, named with its file and key.

[[noreturn]] void ShapeError(const fs::path& file, const std::string& key,
                             const std::string& expected) {
  throw InputError(CapForMessage(file.string()) + ": key '" + CapForMessage(key) + "': expected " +
                   expected);
}

// `j[key]`, when present, is a string.
void OptionalString(const Json& j, const std::string& key, const std::string& shown,
                    const fs::path& file) {
  if (j.contains(key) && !j[key].is_string()) ShapeError(file, shown, "a string");
}

// `j[key]`, when present, is an array of objects; `each` checks each one.
template <typename Each>
void OptionalObjects(const Json& j, const std::string& key, const fs::path& file, Each each) {
  if (!j.contains(key)) return;
  if (!j[key].is_array()) ShapeError(file, key, "a list");
  for (size_t i = 0; i < j[key].size(); ++i) {
    const std::string item = key + "[" + std::to_string(i) + "]";
    if (!j[key][i].is_object()) ShapeError(file, item, "an object");
    each(j[key][i], item);
  }
}

void CheckGateShape(const Json& g, const std::string& where, const fs::path& file) {
  if (g.contains("passed") && !g["passed"].is_boolean()) {
    ShapeError(file, where + ".passed", "true or false");
  }
}

void CheckRunShape(const Json& s, const fs::path& file) {
  OptionalString(s, "scenario", "scenario", file);
  OptionalObjects(s, "gates", file,
                  [&](const Json& g, const std::string& w) { CheckGateShape(g, w, file); });
}

// An object whose values are objects (a point's metrics, ratios, gates).
void CheckObjectOfObjects(const Json& p, const std::string& key, const std::string& where,
                          const fs::path& file) {
  if (!p.contains(key)) return;
  if (!p[key].is_object()) ShapeError(file, where + "." + key, "an object");
  for (auto it = p[key].begin(); it != p[key].end(); ++it) {
    if (!it.value().is_object()) ShapeError(file, where + "." + key + "." + it.key(), "an object");
  }
}

void CheckSweepShape(const Json& a, const fs::path& file) {
  OptionalString(a, "sweep", "sweep", file);
  if (a.contains("seeds") && !a["seeds"].is_array()) ShapeError(file, "seeds", "a list");
  OptionalObjects(a, "gates", file,
                  [&](const Json& g, const std::string& w) { CheckGateShape(g, w, file); });
  OptionalObjects(a, "failed", file, [](const Json&, const std::string&) {});
  OptionalObjects(a, "points", file, [&](const Json& p, const std::string& w) {
    if (p.contains("set") && !p["set"].is_object()) ShapeError(file, w + ".set", "an object");
    for (const char* key : {"gates", "metrics", "ratios"}) CheckObjectOfObjects(p, key, w, file);
  });
}

// --- The folder's files ---------------------------------------------------------------------

// No sizes: summary.json's varies with its wall-clock timing, and the page must not.
struct FileEntry {
  std::string rel;  // generic, relative to the folder
};

std::string Extension(const std::string& rel) {
  const size_t dot = rel.rfind('.');
  const size_t slash = rel.rfind('/');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string e = rel.substr(dot + 1);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

// Regular files under `dir`, sorted by path, without hidden files, temporaries (".part") and
// the report itself: the listing is the same in the run's temporary folder and afterwards.
std::vector<FileEntry> ListFiles(const fs::path& dir) {
  std::vector<FileEntry> files;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (!name.empty() && name[0] == '.') {
      if (it->is_directory(ec)) it.disable_recursion_pending();
      continue;
    }
    if (!it->is_regular_file(ec)) continue;
    FileEntry f;
    f.rel = it->path().lexically_relative(dir).generic_string();
    if (f.rel == kReportName || Extension(f.rel) == "part") continue;
    files.push_back(f);
  }
  std::sort(files.begin(), files.end(),
            [](const FileEntry& a, const FileEntry& b) { return a.rel < b.rel; });
  return files;
}

bool IsDataFile(const std::string& rel) {
  static const std::set<std::string> kData = {"csv", "tum",  "json", "yaml",
                                              "yml", "html", "txt",  "log"};
  return kData.count(Extension(rel)) > 0;
}

// What a figure shows, for the file names the kinds write (docs/scenarios.md, "What each kind
// writes").
std::string FigureDescription(const std::string& rel) {
  static const std::pair<const char*, const char*> kKnown[] = {
      {"config_",
       "the rendered camera image with the detections, truth axes and each "
       "estimate's 95% position ellipse"},
      {"lateral_error", "Table I: lateral error per estimator beside the paper's values"},
      {"fig5_contact", "error and covariance over the contact iterations"},
      {"loop",
       "each estimator's mean position error with the declared and with the augmented model "
       "(log axis, values in mm)"},
      {"residual_before_after",
       "residual against the quantity that exposed the first chosen "
       "effect, before and after"},
      {"residual_structure", "the residual's structure per joint"},
      {"matrix", "error and NEES per estimator and mismatch effect"},
      {"deflection", "the hand's deflection per configuration"},
      {"sweep_", "a rendered frame of the detection sweep"},
      {"sweep", "mean over seeds with its 95% bootstrap confidence interval"},
      {"smoke", "the rendered tag with detected and true corners"},
      {"fig6_",
       "joint estimates with their 95% bands against the simulated truth and the "
       "commanded reference"},
      {"fig8_gripper_error",
       "each estimator's gripper position error against MuJoCo's grasp point (the truth), and "
       "the commanded postures"},
      {"fig8_",
       "joint estimates with their 95% bands against the commanded reference angles; the "
       "flexible arm bends between its joints, so there is no true joint angle to draw: its "
       "truth is the gripper's position (fig8_gripper_error.png)"},
      {"dynamic_residual",
       "the channel the chosen effects helped most: its residual spectrum, and an encoder's "
       "residual in time, with the declared model and with the effects"},
      {"fig9_direct_fusion", "the gripper's height per estimator and the reference joint angles"},
      {"fig9_", "joint estimates with their 95% bands against the commanded reference angles"},
      {"fig10_yaw_drift", "the IMU orientation filter's yaw drift against the truth"},
      {"fig10_",
       "joint estimates with their 95% bands against the simulated truth and the "
       "commanded reference"},
  };
  const std::string name = fs::path(rel).filename().string();
  for (const auto& [prefix, text] : kKnown) {
    if (name.rfind(prefix, 0) == 0) return text;
  }
  return "";
}

// --- Page parts -----------------------------------------------------------------------------

void Head(const std::string& title, std::ostringstream* h) {
  *h << "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
     << "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
     << "<title>" << HtmlEscape(title) << "</title>\n<style>" << kStyle << "</style>\n"
     << "</head>\n<body>\n";
}

void Tail(const std::string& source, std::ostringstream* h) {
  *h << "<p class=\"muted\">Made by flexbench " << HtmlEscape(FLEXBENCH_VERSION) << " from "
     << HtmlEscape(source) << "; <code>flexbench report DIR</code> makes it again.</p>\n"
     << "</body>\n</html>\n";
}

// A two-column table of key/value rows; its cells are not width-capped (a long command stays on
// as few lines as the page allows).
void KeyValueTable(const std::vector<std::pair<std::string, std::string>>& rows,
                   std::ostringstream* h) {
  *h << "<table class=\"kv\">\n";
  for (const auto& [key, html] : rows) {
    *h << "<tr><th>" << HtmlEscape(key) << "</th><td>" << html << "</td></tr>\n";
  }
  *h << "</table>\n";
}

std::string Code(const std::string& text) { return "<code>" + HtmlEscape(text) + "</code>"; }

// The gates of a run or a sweep: one row each with its verdict as a word, not only a colour.
void GateTable(const Json& gates, bool with_point, std::ostringstream* h) {
  if (!gates.is_array() || gates.empty()) {
    *h << "<p class=\"muted\">No gates.</p>\n";
    return;
  }
  int passed = 0;
  for (const Json& g : gates) passed += g.value("passed", false) ? 1 : 0;
  *h << "<p>" << passed << " of " << gates.size() << " gates passed.</p>\n";
  *h << "<div class=\"scroll\"><table>\n<tr><th>gate</th>" << (with_point ? "<th>point</th>" : "")
     << "<th>metric</th><th>value</th><th>op</th><th>threshold</th><th>result</th></tr>\n";
  for (const Json& g : gates) {
    const bool ok = g.value("passed", false);
    *h << "<tr class=\"" << (ok ? "pass" : "fail") << "\"><td>" << Cell(g.value("name", Json()))
       << "</td>";
    if (with_point) *h << "<td>" << Cell(g.value("point", Json())) << "</td>";
    *h << "<td>" << Cell(g.value("metric", Json())) << "</td>" << Td(g.value("value", Json()))
       << "<td>" << Cell(g.value("op", Json())) << "</td>" << Td(g.value("threshold", Json()))
       << "<td class=\"verdict\">" << (ok ? "PASS" : "FAIL") << "</td></tr>\n";
  }
  *h << "</table></div>\n";
}

void FlatTable(const Json& j, std::ostringstream* h) {
  std::vector<std::pair<std::string, Json>> rows;
  Flatten(j, "", &rows);
  *h << "<div class=\"scroll\"><table>\n<tr><th>metric</th><th>value</th></tr>\n";
  for (const auto& [key, v] : rows) {
    *h << "<tr><td>" << HtmlEscape(key) << "</td>" << Td(v) << "</tr>\n";
  }
  *h << "</table></div>\n";
}

// Estimators side by side: a row per metric (the union, in first-seen order), a column each.
void EstimatorTable(const Json& estimators, std::ostringstream* h) {
  std::vector<std::string> names, keys;
  std::vector<std::map<std::string, Json>> values;
  std::set<std::string> seen;
  for (auto it = estimators.begin(); it != estimators.end(); ++it) {
    names.push_back(it.key());
    std::vector<std::pair<std::string, Json>> rows;
    Flatten(it.value(), "", &rows);
    values.emplace_back();
    for (auto& [path, v] : rows) {
      // Every estimator's metrics are under "metrics.": left out for shorter rows.
      const std::string key = path.rfind("metrics.", 0) == 0 ? path.substr(8) : path;
      if (seen.insert(key).second) keys.push_back(key);
      values.back()[key] = v;
    }
  }
  *h << "<div class=\"scroll\"><table>\n<tr><th>metric</th>";
  for (const std::string& n : names) *h << "<th>" << HtmlEscape(n) << "</th>";
  *h << "</tr>\n";
  for (const std::string& key : keys) {
    *h << "<tr><td>" << HtmlEscape(key) << "</td>";
    for (const auto& col : values) {
      const auto it = col.find(key);
      *h << (it == col.end() ? std::string("<td></td>") : Td(it->second));
    }
    *h << "</tr>\n";
  }
  *h << "</table></div>\n";
}

void Figures(const std::vector<FileEntry>& files, bool top_level_only, std::ostringstream* h) {
  int n = 0;
  for (const FileEntry& f : files) {
    if (Extension(f.rel) != "png") continue;
    if (top_level_only && f.rel.find('/') != std::string::npos) continue;
    const std::string src = HtmlEscape(UrlPath(f.rel));
    const std::string description = FigureDescription(f.rel);
    ++n;
    *h << "<figure><a href=\"" << src << "\"><img src=\"" << src << "\" alt=\"" << HtmlEscape(f.rel)
       << "\"></a><figcaption>Figure " << n << ": <code>" << HtmlEscape(f.rel) << "</code>"
       << (description.empty() ? "" : " &mdash; ") << HtmlEscape(description)
       << "</figcaption></figure>\n";
  }
  if (n == 0) *h << "<p class=\"muted\">No figures.</p>\n";
}

// Links to the data files; `keep` chooses which.
template <typename Keep>
void FileLinks(const std::vector<FileEntry>& files, Keep keep, std::ostringstream* h) {
  *h << "<ul>\n";
  for (const FileEntry& f : files) {
    if (!IsDataFile(f.rel) || !keep(f.rel)) continue;
    *h << "<li><a href=\"" << HtmlEscape(UrlPath(f.rel)) << "\">" << HtmlEscape(f.rel)
       << "</a></li>\n";
  }
  *h << "</ul>\n";
}

// --- The answer: what a run found, how sure, how much better, what is left -----------------

constexpr double kPi = 3.14159265358979323846;

// Fmt of one number, a non-finite one spelled as Num spells it.
std::string FmtNum(const char* format, double v) {
  return std::isfinite(v) ? Fmt(format, v) : Num(v);
}

// `j[key]` when `j` is an object holding it, else null.
const Json& At(const Json& j, const std::string& key) {
  static const Json kNull;
  if (!j.is_object()) return kNull;
  const auto it = j.find(key);
  return it == j.end() ? kNull : *it;
}

double Number(const Json& v) {
  return v.is_number() ? v.get<double>() : std::numeric_limits<double>::quiet_NaN();
}

std::string Text(const Json& v) {
  return v.is_string() ? v.get<std::string>() : v.is_null() ? std::string() : v.dump();
}

// A list of names ("a + b") from a JSON array of strings (or one string).
std::string Joined(const Json& v, const char* sep) {
  if (!v.is_array()) return Text(v);
  std::string s;
  for (const Json& e : v) s += (s.empty() ? "" : sep) + Text(e);
  return s;
}

// An identification's metric: a closed_loop run's `metrics.KEY`, or the copy a kind that runs
// identification inside it keeps as `metrics.identification_KEY`.
const Json& IdMetric(const Json& s, const std::string& key) {
  const Json& m = At(s, "metrics");
  const Json& v = At(m, key);
  return v.is_null() ? At(m, "identification_" + key) : v;
}

// The verdict in words (docs/identification.md, "Verdicts").
std::string VerdictWords(const std::string& verdict) {
  static const std::pair<const char*, const char*> kWords[] = {
      {"explained",
       "the fitted effects remove the error on held-out data, no structure is left in the "
       "residual, and no alternative set of effects at most as complex does as well."},
      {"ambiguous",
       "the correction holds on held-out data and is shipped, but its cause is not singled out: "
       "with a chosen effect banned, other effects (listed below) do about as well."},
      {"partly_explained",
       "the held-out error drops, but structure remains in the residual (see what is left): the "
       "correction is shipped, the model is not complete."},
      {"unexplained",
       "nothing the candidates offer lowers the held-out error, or structure remains that no "
       "candidate explains; no augmented model is written."},
      {"no_effect", "nothing was found and nothing beyond the stated noise is left."},
  };
  for (const auto& [name, words] : kWords) {
    if (verdict == name) return words;
  }
  return "";
}

// An SI unit and a more readable one for tables: rad as deg, m as mm.
struct Shown {
  double scale = 1.0;
  std::string unit;
};

Shown Readable(const std::string& si) {
  if (si == "rad") return {180.0 / kPi, "deg"};
  if (si == "m") return {1e3, "mm"};
  if (si == "rad/Nm") return {180.0 / kPi, "deg/Nm"};
  return {1.0, si};
}

// The unit of parameter `i` of `n`: "m, rad" over six parameters is [rho; theta].
std::string ParamUnit(const std::string& unit, size_t i, size_t n) {
  const size_t comma = unit.find(", ");
  if (comma == std::string::npos) return unit;
  return i < n / 2 ? unit.substr(0, comma) : unit.substr(comma + 2);
}

// One row per identified effect: each parameter's value and std in the fit's unit and in a
// readable one, and the value in stds.
void EffectsTable(const Json& effects, std::ostringstream* h) {
  *h << "<table class=\"answer\">\n<tr><th>effect</th><th>fitted value &plusmn; std</th>"
        "<th>the same in</th><th>|value| / std</th><th>share of the correction</th></tr>\n";
  for (const Json& e : effects) {
    const Json& value = At(e, "value");
    const Json& stdev = At(e, "std");
    const std::string unit = Text(At(e, "unit"));
    std::string si, shown, z;
    const size_t n = value.is_array() ? value.size() : 1;
    for (size_t i = 0; i < n; ++i) {
      const double v = Number(value.is_array() ? value[i] : value);
      const double s = Number(stdev.is_array() && i < stdev.size() ? stdev[i] : stdev);
      const std::string u = ParamUnit(unit, i, n);
      const Shown r = Readable(u);
      const char* br = i ? "<br>" : "";
      si += br + Num(v) + " &plusmn; " + Num(s) + " " + HtmlEscape(u);
      shown += br + FmtNum("%.4g", r.scale * v) + " &plusmn; " + FmtNum("%.2g", r.scale * s) + " " +
               HtmlEscape(r.unit);
      // A direction the data do not determine is reported as 0 +- 0: no ratio.
      z += br + (s > 0.0 ? FmtNum("%.3g", std::abs(v) / s) : std::string("&mdash;"));
    }
    // An equivalence set's name lists its members, the reported one first.
    const std::string name = Text(At(e, "effect"));
    const size_t bar = name.find(" | ");
    std::string shown_name = "<b>" + HtmlEscape(name.substr(0, bar)) + "</b>";
    if (bar != std::string::npos) {
      std::string others = name.substr(bar + 3);
      for (size_t p = others.find(" | "); p != std::string::npos; p = others.find(" | ", p)) {
        others.replace(p, 3, ", ");
      }
      shown_name += "<span class=\"also\">the same correction as " + HtmlEscape(others) + "</span>";
    }
    *h << "<tr><td>" << shown_name << "</td><td class=\"num\">" << si << "</td><td class=\"num\">"
       << shown << "</td><td class=\"num\">" << z << "</td><td class=\"num\">"
       << FmtNum("%.3g", Number(At(e, "share"))) << "</td></tr>\n";
  }
  *h << "</table>\n";
}

// The units an identification's errors come in (closed_loop's metric suffixes), as shown.
const std::pair<const char*, Shown> kErrorUnits[] = {
    {"_m", {1e3, "mm"}}, {"_px", {1.0, "px"}}, {"_gravity_deg", {1.0, "deg (gravity)"}}};

// One line under the verdict, so a long table of effects leaves the answer in view: how many
// effects, and the held-out error before and after.
void Headline(const Json& s, const Json& effects, std::ostringstream* h) {
  size_t params = 0;
  for (const Json& e : effects) params += At(e, "value").is_array() ? At(e, "value").size() : 1;
  *h << "<p>" << effects.size() << " effect" << (effects.size() == 1 ? "" : "s") << " found ("
     << params << " parameter" << (params == 1 ? "" : "s") << ")";
  for (const auto& [suffix, shown] : kErrorUnits) {
    const double b = Number(IdMetric(s, std::string("val_err_before") + suffix));
    const double a = Number(IdMetric(s, std::string("val_err_after") + suffix));
    if (!std::isfinite(b) || !std::isfinite(a)) continue;
    *h << "; the held-out error goes from " << FmtNum("%.4g", shown.scale * b) << " " << shown.unit
       << " to " << FmtNum("%.4g", shown.scale * a) << " " << shown.unit << " ("
       << FmtNum("%.3g", a / b) << " of it)";
    break;
  }
  *h << ".</p>\n";
}

// Errors before and after on the held-out and the calibration rows, in their own units (metre
// errors as mm), and the cross-validated held-out error in units of the stated noise.
void BetterTable(const Json& s, std::ostringstream* h) {
  struct Row {
    const char* data;
    const char* key;  // before/after around it: val_err_{before,after}<suffix>
  };
  static const Row kRows[] = {{"held-out (validation) rows", "val_err"},
                              {"calibration rows", "cal_err"}};
  std::ostringstream rows;
  for (const Row& r : kRows) {
    for (const auto& [suffix, shown] : kErrorUnits) {
      const double b = Number(IdMetric(s, std::string(r.key) + "_before" + suffix));
      const double a = Number(IdMetric(s, std::string(r.key) + "_after" + suffix));
      if (!std::isfinite(b) && !std::isfinite(a)) continue;
      rows << "<tr><td>" << r.data << "</td><td class=\"num\">" << FmtNum("%.4g", shown.scale * b)
           << " " << shown.unit << "</td><td class=\"num\">" << FmtNum("%.4g", shown.scale * a)
           << " " << shown.unit << "</td><td class=\"num\">" << FmtNum("%.3g", a / b)
           << "</td></tr>\n";
    }
  }
  const double cb = Number(IdMetric(s, "cv_err_before")), ca = Number(IdMetric(s, "cv_err_after"));
  if (std::isfinite(cb) || std::isfinite(ca)) {
    rows << "<tr><td>held-out folds (cross-validation)</td><td class=\"num\">" << FmtNum("%.4g", cb)
         << " &sigma;&sup2;</td><td class=\"num\">" << FmtNum("%.4g", ca)
         << " &sigma;&sup2;</td><td class=\"num\">" << FmtNum("%.3g", ca / cb) << "</td></tr>\n";
  }
  if (rows.str().empty()) return;
  *h << "<h3>How much better</h3>\n<table class=\"answer\">\n<tr><th>mean error on</th>"
        "<th>declared model</th><th>identified model</th><th>after / before</th></tr>\n"
     << rows.str()
     << "</table>\n<p class=\"muted\">&sigma;&sup2;: the mean squared residual "
        "in units of the stated noise (1: the noise alone).</p>\n";
}

// Which source directions the augmented model scaled: those the rows constrain; the others
// keep their declared size (metrics.source_scaling).
std::string ScaledSources(const Json& scaling) {
  const Json& on = At(scaling, "constrained");
  const Json& kept = At(scaling, "kept_declared");
  if (!on.is_array() || !kept.is_array()) return "them";
  const auto names = [](const Json& list) {
    std::string out;
    for (const Json& n : list) out += (out.empty() ? "" : ", ") + HtmlEscape(Text(n));
    return out;
  };
  std::string text = "the " + std::to_string(on.size()) + " source direction(s) the rows constrain";
  if (!kept.empty()) {
    text += " (" + names(on) + "; kept as declared, unseen by the rows: " + names(kept) + ")";
  }
  return text;
}

// Alternatives, near-equivalent effects and the augmented model's uncertainty.
void HowSure(const Json& s, const Json& id, std::ostringstream* h) {
  std::ostringstream items;
  const double chosen = Number(IdMetric(s, "cv_err_after"));
  const Json& also = At(id, "also_fits");
  const auto in_also = [&](const Json& a) {
    if (!also.is_array()) return false;
    return std::any_of(also.begin(), also.end(), [&](const Json& b) {
      return At(b, "banned") == At(a, "banned") && At(b, "effects") == At(a, "effects");
    });
  };
  for (const Json& a : At(id, "alternatives")) {
    if (in_also(a)) continue;
    const Json& effects = At(a, "effects");
    const std::string error =
        " reach a held-out error of " + FmtNum("%.4g", Number(At(a, "cv_err"))) + " &sigma;&sup2;" +
        (std::isfinite(chosen) ? " (the chosen model: " + FmtNum("%.4g", chosen) + " &sigma;&sup2;)"
                               : std::string());
    const std::string without = "Without <code>" + HtmlEscape(Text(At(a, "banned"))) + "</code>: ";
    const std::string list = "<code>" + HtmlEscape(Joined(effects, " + ")) + "</code>";
    // A long list folds: the numbers stay on one line.
    if (effects.is_array() && effects.size() > 4) {
      items << "<li><details><summary>" << without << effects.size() << " effects" << error
            << "</summary>" << list << "</details></li>\n";
    } else {
      items << "<li>" << without << list << error << ".</li>\n";
    }
  }
  if (also.is_array()) {
    for (const Json& a : also) {
      items << "<li>Also fits: <code>" << HtmlEscape(Joined(At(a, "effects"), " + "))
            << "</code> in place of <code>" << HtmlEscape(Text(At(a, "banned")))
            << "</code> reaches " << FmtNum("%.4g", Number(At(a, "cv_err")))
            << " &sigma;&sup2; with " << Cell(At(a, "num_params")) << " parameters instead of "
            << Cell(At(a, "chosen_num_params"))
            << ": as good but more complex, so no evidence against the simpler cause.</li>\n";
    }
  }
  for (const Json& set : At(id, "equivalence_sets")) {
    if (At(set, "members").size() < 2) continue;
    items << "<li>Indistinguishable on this data: <code>" << HtmlEscape(Text(At(set, "name")))
          << "</code> (the same correction; the first is reported).</li>\n";
  }
  const Json& simpler = At(id, "simpler_equivalents");
  if (simpler.is_array() && !simpler.empty()) {
    items << "<li>Chosen effects that together equal a simpler one: <code>"
          << HtmlEscape(Joined(simpler, ", ")) << "</code>.</li>\n";
  }
  if (IdMetric(s, "near_singular") == Json(true)) {
    items << "<li>The fit is near-singular: it does not determine <code>"
          << HtmlEscape(Text(At(id, "undetermined"))) << "</code>.</li>\n";
  }
  const double nb = Number(IdMetric(s, "nees_before")), na = Number(IdMetric(s, "nees_after"));
  const double lo = Number(IdMetric(s, "nees_bound_low")),
               hi = Number(IdMetric(s, "nees_bound_high"));
  if (std::isfinite(na) && std::isfinite(lo)) {
    items << "<li>Uncertainty: the validation rows' mean NEES is " << FmtNum("%.3g", nb)
          << " under the declared model and " << FmtNum("%.3g", na)
          << " under the identified one, with the declared PPOE sources (a consistent model: "
          << FmtNum("%.3g", lo) << " to " << FmtNum("%.3g", hi) << ", 95%)"
          << (na < lo   ? ": below it, the declared sources are larger than the error left"
              : na > hi ? ": above it, the declared sources are smaller than the error left"
                        : "")
          << ". The augmented model scales " << ScaledSources(IdMetric(s, "source_scaling"))
          << " by " << FmtNum("%.3g", Number(IdMetric(s, "source_covariance_scale")))
          << " (mean NEES then " << FmtNum("%.3g", Number(IdMetric(s, "nees_after_scaled")))
          << ").</li>\n";
  }
  if (items.str().empty()) return;
  *h << "<h3>How sure</h3>\n<ul class=\"answer\">\n" << items.str() << "</ul>\n";
}

void WhatIsLeft(const Json& s, std::ostringstream* h) {
  std::ostringstream items;
  const Json& f = IdMetric(s, "residual_finding");
  if (f.is_object() && !Text(At(f, "message")).empty()) {
    const bool sig = At(f, "significant") == Json(true);
    items << "<li>" << (sig ? "<b>Structure left</b>: " : "Largest structure tested: ")
          << HtmlEscape(Text(At(f, "message")))
          << (sig ? "" : " &mdash; not significant, within the noise") << ".</li>\n";
  }
  const double ratio = Number(IdMetric(s, "cal_residual_noise_ratio"));
  if (std::isfinite(ratio)) {
    items << "<li>The calibration residual after the fit is " << FmtNum("%.3g", ratio)
          << " times the stated noise (1: all of it is noise).</li>\n";
  }
  if (IdMetric(s, "sources_cover_residual") == Json(false)) {
    items << "<li><b>The declared uncertainty sources cannot cover what the effects leave</b> "
             "(the NEES stays above its bound at the largest source scale).</li>\n";
  }
  const Json& un = IdMetric(s, "unidentifiable");
  if (un.is_array() && !un.empty()) {
    items << "<li><details><summary>" << un.size()
          << " candidates this data cannot identify (their sensitivity lies within the chosen "
             "effects and nuisance unknowns)</summary><code>"
          << HtmlEscape(Joined(un, ", ")) << "</code></details></li>\n";
  }
  const Json& skipped = IdMetric(s, "skipped_candidates");
  if (skipped.is_array() && !skipped.empty()) {
    items << "<li>" << skipped.size() << " candidate" << (skipped.size() == 1 ? "" : "s")
          << " not offered at their location (<code>metrics.skipped_candidates</code>).</li>\n";
  }
  if (items.str().empty()) return;
  *h << "<h3>What is left</h3>\n<ul class=\"answer\">\n" << items.str() << "</ul>\n";
}

// The calibrated model files the run wrote, and how to load them.
void ModelLinks(const Json& id, const std::vector<FileEntry>& files, std::ostringstream* h) {
  static const struct {
    const char* name;
    const char* what;
    const char* not_held;  // identification.calibrated_model's list of what it lacks
  } kModels[] = {
      {"declared_augmented.yaml",
       "the declared model with the identified effects and their stds (flexbench's estimators)",
       ""},
      {"calibrated_model.xml",
       "MJCF for MuJoCo: <code>simulate calibrated_model.xml</code> (Debian: "
       "<code>mujoco-simulate</code>)",
       "not_in_mjcf"},
      {"calibrated_model.urdf", "URDF", "not_in_urdf"}};
  const Json& cm = At(id, "calibrated_model");
  std::ostringstream links;
  for (const auto& m : kModels) {
    for (const FileEntry& f : files) {
      if (fs::path(f.rel).filename() != m.name) continue;
      links << "<li><a href=\"" << HtmlEscape(UrlPath(f.rel)) << "\">" << HtmlEscape(f.rel)
            << "</a> &mdash; " << m.what;
      const Json& lacks = At(cm, m.not_held);
      if (lacks.is_array() && !lacks.empty()) {
        links << "; without <code>" << HtmlEscape(Joined(lacks, ", "))
              << "</code> (no form for them)";
      }
      links << "</li>\n";
    }
  }
  if (!Text(At(cm, "not_written")).empty()) {
    links << "<li>No MJCF or URDF: " << HtmlEscape(Text(At(cm, "not_written"))) << "</li>\n";
  }
  if (links.str().empty()) return;
  *h << "<h3>The calibrated model</h3>\n<ul class=\"answer\">\n" << links.str() << "</ul>\n";
}

// The summary whose identification a page answers with: the run's own, or, for a kind that
// runs identification inside its run (closed_loop_estimators), that result's (`*sub` names its
// folder). Null when neither holds one.
Json IdentificationSummary(const Json& s, const fs::path& dir, std::string* sub) {
  sub->clear();
  if (At(s, "identification").is_object() && !At(At(s, "metrics"), "verdict").is_null()) return s;
  std::error_code ec;
  if (fs::is_regular_file(dir / "identify" / "summary.json", ec)) {
    try {
      Json inner = ReadJson(dir / "identify" / "summary.json");
      if (At(inner, "identification").is_object()) {
        *sub = "identify";
        return inner;
      }
    } catch (const InputError&) {
      // Its own page names the problem; this one answers from the copy it holds.
    }
  }
  return At(s, "identification").is_object() ? s : Json();
}

// What a dynamic identification (closed_loop_dynamic) found: verdict, effects, streams, what is
// left.
void DynamicAnswer(const Json& run, const std::vector<FileEntry>& files, std::ostringstream* h) {
  const Json& d = At(run, "dynamic_identification");
  if (!d.is_object()) return;
  const std::string verdict = Text(At(At(run, "metrics"), "verdict"));
  *h << "<h2>The answer</h2>\n<p class=\"verdict\">Verdict: <b>" << HtmlEscape(verdict)
     << "</b></p>\n<h3>What was found</h3>\n";
  const Json& chosen = At(d, "chosen");
  if (chosen.is_array() && !chosen.empty()) {
    *h << "<table><tr><th>effect</th><th>value</th><th>std</th><th>equivalent</th></tr>\n";
    for (const Json& c : chosen) {
      for (const auto& [name, v] : At(c, "values").items()) {
        *h << "<tr><td>" << HtmlEscape(Text(At(c, "name"))) << "</td><td>" << Cell(v) << " "
           << HtmlEscape(name) << "</td>" << Td(At(At(c, "std_errors"), name)) << "<td>"
           << HtmlEscape(Joined(At(c, "equivalent"), ", ")) << "</td></tr>\n";
      }
    }
    *h << "</table>\n";
  } else {
    *h << "<p>No effect was chosen.</p>\n";
  }
  *h << "<h3>How much better</h3>\n<table><tr><th>stream</th><th>unit</th><th>noise</th>"
     << "<th>residual RMS before</th><th>after</th></tr>\n";
  for (const Json& st : At(d, "streams")) {
    *h << "<tr><td>" << HtmlEscape(Text(At(st, "stream"))) << "</td><td>"
       << HtmlEscape(Text(At(st, "unit"))) << "</td>" << Td(At(st, "noise"))
       << Td(At(st, "rms_before")) << Td(At(st, "rms_after")) << "</tr>\n";
  }
  *h << "</table>\n";
  const Json& replay = At(At(run, "metrics"), "heldout_replay");
  if (replay.is_object()) {
    *h << "<h3>The estimators on the held-out last fold</h3>\n<table><tr><th>estimator</th>"
       << "<th>mean position error, declared model [mm]</th><th>augmented model [mm]</th></tr>\n";
    for (const auto& [label, r] : replay.items()) {
      const auto mm = [&](const char* part) {
        const Json& v = At(At(r, part), "pos_err_mean_m");
        return v.is_number() ? Td(Json(1e3 * v.get<double>())) : Td(Json());
      };
      *h << "<tr><td>" << HtmlEscape(label) << "</td>" << mm("before") << mm("after") << "</tr>\n";
    }
    *h << "</table>\n";
  }
  ModelLinks(d, files, h);
  *h << "<h3>Selection and what is left</h3>\n<ul>\n";
  for (const Json& line : At(d, "log")) *h << "<li>" << HtmlEscape(Text(line)) << "</li>\n";
  *h << "</ul>\n";
}

// What an identification found, above everything else on its page.
void Answer(const Json& run, const fs::path& dir, const std::vector<FileEntry>& files,
            std::ostringstream* h) {
  std::string sub;
  const Json s = IdentificationSummary(run, dir, &sub);
  const Json& id = At(s, "identification");
  if (!id.is_object()) return;
  const std::string verdict = Text(IdMetric(s, "verdict"));
  *h << "<h2>The answer</h2>\n";
  if (!sub.empty()) {
    *h << "<p>From the identification inside this run (<a href=\"" << HtmlEscape(UrlPath(sub))
       << "/report.html\">" << HtmlEscape(sub) << "/report.html</a>, its own page).</p>\n";
  }
  if (!verdict.empty()) {
    *h << "<p class=\"verdict\">Verdict: <b>" << HtmlEscape(verdict) << "</b> &mdash; "
       << HtmlEscape(VerdictWords(verdict)) << "</p>\n";
  }
  const Json& effects = At(id, "effects");
  if (effects.is_array()) Headline(s, effects, h);
  *h << "<h3>What was found</h3>\n";
  if (effects.is_array() && !effects.empty()) {
    EffectsTable(effects, h);
  } else {
    *h << "<p>No effect was chosen.</p>\n";
  }
  const Json& truth = IdMetric(s, "truth_effects");
  if (truth.is_array() && !truth.empty()) {
    *h << "<p>The simulated truth holds <code>" << HtmlEscape(Joined(truth, ", "))
       << "</code>; found correctly: " << Cell(IdMetric(s, "effect_found_correct")) << ".</p>\n";
  }
  BetterTable(s, h);
  HowSure(s, id, h);
  WhatIsLeft(s, h);
  ModelLinks(id, files, h);
}

// Plain words for the flags and bounds the metric tables hold; each shown when a key ends in it.
void FlagNotes(const std::vector<std::string>& keys, std::ostringstream* h) {
  static const std::pair<const char*, const char*> kNotes[] = {
      {"nees_bound_low",
       "<code>nees_mean</code> / <code>nees_before</code> / <code>nees_after</code>: the mean "
       "normalised estimation error squared (e<sup>T</sup> P<sup>-1</sup> e), about its "
       "degrees of freedom (<code>nees_dof</code>) when the stated covariance matches the "
       "errors. <code>nees_bound_low</code> and <code>nees_bound_high</code> are the 95% range "
       "of that mean for a consistent estimator: below it the covariance is larger than the "
       "errors (cautious), above it smaller (overconfident)."},
      {"nees_consistent",
       "<code>nees_consistent</code>: whether the mean NEES lies inside those bounds. It is a "
       "diagnostic, not a verdict: the gates decide pass or fail, and a run whose gates do not "
       "name it passes with it false."},
      {"_independent",
       "<code>*_independent</code>: the bounds if every step's error were independent; the "
       "plain bounds allow for the error the fitted parameters share across all steps "
       "(<code>nees_shared_share</code> of the covariance), which moves every step alike."},
      {"mismatch_flagged",
       "<code>mismatch_flagged</code>: the running NEES test over the last "
       "<code>mismatch_window</code> steps left its bounds, the estimator's sign that its model "
       "does not fit; <code>mismatch_first_step</code> is where (-1: never)."},
  };
  std::ostringstream items;
  for (const auto& [suffix, text] : kNotes) {
    const std::string sfx = suffix;
    const bool present = std::any_of(keys.begin(), keys.end(), [&](const std::string& k) {
      return k.size() >= sfx.size() && k.find(sfx) != std::string::npos;
    });
    if (present) items << "<li>" << text << "</li>\n";
  }
  if (items.str().empty()) return;
  *h << "<ul class=\"notes\">\n" << items.str() << "</ul>\n";
}

std::vector<std::string> LeafKeys(const Json& j) {
  std::vector<std::pair<std::string, Json>> rows;
  Flatten(j, "", &rows);
  std::vector<std::string> keys;
  for (const auto& r : rows) keys.push_back(r.first);
  return keys;
}

// "0.11 [4.8, 7.3] below": a mean NEES with its bounds and where it lies.
std::string NeesCell(const Json& m) {
  const double v = Number(At(m, "nees_mean"));
  const double lo = Number(At(m, "nees_bound_low")), hi = Number(At(m, "nees_bound_high"));
  if (!std::isfinite(v)) return "&mdash;";
  std::string where = !(v >= lo) ? "below" : !(v <= hi) ? "above" : "inside";
  return FmtNum("%.3g", v) + " [" + FmtNum("%.3g", lo) + ", " + FmtNum("%.3g", hi) + "] " + where;
}

std::string FlagCell(const Json& m) {
  if (At(m, "mismatch_flagged") != Json(true)) return "no";
  return "yes (step " + Cell(At(m, "mismatch_first_step")) + ")";
}

// Estimators scored before and after identification (closed_loop_estimators), as the table of
// docs/measurements.md: errors in mm, NEES with its bounds, the mismatch test.
bool BeforeAfterTable(const Json& estimators, std::ostringstream* h) {
  std::ostringstream rows;
  for (auto it = estimators.begin(); it != estimators.end(); ++it) {
    const Json& m = At(it.value(), "metrics");
    const Json &b = At(m, "before"), &a = At(m, "after");
    if (!b.is_object() || !a.is_object()) continue;
    const auto mm = [](const Json& j, const char* key) {
      return FmtNum("%.3g", 1e3 * Number(At(j, key))) + " mm";
    };
    rows << "<tr><td><b>" << HtmlEscape(it.key()) << "</b></td><td class=\"num\">"
         << mm(b, "pos_err_mean_m") << "</td><td class=\"num\">" << mm(a, "pos_err_mean_m")
         << "</td><td class=\"num\">"
         << FmtNum("%.3g", Number(At(a, "pos_err_mean_m")) / Number(At(b, "pos_err_mean_m")))
         << "</td><td class=\"num\">" << mm(b, "lateral_err_mean_m") << " &rarr; "
         << mm(a, "lateral_err_mean_m") << "</td><td class=\"num\">" << NeesCell(b)
         << "</td><td class=\"num\">" << NeesCell(a) << "</td><td>" << FlagCell(b) << " / "
         << FlagCell(a) << "</td></tr>\n";
  }
  if (rows.str().empty()) return false;
  *h << "<h2>Before and after, per estimator</h2>\n<div class=\"scroll\"><table class=\"answer\">\n"
        "<tr><th>estimator</th><th>position error before</th><th>after</th><th>after / "
        "before</th><th>lateral error before &rarr; after</th><th>NEES before [95% bounds]</th>"
        "<th>NEES after [95% bounds]</th><th>mismatch flagged (step) before / after</th></tr>\n"
     << rows.str() << "</table></div>\n";
  FlagNotes({"nees_bound_low", "nees_consistent", "mismatch_flagged"}, h);
  return true;
}

// The run's warnings (summary.json `warnings`, and those of the results inside it), first.
void Warnings(const Json& s, const fs::path& dir, std::ostringstream* h) {
  std::vector<std::string> lines;
  const auto add = [&](const Json& w, const std::string& where) {
    if (!w.is_array()) return;
    for (const Json& line : w) lines.push_back(where + Text(line));
  };
  add(At(s, "warnings"), "");
  std::vector<fs::path> inner;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_directory(ec) && fs::is_regular_file(it->path() / "summary.json", ec)) {
      inner.push_back(it->path());
    }
  }
  std::sort(inner.begin(), inner.end());
  for (const fs::path& sub : inner) {
    try {
      add(At(ReadJson(sub / "summary.json"), "warnings"), sub.filename().string() + "/: ");
    } catch (const InputError&) {
      // Its own page names the problem.
    }
  }
  if (lines.empty()) return;
  *h << "<div class=\"warnings\"><b>Warnings</b>\n<ul>\n";
  for (const std::string& l : lines) *h << "<li>" << HtmlEscape(l) << "</li>\n";
  *h << "</ul></div>\n";
}

// --- A run ----------------------------------------------------------------------------------

std::string RunReportUnchecked(const fs::path& dir) {
  const Json s = ReadJson(dir / "summary.json");
  CheckRunShape(s, dir / "summary.json");
  const std::vector<FileEntry> files = ListFiles(dir);
  const std::string scenario = s.value("scenario", std::string("(unnamed)"));
  std::ostringstream h;
  Head(scenario + " - flexbench report", &h);
  h << "<h1>" << HtmlEscape(scenario) << "</h1>\n";
  if (s.contains("description") && s["description"].is_string()) {
    h << "<p>" << HtmlEscape(s["description"].get<std::string>()) << "</p>\n";
  }
  Warnings(s, dir, &h);
  const Json& estimators = At(s, "estimators");
  const bool before_after = estimators.is_object() && BeforeAfterTable(estimators, &h);
  Answer(s, dir, files, &h);
  DynamicAnswer(s, files, &h);
  // With an answer above, the full tables are there for who wants them, folded.
  const bool fold = before_after || At(s, "identification").is_object();
  if (fold) h << "<h2>How this was made</h2>\n";
  std::vector<std::pair<std::string, std::string>> rows = {
      {"scenario", Cell(s.value("scenario", Json()))},
      {"kind", Cell(s.value("kind", Json()))},
      {"seed", Cell(s.value("seed", Json()))}};
  if (s.contains("command")) {
    rows.emplace_back("command",
                      "<pre>" +
                          HtmlEscape(s["command"].is_string() ? s["command"].get<std::string>()
                                                              : s["command"].dump()) +
                          "</pre>");
  }
  std::string overrides = "none";
  if (s.contains("overrides") && s["overrides"].is_array() && !s["overrides"].empty()) {
    overrides.clear();
    for (const Json& o : s["overrides"]) {
      overrides += (overrides.empty() ? "" : "<br>") +
                   Code("--set " + (o.is_string() ? o.get<std::string>() : o.dump()));
    }
  }
  rows.emplace_back("overrides", overrides);
  KeyValueTable(rows, &h);

  h << "<h2>Gates</h2>\n";
  GateTable(s.value("gates", Json()), false, &h);
  h << "<h2>Metrics</h2>\n";
  if (fold) h << "<details><summary>Every metric of summary.json, as stored (SI units)</summary>\n";
  if (s.contains("metrics") && s["metrics"].is_object() && !s["metrics"].empty()) {
    FlatTable(s["metrics"], &h);
    FlagNotes(LeafKeys(s["metrics"]), &h);
  }
  if (estimators.is_object() && !estimators.empty()) {
    h << "<h3>Estimators</h3>\n";
    EstimatorTable(estimators, &h);
    FlagNotes(LeafKeys(estimators), &h);
  }
  if (fold) h << "</details>\n";
  h << "<h2>Figures</h2>\n";
  Figures(files, false, &h);
  h << "<h2>Files</h2>\n";
  FileLinks(
      files, [](const std::string&) { return true; }, &h);
  Tail("summary.json", &h);
  return h.str();
}

// --- A sweep --------------------------------------------------------------------------------

// Seeds as ranges: "1-32" rather than 32 numbers.
std::string SeedRanges(const Json& seeds) {
  std::vector<long long> v;
  for (const Json& s : seeds) {
    if (s.is_number_integer() || s.is_number_unsigned()) v.push_back(s.get<long long>());
  }
  std::string out;
  for (size_t i = 0; i < v.size();) {
    size_t j = i;
    while (j + 1 < v.size() && v[j + 1] == v[j] + 1) ++j;
    out += (out.empty() ? "" : ", ") + std::to_string(v[i]) +
           (j > i ? "&ndash;" + std::to_string(v[j]) : std::string());
    i = j + 1;
  }
  return out + " (" + std::to_string(v.size()) + " seeds)";
}

// Metrics with one value in every run of every point (a model's nees_dof, a fixed count):
// "group/name" -> that value. Shown once, not per point.
std::map<std::string, Json> ConstantMetrics(const Json& points) {
  std::map<std::string, Json> same;
  if (!points.is_array() || points.empty()) return same;
  for (const char* group : {"metrics", "ratios"}) {
    const Json& first = At(points[0], group);
    if (!first.is_object()) continue;
    for (auto it = first.begin(); it != first.end(); ++it) {
      const Json& v = At(it.value(), "min");
      if (!v.is_number()) continue;
      const bool constant = std::all_of(points.begin(), points.end(), [&](const Json& p) {
        const Json& m = At(At(p, group), it.key());
        return At(m, "min") == v && At(m, "max") == v;
      });
      if (constant) same[std::string(group) + "/" + it.key()] = v;
    }
  }
  return same;
}

void ConstantTable(const std::map<std::string, Json>& same, std::ostringstream* h) {
  if (same.empty()) return;
  *h << "<h2 id=\"same\">The same in every run</h2>\n<p>These " << same.size()
     << " metrics have one value in every run of every point; the tables per point leave them "
        "out.</p>\n<div class=\"scroll\"><table>\n<tr><th>metric</th><th>value</th></tr>\n";
  for (const auto& [key, v] : same) {
    *h << "<tr><td>" << HtmlEscape(key.substr(key.find('/') + 1)) << "</td>" << Td(v) << "</tr>\n";
  }
  *h << "</table></div>\n";
}

void PointMetrics(const Json& point, const std::map<std::string, Json>& same,
                  std::ostringstream* h) {
  *h << "<div class=\"scroll\"><table>\n<tr><th>metric</th><th>n</th><th>mean</th>"
        "<th>95% CI of the mean</th><th>std</th><th>median</th><th>min</th><th>max</th></tr>\n";
  for (const char* group : {"metrics", "ratios"}) {
    if (!point.contains(group) || !point[group].is_object()) continue;
    for (auto it = point[group].begin(); it != point[group].end(); ++it) {
      if (same.count(std::string(group) + "/" + it.key())) continue;
      const Json& m = it.value();
      *h << "<tr><td>" << HtmlEscape(it.key()) << "</td>" << Td(m.value("n", Json()))
         << Td(m.value("mean", Json())) << "<td class=\"num\">[" << Cell(m.value("ci_low", Json()))
         << ", " << Cell(m.value("ci_high", Json())) << "]</td>" << Td(m.value("std", Json()))
         << Td(m.value("median", Json())) << Td(m.value("min", Json()))
         << Td(m.value("max", Json())) << "</tr>\n";
    }
  }
  *h << "</table></div>\n";
}

void PointGates(const Json& point, std::ostringstream* h) {
  if (!point.contains("gates") || !point["gates"].is_object() || point["gates"].empty()) return;
  *h << "<table>\n<tr><th>scenario gate</th><th>passes / runs</th><th>pass fraction</th>"
        "<th>95% Wilson interval</th></tr>\n";
  for (auto it = point["gates"].begin(); it != point["gates"].end(); ++it) {
    const Json& g = it.value();
    *h << "<tr><td>" << HtmlEscape(it.key()) << "</td><td class=\"num\">"
       << Cell(g.value("passes", Json())) << " / " << Cell(g.value("n", Json())) << "</td>"
       << Td(g.value("pass_fraction", Json())) << "<td class=\"num\">["
       << Cell(g.value("wilson_low", Json())) << ", " << Cell(g.value("wilson_high", Json()))
       << "]</td></tr>\n";
  }
  *h << "</table>\n";
}

std::string SweepReportUnchecked(const fs::path& dir) {
  const Json a = ReadJson(dir / "aggregate.json");
  CheckSweepShape(a, dir / "aggregate.json");
  Json how = Json::object();
  if (fs::is_regular_file(dir / kSweepCommandFile)) how = ReadJson(dir / kSweepCommandFile);
  const std::vector<FileEntry> files = ListFiles(dir);
  const std::string name = a.value("sweep", std::string("(unnamed)"));
  std::ostringstream h;
  Head(name + " - flexbench sweep report", &h);
  h << "<h1>Sweep " << HtmlEscape(name) << "</h1>\n";
  std::vector<std::pair<std::string, std::string>> rows = {
      {"sweep", Cell(a.value("sweep", Json()))}};
  for (const char* key : {"sweep_file", "scenario"}) {
    if (how.contains(key)) rows.emplace_back(key, Cell(how[key]));
  }
  rows.emplace_back("seeds", SeedRanges(a.value("seeds", Json::array())));
  if (how.contains("command"))
    rows.emplace_back("command", "<pre>" + Cell(how["command"]) + "</pre>");
  rows.emplace_back("runs", Cell(a.value("runs", Json())) + " (" +
                                Cell(a.value("succeeded", Json())) + " succeeded)");
  rows.emplace_back("bootstrap resamples", Cell(a.value("bootstrap_resamples", Json())));
  KeyValueTable(rows, &h);

  h << "<h2>Sweep gates</h2>\n";
  GateTable(a.value("gates", Json()), true, &h);
  const Json failed = a.value("failed", Json::array());
  if (failed.is_array() && !failed.empty()) {
    h << "<h2>Failed runs</h2>\n<table>\n<tr><th>point</th><th>seed</th><th>status</th>"
         "<th>error</th></tr>\n";
    for (const Json& f : failed) {
      h << "<tr><td>" << Cell(f.value("point", Json())) << "</td>" << Td(f.value("seed", Json()))
        << "<td>" << Cell(f.value("status", Json())) << "</td><td>"
        << Cell(f.value("error", Json())) << "</td></tr>\n";
    }
    h << "</table>\n";
  }
  const std::map<std::string, Json> same = ConstantMetrics(At(a, "points"));
  h << "<h2>Aggregate per point</h2>\n";
  if (!same.empty()) {
    h << "<p>Metrics with one value in every run are listed once, under <a href=\"#same\">The "
         "same in every run</a>.</p>\n";
  }
  for (const Json& p : a.value("points", Json::array())) {
    h << "<h3>Point " << Cell(p.value("point", Json())) << "</h3>\n";
    std::string set;
    const Json ps = p.value("set", Json::object());
    for (auto it = ps.begin(); it != ps.end(); ++it) {
      set += (set.empty() ? "" : ", ") +
             Code(it.key() + "=" +
                  (it.value().is_string() ? it.value().get<std::string>() : it.value().dump()));
    }
    h << "<p>" << (set.empty() ? std::string("no grid values") : set) << "; "
      << Cell(p.value("succeeded", Json())) << " of " << Cell(p.value("runs", Json()))
      << " runs succeeded.</p>\n";
    PointGates(p, &h);
    PointMetrics(p, same, &h);
  }
  ConstantTable(same, &h);
  h << "<h2>Figures</h2>\n";
  Figures(files, true, &h);
  h << "<h2>Files</h2>\n<p>Each run's folder has its own report.</p>\n";
  // Under runs/ only the runs' reports and summaries: their other files are in their reports.
  FileLinks(
      files,
      [](const std::string& rel) {
        if (rel.rfind("runs/", 0) != 0) return true;
        const std::string name = fs::path(rel).filename().string();
        return name == kReportName || name == "summary.json";
      },
      &h);
  Tail("aggregate.json", &h);
  return h.str();
}

// The shape checks cover what the pages read; a JSON type error they missed is still the
// file's fault, never an internal error.
std::string RunReport(const fs::path& dir) {
  try {
    return RunReportUnchecked(dir);
  } catch (const Json::exception& e) {
    throw InputError(CapForMessage((dir / "summary.json").string()) +
                     ": unexpected content: " + e.what());
  }
}

std::string SweepReport(const fs::path& dir) {
  try {
    return SweepReportUnchecked(dir);
  } catch (const Json::exception& e) {
    throw InputError(CapForMessage((dir / "aggregate.json").string()) +
                     ": unexpected content: " + e.what());
  }
}

}  // namespace

Json ReadResultJson(const fs::path& path) { return ReadJson(path); }

std::string HtmlEscape(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string UrlPath(const std::string& relative) {
  static const char* kHex = "0123456789ABCDEF";
  std::string out;
  for (unsigned char c : relative) {
    if (std::isalnum(c) || c == '-' || c == '.' || c == '_' || c == '~' || c == '/') {
      out += static_cast<char>(c);
    } else {
      out += '%';
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  return out;
}

std::string ShellQuote(const std::string& arg) {
  const bool safe = !arg.empty() && std::all_of(arg.begin(), arg.end(), [](unsigned char c) {
    return std::isalnum(c) || std::string("_@%+=:,./-").find(c) != std::string::npos;
  });
  if (safe) return arg;
  std::string q = "'";
  for (char c : arg) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string CommandLine(const std::vector<std::string>& args) {
  std::string line;
  for (const std::string& a : args) line += (line.empty() ? "" : " ") + ShellQuote(a);
  return line;
}

std::string RenderReport(const fs::path& dir) {
  std::error_code ec;
  if (fs::is_regular_file(dir / "summary.json", ec)) return RunReport(dir);
  if (fs::is_regular_file(dir / "aggregate.json", ec)) return SweepReport(dir);
  throw InputError(CapForMessage(dir.string()) +
                   ": not a flexbench result (no summary.json or aggregate.json)");
}

// Folders below a run's `dir` that are results themselves (e.g. closed_loop_estimators'
// identify/), deepest first: their reports exist before a page above links them.
std::vector<fs::path> NestedResults(const fs::path& dir) {
  std::vector<fs::path> nested;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_directory(ec) && fs::is_regular_file(it->path() / "summary.json", ec)) {
      nested.push_back(it->path());
    }
  }
  std::sort(nested.begin(), nested.end(), [](const fs::path& a, const fs::path& b) {
    const auto depth = [](const fs::path& p) { return std::distance(p.begin(), p.end()); };
    return depth(a) != depth(b) ? depth(a) > depth(b) : a < b;
  });
  return nested;
}

void WriteReport(const fs::path& dir) {
  std::error_code ec;
  if (fs::is_regular_file(dir / "summary.json", ec)) {
    for (const fs::path& sub : NestedResults(dir)) {
      WriteFileAtomic(sub / kReportName, RunReport(sub));
    }
  }
  WriteFileAtomic(dir / kReportName, RenderReport(dir));
}

int ReportCommand(const std::string& dir) {
  try {
    WriteReport(dir);
    std::cerr << "[flexbench] wrote " << (fs::path(dir) / kReportName).string() << "\n";
    return kExitOk;
  } catch (const std::exception& e) {
    return ReportError(e);
  }
}

}  // namespace flexbench::scenarios
