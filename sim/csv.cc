#include "sim/csv.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "estimators/error.h"
#include "sim/config.h"

namespace flexbench::sim {

std::string TrimBlanks(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r");
  if (a == std::string::npos) return "";
  const size_t b = s.find_last_not_of(" \t\r");
  return s.substr(a, b - a + 1);
}

std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string cell;
  while (std::getline(ss, cell, ',')) out.push_back(TrimBlanks(cell));
  if (!line.empty() && line.back() == ',') out.push_back("");
  return out;
}

double ParseCsvNumber(const std::string& cell, const std::string& where, const std::string& col,
                      double max_abs) {
  if (cell.empty()) throw InputError(where + ": column '" + CapForMessage(col) + "' is empty");
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(cell.c_str(), &end);
  if (end == cell.c_str() || *end != '\0' || errno == ERANGE) {
    throw InputError(where + ": column '" + CapForMessage(col) + "': '" + CapForMessage(cell) +
                     "' is not a number");
  }
  if (!std::isfinite(v)) {
    throw InputError(where + ": column '" + CapForMessage(col) + "' is " + CapForMessage(cell));
  }
  if (std::abs(v) > max_abs) {
    char lim[32];
    std::snprintf(lim, sizeof(lim), "%g", max_abs);
    throw InputError(where + ": column '" + CapForMessage(col) + "': " + CapForMessage(cell) +
                     " is out of range (|value| <= " + lim + ")");
  }
  return v;
}

std::uintmax_t CountLines(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<char> buffer(1 << 20);
  std::uintmax_t lines = 0;
  char last = '\n';
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const std::streamsize n = in.gcount();
    if (n <= 0) break;
    lines += static_cast<std::uintmax_t>(std::count(buffer.data(), buffer.data() + n, '\n'));
    last = buffer[static_cast<size_t>(n) - 1];
  }
  return lines + (last != '\n' ? 1 : 0);
}

CsvLines::CsvLines(const std::string& path, std::uintmax_t max_bytes) : path_(CapForMessage(path)) {
  CheckInputFile(path, max_bytes);
  in_.open(path, std::ios::binary);
  if (!in_) throw InputError(path_ + ": cannot open");
}

bool CsvLines::Next(std::vector<std::string>* cells) {
  std::string line;
  while (std::getline(in_, line)) {
    ++line_no_;
    // Excel's "CSV UTF-8" starts with a byte-order mark: not part of the first column's name.
    if (line_no_ == 1 && line.compare(0, 3, "\xEF\xBB\xBF") == 0) line.erase(0, 3);
    const std::string t = TrimBlanks(line);
    if (t.empty() || t[0] == '#') continue;
    *cells = SplitCsv(t);
    return true;
  }
  return false;
}

}  // namespace flexbench::sim
