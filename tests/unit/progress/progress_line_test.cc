// ProgressLine: what a long run prints on a terminal and in a log, with a fake clock.
#include <gtest/gtest.h>

#include <vector>

#include "scenarios/runner/progress.h"

namespace flexbench::scenarios {
namespace {

struct Harness {
  explicit Harness(bool terminal, bool quiet = false) {
    ProgressLine::Options o;
    o.terminal = terminal;
    o.quiet = quiet;
    line = std::make_unique<ProgressLine>(
        o, [this](const std::string& t) { out.push_back(t); }, [this] { return now; });
  }
  double now = 0.0;
  std::vector<std::string> out;
  std::unique_ptr<ProgressLine> line;
};

TEST(ProgressLine, ShortRunsPrintNothing) {
  for (const bool terminal : {true, false}) {
    Harness h(terminal);
    for (int k = 1; k <= 10; ++k) {
      h.now = 0.15 * k;
      h.line->Update("configurations", k, 10);
    }
    EXPECT_TRUE(h.out.empty()) << terminal;
  }
}

TEST(ProgressLine, TerminalUpdatesOneLineWithElapsedAndEta) {
  Harness h(true);
  for (int k = 1; k <= 10; ++k) {
    h.now = 1.0 * k;  // one second a step
    h.line->Update("configurations", k, 10);
  }
  // From 2 s on: steps 2..10, each rewriting the line; the last ends it.
  ASSERT_EQ(h.out.size(), 9u);
  EXPECT_EQ(h.out[0].rfind("\r[flexbench] configurations 2/10, elapsed 2.0 s, ETA 8 s", 0), 0u)
      << h.out[0];
  for (size_t k = 0; k + 1 < h.out.size(); ++k) EXPECT_EQ(h.out[k].back(), ' ');
  EXPECT_EQ(h.out.back().back(), '\n');
  EXPECT_NE(h.out.back().find("10/10, elapsed 10.0 s"), std::string::npos);
  EXPECT_EQ(h.out.back().find("ETA"), std::string::npos);
}

TEST(ProgressLine, LogGetsAPlainLineEveryPeriodAndTheStagesEnd) {
  Harness h(false);
  for (int k = 1; k <= 60; ++k) {
    h.now = 0.5 * k;  // 30 s in all
    h.line->Update("tracking", k, 60);
  }
  // At 2 s (the first after the quiet start), 12 s, 22 s, and the end at 30 s.
  ASSERT_EQ(h.out.size(), 4u);
  EXPECT_EQ(h.out[0], "[flexbench] tracking 4/60, elapsed 2.0 s, ETA 28 s\n");
  EXPECT_EQ(h.out[1], "[flexbench] tracking 24/60, elapsed 12.0 s, ETA 18 s\n");
  EXPECT_EQ(h.out[3], "[flexbench] tracking 60/60, elapsed 30.0 s\n");
  for (const std::string& l : h.out) EXPECT_EQ(l.find('\r'), std::string::npos);
}

// A new stage's ETA counts from its first step, not from the run's start.
TEST(ProgressLine, EtaIsPerStage) {
  Harness h(true);
  h.now = 50.0;
  h.line->Update("first", 1, 1);
  h.now = 52.0;  // the second stage's first step took 2 s
  h.line->Update("second", 1, 5);
  ASSERT_FALSE(h.out.empty());
  EXPECT_NE(h.out.back().find("second 1/5, elapsed 52.0 s, ETA 8 s"), std::string::npos)
      << h.out.back();
}

TEST(ProgressLine, QuietPrintsNothing) {
  for (const bool terminal : {true, false}) {
    Harness h(terminal, /*quiet=*/true);
    for (int k = 1; k <= 100; ++k) {
      h.now = 1.0 * k;
      h.line->Update("steps", k, 100);
    }
    EXPECT_TRUE(h.out.empty());
  }
}

}  // namespace
}  // namespace flexbench::scenarios
