// report.html: one self-contained page per result folder (a run's or a sweep's) that a reader
// opens in any browser, offline and without JavaScript: how the result was made (scenario,
// seed, command, overrides), the gates, the metrics as tables, every figure the folder holds and
// links to its data files. It is made from the folder alone, so `flexbench report DIR` makes the
// same bytes as the run did, and the same folder always gives the same page.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

// Written by a sweep's collect beside aggregate.json: {"command", "sweep_file", "scenario"},
// how the sweep was run (aggregate.json stays the same bytes whatever the command).
inline constexpr const char* kSweepCommandFile = "sweep_command.json";

// The largest summary.json / aggregate.json a report reads (bytes; a run's summary is some
// kilobytes), and the deepest nesting of lists and objects in it. Beyond either the file is
// refused as bad input before a tree is built.
inline constexpr std::uintmax_t kMaxResultJsonBytes = 64u << 20;
inline constexpr int kMaxResultJsonDepth = 64;

// A result file (summary.json, aggregate.json) as a JSON object: too big, too deep, not JSON or
// not an object is InputError naming the file.
Json ReadResultJson(const std::filesystem::path& path);

// `text` with &, <, >, " and ' replaced by entities: text from result files is never markup.
std::string HtmlEscape(const std::string& text);

// A relative path as a URL path: bytes other than unreserved characters and '/' are
// percent-encoded, so a file named "a b#1.png" is still found (and "c:d.png" is no URL scheme).
std::string UrlPath(const std::string& relative);

// One argument as the shell reads it back: unchanged when made of safe characters, otherwise
// single-quoted.
std::string ShellQuote(const std::string& arg);

// The arguments shell-quoted and joined with spaces.
std::string CommandLine(const std::vector<std::string>& args);

// The report of `dir`: a run's when it holds summary.json, else a sweep's when it holds
// aggregate.json. Throws InputError naming `dir` when it holds neither, and naming the file
// (and the key) when one is not JSON, too big, too deep or of the wrong shape.
std::string RenderReport(const std::filesystem::path& dir);

// Writes RenderReport(dir) to dir/report.html through a temporary file and a rename; in a
// run's folder first the reports of the results inside it (folders with summary.json).
void WriteReport(const std::filesystem::path& dir);

// `flexbench report DIR`: regenerates DIR/report.html. Returns an exit code (2: DIR is not a
// flexbench result; one line on stderr).
int ReportCommand(const std::string& dir);

}  // namespace flexbench::scenarios
