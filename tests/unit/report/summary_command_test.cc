// `flexbench summary`'s rows: the headline gate and its unit, gate counts, a sweep's summed run
// times, and InputError for a folder that is not a result.
#include "scenarios/runner/summary_command.h"

#include <gtest/gtest.h>

#include <string>

#include "estimators/error.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;
using scenarios::Headline;
using scenarios::Json;
using scenarios::ReadResultRow;

Json Gate(const std::string& metric, const Json& value, bool passed = true) {
  return Json{{"name", "g"}, {"metric", metric}, {"op", "<"}, {"value", value}, {"passed", passed}};
}

TEST(SummaryHeadline, TheFirstGateWithAUnitIsShownInItsUnit) {
  const Json gates =
      Json::array({Gate("metrics.effect_found_correct", true), Gate("metrics.count", 3),
                   Gate("estimators.ppoe_ekf.metrics.lateral_err_mean_m", 0.00117)});
  EXPECT_EQ(Headline(gates), "ppoe_ekf lateral_err_mean 1.17 mm");
}

TEST(SummaryHeadline, UnitsOfTheScenariosMetricNames) {
  EXPECT_EQ(Headline(Json::array({Gate("a.joint_rmse_deg", 1.93)})), "joint_rmse 1.93 deg");
  EXPECT_EQ(Headline(Json::array({Gate("corner_rmse_px", 0.0661)})), "corner_rmse 0.0661 px");
  EXPECT_EQ(Headline(Json::array({Gate("x.tilt_rad", 0.002)})), "tilt 2 mrad");
  EXPECT_EQ(Headline(Json::array({Gate("a.inside80_frac", 0.8)})), "inside80 80 %");
}

TEST(SummaryHeadline, WithoutAUnitTheFirstNumberAndNeverABoolean) {
  EXPECT_EQ(Headline(Json::array({Gate("ok", true), Gate("metrics.unflagged_growth_cells", 0)})),
            "unflagged_growth_cells 0");
  EXPECT_EQ(Headline(Json::array({Gate("ok", true)})), "");
  EXPECT_EQ(Headline(Json::array()), "");
}

TEST(SummaryHeadline, ASweepStatisticIsNamedAndARatioHasNoUnit) {
  EXPECT_EQ(Headline(Json::array({Gate("mean(estimators.fk.metrics.err_m)", 0.002)})),
            "mean fk err 2 mm");
  EXPECT_EQ(Headline(Json::array({Gate("ci_high(ratio(estimators.a.metrics.e_m, "
                                       "estimators.b.metrics.e_m))",
                                       0.105)})),
            "ci_high ratio a e_m 0.105");
  EXPECT_EQ(Headline(Json::array({Gate("pass_fraction(stays_below_1p5_deg)", 0.96875)})),
            "pass_fraction stays_below_1p5_deg 0.969");
}

TEST(SummaryRow, RunAndSweepFoldersAndSomethingElse) {
  TempDir tmp;
  const Json gates = Json::array({Gate("err_m", 0.001, true), Gate("err_m", 0.001, false)});
  WriteFile(tmp.path() / "run" / "summary.json",
            Json{{"scenario", "s"}, {"gates", gates}, {"timing", {{"total_s", 2.5}}}}.dump());
  const scenarios::ResultRow run = ReadResultRow(tmp.path() / "run");
  EXPECT_EQ(run.scenario, "s");
  EXPECT_EQ(run.gates_passed, 1);
  EXPECT_EQ(run.gates_total, 2);
  EXPECT_DOUBLE_EQ(run.seconds, 2.5);
  EXPECT_GT(run.bytes, 0u);
  EXPECT_NE(scenarios::FormatResultTable({run}).find("1/2 FAIL"), std::string::npos);

  WriteFile(tmp.path() / "sw" / "aggregate.json", Json{{"sweep", "w"}, {"gates", gates}}.dump());
  for (const char* r : {"a", "b"}) {
    WriteFile(tmp.path() / "sw" / "runs" / r / "summary.json",
              Json{{"scenario", "s"}, {"timing", {{"total_s", 1.25}}}}.dump());
  }
  const scenarios::ResultRow sweep = ReadResultRow(tmp.path() / "sw");
  EXPECT_EQ(sweep.scenario, "sweep w");
  EXPECT_DOUBLE_EQ(sweep.seconds, 2.5);
  EXPECT_TRUE(sweep.summed);

  const std::string error = ErrorOf([&] { ReadResultRow(tmp.path()); });
  EXPECT_NE(error.find("not a flexbench result"), std::string::npos) << error;
}

}  // namespace
}  // namespace flexbench::testing
