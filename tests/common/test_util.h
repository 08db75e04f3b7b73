// Helpers shared by the test suites: running the flexbench binary, temporary folders, files.
#pragma once

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>

#include "estimators/error.h"

namespace flexbench::testing {

inline std::string SourceDir() { return FLEXBENCH_SOURCE_DIR; }
inline std::string BinDir() { return FLEXBENCH_BIN_DIR; }
inline std::string Flexbench() { return BinDir() + "/flexbench"; }

// The last non-empty line of a command's stderr: the error line.
inline std::string LastLine(std::string err) {
  while (!err.empty() && err.back() == '\n') err.pop_back();
  const size_t nl = err.rfind('\n');
  return nl == std::string::npos ? err : err.substr(nl + 1);
}

// Regular files below `dir` now (0 when it does not exist or is moved away meanwhile).
inline int FilesIn(const std::filesystem::path& dir) {
  int n = 0;
  std::error_code ec;
  for (std::filesystem::recursive_directory_iterator it(dir, ec), end; !ec && it != end;
       it.increment(ec)) {
    n += it->is_regular_file(ec);
  }
  return n;
}

// The message of the InputError that f throws; "" when it throws none.
inline std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

struct CommandResult {
  int exit_code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};

// Runs a shell command, capturing stdout and stderr separately.
inline CommandResult RunCommand(const std::string& command) {
  const std::filesystem::path err_file =
      std::filesystem::temp_directory_path() /
      ("flexbench_stderr_" + std::to_string(std::random_device{}()) + ".txt");
  CommandResult r;
  const std::string full = command + " 2>" + err_file.string();
  FILE* pipe = popen(full.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.out.append(buf.data(), n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(err_file);
  std::stringstream ss;
  ss << in.rdbuf();
  r.err = ss.str();
  std::filesystem::remove(err_file);
  return r;
}

inline std::string ReadFile(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

inline void WriteFile(const std::filesystem::path& p, const std::string& text) {
  std::filesystem::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary) << text;
}

// A fresh temporary folder, removed at scope exit.
class TempDir {
 public:
  TempDir() {
    path_ = std::filesystem::temp_directory_path() /
            ("flexbench_test_" + std::to_string(std::random_device{}()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

inline int CountLines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

}  // namespace flexbench::testing
