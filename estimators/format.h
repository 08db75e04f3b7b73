// Numbers as text, written the same way by every layer: messages, logs, tables and files.
#pragma once

#include <cstdarg>
#include <cstdio>
#include <string>

namespace flexbench {

// printf into a string, of any length.
inline std::string Fmt(const char* format, ...) __attribute__((format(printf, 1, 2)));
inline std::string Fmt(const char* format, ...) {
  va_list args;
  va_start(args, format);
  va_list again;
  va_copy(again, args);
  const int n = std::vsnprintf(nullptr, 0, format, args);
  va_end(args);
  std::string s(n > 0 ? n : 0, '\0');
  if (n > 0) std::vsnprintf(s.data(), s.size() + 1, format, again);
  va_end(again);
  return s;
}

// Six significant digits (printf's %.6g, an ostream's default): what a person reads.
inline std::string ShortNum(double v) { return Fmt("%.6g", v); }

// 17 significant digits: a number written reads back as itself.
inline std::string ExactNum(double v) { return Fmt("%.17g", v); }

}  // namespace flexbench
