// Replays every seed (tests/fuzz/corpus/<target>/) and every crash found by a fuzzer
// (tests/fuzz/regressions/<target>/) through the fuzz entry points (tests/fuzz/fuzz_entry.h)
// in the normal build: nothing but an InputError may escape a loader, and an InputError is
// what the runner prints after "flexbench: error: " with exit code 2, so its message must be
// one line that names the input: a file (every input file of an entry lives under its work
// folder) or, for an entry whose input is no file, what Target::also_named says (--set).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "tests/fuzz/fuzz_entry.h"

namespace fs = std::filesystem;

namespace {

std::vector<fs::path> Files(const fs::path& dir) {
  std::vector<fs::path> out;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return out;
  for (const fs::directory_entry& e : fs::directory_iterator(dir)) {
    if (e.is_regular_file() && e.path().filename().string()[0] != '.') out.push_back(e.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::string Read(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

class FuzzReplay : public testing::TestWithParam<flexbench::fuzz::Target> {};

TEST_P(FuzzReplay, EveryCorpusAndRegressionFileIsAcceptedOrAnInputError) {
  const flexbench::fuzz::Target& target = GetParam();
  const fs::path root = fs::path(FLEXBENCH_SOURCE_DIR) / "tests/fuzz";
  const std::vector<fs::path> corpus = Files(root / "corpus" / target.name);
  ASSERT_FALSE(corpus.empty()) << "no seeds in tests/fuzz/corpus/" << target.name;
  std::vector<fs::path> files = corpus;
  const std::vector<fs::path> regressions = Files(root / "regressions" / target.name);
  files.insert(files.end(), regressions.begin(), regressions.end());
  // A fuzzer's own corpus replayed the same way: FLEXBENCH_FUZZ_REPLAY_EXTRA=<dir> holding
  // <target>/ folders (e.g. the first folder given to build-fuzz/bin/fuzz_<target>).
  if (const char* extra = std::getenv("FLEXBENCH_FUZZ_REPLAY_EXTRA")) {
    const std::vector<fs::path> more = Files(fs::path(extra) / target.name);
    files.insert(files.end(), more.begin(), more.end());
  }
  const std::string& work = flexbench::fuzz::WorkDir();
  int accepted = 0, rejected = 0;
  for (const fs::path& file : files) {
    SCOPED_TRACE(file.string());
    const std::string bytes = Read(file);
    std::optional<std::string> error;
    try {
      error = target.entry(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
    } catch (const std::exception& e) {
      ADD_FAILURE() << "not an InputError escaped: " << e.what();
      continue;
    } catch (...) {
      ADD_FAILURE() << "a non-std exception escaped";
      continue;
    }
    if (!error) {
      ++accepted;
      continue;
    }
    ++rejected;
    if (std::getenv("FLEXBENCH_FUZZ_REPLAY_VERBOSE")) {
      std::printf("  %s: %s\n", file.filename().string().c_str(), error->c_str());
    }
    EXPECT_EQ(error->find('\n'), std::string::npos) << "message of more than one line: " << *error;
    const bool names_input =
        error->find(work) != std::string::npos ||
        (target.also_named && error->find(target.also_named) != std::string::npos);
    EXPECT_TRUE(names_input) << "message names no input: " << *error;
    EXPECT_LT(error->size(), 2000u) << *error;
  }
  std::printf(
      "[ fuzz     ] %s: %zu corpus + %zu regression files (%zu in all), %d accepted, "
      "%d rejected\n",
      target.name, corpus.size(), regressions.size(), files.size(), accepted, rejected);
}

INSTANTIATE_TEST_SUITE_P(Targets, FuzzReplay, testing::ValuesIn(flexbench::fuzz::Targets()),
                         [](const testing::TestParamInfo<flexbench::fuzz::Target>& info) {
                           return std::string(info.param.name);
                         });

}  // namespace
