// CSV files as every flexbench reader takes them: one header row, blank lines and '#' comments
// skipped, cells trimmed, a UTF-8 byte-order mark ignored, and each bad cell one InputError
// naming "<file>:<line>: column '<name>'".
#pragma once

#include <cstdint>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

namespace flexbench::sim {

// `s` without leading and trailing blanks (space, tab, CR).
std::string TrimBlanks(const std::string& s);

// The comma-separated cells of one line, each trimmed (a trailing comma makes an empty cell).
std::vector<std::string> SplitCsv(const std::string& line);

// The number in `cell` of column `col` at `where` ("<file>:<line>"). InputError when it is
// empty, not a number, not finite, or larger in magnitude than max_abs.
double ParseCsvNumber(const std::string& cell, const std::string& where, const std::string& col,
                      double max_abs = std::numeric_limits<double>::infinity());

// Lines of `path` (a last line without '\n' counts): an upper bound of its data rows, found
// without keeping any of it.
std::uintmax_t CountLines(const std::string& path);

// The data lines of a CSV file, one at a time.
class CsvLines {
 public:
  // Opens `path`, a regular file of at most max_bytes (InputError otherwise).
  CsvLines(const std::string& path, std::uintmax_t max_bytes);
  // The cells of the next data line; false at the end.
  bool Next(std::vector<std::string>* cells);
  // "<file>:<line>" of the last line returned.
  std::string Where() const { return path_ + ":" + std::to_string(line_no_); }
  int line() const { return line_no_; }

 private:
  std::ifstream in_;
  std::string path_;
  int line_no_ = 0;
};

}  // namespace flexbench::sim
