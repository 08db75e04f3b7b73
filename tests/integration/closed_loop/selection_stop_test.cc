// What ends a selection, said in the results: the held-out error (the default, no cap), BIC
// without cross-validation, or a cap or time budget the user gave that stopped a selection the
// data would continue (then never "explained"). Rows made by MuJoCo with two planted joint offsets.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <random>

#include "tests/common/planar_rows.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;

class SelectionStop : public ::testing::Test {
 protected:
  void SetUp() override {
    std::mt19937_64 rng(11);
    const std::array<double, 3> offset = {0.0, 0.5 * M_PI / 180.0, -0.4 * M_PI / 180.0};
    WriteFile(tmp_.path() / "cal.csv", kPlanarHeader + PlanarRows(80, rng, 1e-4, offset));
    WriteFile(tmp_.path() / "val.csv", kPlanarHeader + PlanarRows(60, rng, 1e-4, offset));
  }
  nlohmann::json Identify(const std::string& out, const std::string& extra, std::string* err) {
    const CommandResult r =
        RunCommand(BinDir() + "/flexbench identify --declared " + SourceDir() +
                   "/models/planar3.declared.yaml --calibration " +
                   (tmp_.path() / "cal.csv").string() + " --validation " +
                   (tmp_.path() / "val.csv").string() + " --candidates joint_offset --out " +
                   (tmp_.path() / out).string() + " " + extra + " </dev/null");
    EXPECT_EQ(r.exit_code, 0) << r.err;
    *err = r.err;
    return nlohmann::json::parse(ReadFile(tmp_.path() / out / "summary.json"))["metrics"];
  }
  TempDir tmp_;
};

TEST_F(SelectionStop, TheDefaultStopsWhereTheHeldOutErrorStopsFalling) {
  std::string err;
  const nlohmann::json m = Identify("default", "", &err);
  EXPECT_EQ(m["stopped_by"], "held_out");
  EXPECT_EQ(m["effects_found"].size(), 2u) << m["effects_found"];
  EXPECT_NE(m["verdict"], "partly_explained");
  EXPECT_EQ(err.find("max_effects"), std::string::npos) << err;
  EXPECT_NE(err.find("sigma^2"), std::string::npos) << err;  // held-out errors carry their unit
}

TEST_F(SelectionStop, ACapThatStopsTheDataIsSaidAndNeverExplained) {
  std::string err;
  const nlohmann::json m = Identify("capped", "--max-effects 1", &err);
  EXPECT_EQ(m["stopped_by"], "max_effects");
  EXPECT_EQ(m["effects_found"].size(), 1u) << m["effects_found"];
  EXPECT_EQ(m["verdict"], "partly_explained");
  EXPECT_NE(err.find("stop: max_effects 1 reached, but joint_offset@joint"), std::string::npos)
      << err;
  // A cap the data never reach changes nothing and is not reported.
  const nlohmann::json wide = Identify("wide", "--max-effects 5", &err);
  EXPECT_EQ(wide["stopped_by"], "held_out");
  EXPECT_EQ(wide["effects_found"].size(), 2u);
}

TEST_F(SelectionStop, WithoutCrossValidationBicStopsAndNoNanIsPrinted) {
  std::string err;
  const nlohmann::json m = Identify("bic", "--no-cross-validation", &err);
  EXPECT_EQ(m["stopped_by"], "bic");
  EXPECT_EQ(m["effects_found"].size(), 2u) << m["effects_found"];
  EXPECT_EQ(err.find("nan"), std::string::npos) << err;
}

// A time budget that runs out is said like a cap: log, stopped_by, never "explained". A budget
// of a microsecond is used up before the first round; one of an hour changes nothing.
TEST_F(SelectionStop, ATimeBudgetThatRunsOutIsSaidAndNeverExplained) {
  std::string err;
  const nlohmann::json m = Identify("budget", "--time-budget 1e-6", &err);
  EXPECT_EQ(m["stopped_by"], "time_budget");
  EXPECT_EQ(m["effects_found"].size(), 0u) << m["effects_found"];
  EXPECT_NE(m["verdict"], "explained");
  EXPECT_NE(err.find("stop: time budget 1e-06 s used up"), std::string::npos) << err;
  const nlohmann::json hour = Identify("hour", "--time-budget 3600", &err);
  EXPECT_EQ(hour["stopped_by"], "held_out");
  EXPECT_EQ(hour["effects_found"].size(), 2u);
  const CommandResult bad = RunCommand(BinDir() + "/flexbench identify --declared " + SourceDir() +
                                       "/models/planar3.declared.yaml --calibration " +
                                       (tmp_.path() / "cal.csv").string() + " --validation " +
                                       (tmp_.path() / "val.csv").string() + " --time-budget -1" +
                                       " --out " + (tmp_.path() / "bad").string());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(LastLine(bad.err).find("--time-budget"), std::string::npos) << bad.err;
}

}  // namespace
}  // namespace flexbench::testing
