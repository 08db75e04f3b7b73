// Sweep files. Expansion into points and runs, statistic expressions, and every bad
// input of the file as one InputError naming file and line.
#include "scenarios/sweep/sweep_file.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "estimators/error.h"
#include "tests/common/test_util.h"

namespace flexbench::scenarios::sweep {
namespace {

using flexbench::testing::TempDir;
using flexbench::testing::WriteFile;

SweepSpec Load(const TempDir& tmp, const std::string& text) {
  const auto path = tmp.path() / "s.yaml";
  WriteFile(path, text);
  return LoadSweep(path.string());
}

std::string ErrorOf(const std::string& text) {
  TempDir tmp;
  try {
    Load(tmp, text);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(SweepFile, ExpandsTheGridFirstKeyOutermostAndSeedsInOrder) {
  TempDir tmp;
  const SweepSpec s = Load(tmp,
                           "sweep: g\nscenario: x.yaml\nseeds: [5, 2]\n"
                           "set: {estimators.ppoe_ekf.iterations: 2}\n"
                           "grid:\n  a.k: [1, 2.5]\n  b: [x, {c: 1}]\n");
  EXPECT_EQ(s.scenario, (tmp.path() / "x.yaml").string());
  ASSERT_EQ(s.set.size(), 1u);
  EXPECT_EQ(s.set[0], "estimators.ppoe_ekf.iterations=2");
  const auto points = ExpandPoints(s);
  ASSERT_EQ(points.size(), 4u);
  EXPECT_EQ(points[0].name, "a.k_1__b_x");
  EXPECT_EQ(points[1].name, "a.k_1__b__c__1_");
  EXPECT_EQ(points[1].set[1], "b={c: 1}");
  EXPECT_EQ(points[2].set[0], "a.k=2.5");
  const auto runs = ExpandRuns(s, points);
  ASSERT_EQ(runs.size(), 8u);
  EXPECT_EQ(runs[0].seed, 5u);
  EXPECT_EQ(runs[1].seed, 2u);
  EXPECT_EQ(runs[1].dir, "runs/a.k_1__b_x/seed_2");
  EXPECT_EQ(runs[2].point, 1u);
}

TEST(SweepFile, NoGridIsOnePointNamedBase) {
  TempDir tmp;
  const SweepSpec s = Load(tmp, "sweep: g\nscenario: x.yaml\nseeds: {from: 3, to: 6}\n");
  EXPECT_EQ(s.seeds, (std::vector<std::uint64_t>{3, 4, 5, 6}));
  const auto points = ExpandPoints(s);
  ASSERT_EQ(points.size(), 1u);
  EXPECT_EQ(points[0].name, "base");
  // A sweep's runs keep their numbers, not their images, unless the file asks.
  EXPECT_EQ(s.frames, FrameOutput::kNone);
  EXPECT_EQ(Load(tmp, "sweep: g\nscenario: x.yaml\nseeds: [1]\nframes: key\n").frames,
            FrameOutput::kKey);
}

TEST(SweepFile, ParsesStatistics) {
  const Statistic r = ParseStatistic("ci_high(ratio(a.b, c.d))", "w");
  EXPECT_EQ(r.stat, "ci_high");
  EXPECT_EQ(r.path, "a.b");
  EXPECT_EQ(r.divisor, "c.d");
  EXPECT_FALSE(r.of_gate);
  const Statistic g = ParseStatistic("pass_fraction(my_gate)", "w");
  EXPECT_TRUE(g.of_gate);
  EXPECT_EQ(g.path, "my_gate");
  for (const char* bad : {"mean", "mean(", "average(x)", "mean(ratio(a))",
                          "pass_fraction(ratio(a, b))", "mean(a b)", "mean()"}) {
    EXPECT_THROW(ParseStatistic(bad, "w"), InputError) << bad;
  }
}

TEST(SweepFile, BadInputNamesFileLineAndKey) {
  const std::string head = "sweep: g\nscenario: x.yaml\n";
  struct Case {
    std::string text;
    std::string expect;
  };
  for (const Case& c : std::vector<Case>{
           {head + "seeds: {from: 5, to: 2}\n", "s.yaml:3"},
           {head + "seeds: {from: 5, to: 2}\n", "seed range is empty"},
           {head + "seeds: []\n", "no seeds"},
           {head + "seeds: [1, 1]\n", "listed twice"},
           {head + "seeds: [1]\ngrid: {}\n", "empty grid"},
           {head + "seeds: [1]\ngrid: {a: []}\n", "empty list of values"},
           {head + "seeds: [1]\ngrid: {a: [1, 1]}\n", "a value is listed twice"},
           {head + "seeds: [1]\nseedz: 3\n", "unknown key 'seedz'"},
           {head + "seeds: [1]\ngates:\n  - {name: x, metric: average(a), op: <, threshold: 1}\n",
            "unknown statistic 'average'"},
           {head + "seeds: [1]\ngates:\n  - {name: x, metric: mean(a), op: <<, threshold: 1}\n",
            "unknown operator"},
           {head + "seeds: [1]\ngates:\n  - {name: x, metric: mean(a), op: <, threshold: 1, "
                   "point: nowhere}\n",
            "point 'nowhere' is not a point of this sweep"},
           {head + "seeds: [1]\nplot: {metrics: [a], x: nokey}\n", "not a grid key"},
           {"sweep: a/b\nscenario: x.yaml\nseeds: [1]\n", "plain name"},
           {head + "seeds: [1]\nframes: some\n", "expected all, key or none"},
       }) {
    const std::string e = ErrorOf(c.text);
    EXPECT_NE(e.find(c.expect), std::string::npos) << c.text << "\n-> " << e;
    EXPECT_NE(e.find("s.yaml"), std::string::npos) << e;
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  }
}

}  // namespace
}  // namespace flexbench::scenarios::sweep

namespace flexbench::scenarios::sweep {
namespace {

// Every sweep file of the repository reads, names a scenario file that exists and runs seeds.
TEST(SweepFile, EverySweepOfTheRepositoryReads) {
  int sweeps = 0;
  for (const auto& entry :
       std::filesystem::directory_iterator(flexbench::testing::SourceDir() + "/scenarios/sweeps")) {
    if (entry.path().extension() != ".yaml") continue;
    SCOPED_TRACE(entry.path().string());
    const SweepSpec spec = LoadSweep(entry.path().string());
    EXPECT_TRUE(std::filesystem::exists(spec.scenario)) << spec.scenario;
    EXPECT_GE(spec.seeds.size(), 1u);
    EXPECT_FALSE(spec.gates.empty());
    ++sweeps;
  }
  EXPECT_GE(sweeps, 9);
}

}  // namespace
}  // namespace flexbench::scenarios::sweep
