// Occam's razor on the verdict: a planted single encoder offset (MuJoCo's truth, the sockets'
// contacts simulated by the runner, not by the identification) is named, and an alternative that
// reaches the same held-out error only with more parameters (a translation plus a tilt of the
// next joint's frame) is reported as also fitting: it is no evidence against the simpler cause,
// so the verdict is "explained".
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "scenarios/runner/runner.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;

TEST(ClosedLoopAttribution, ASingleOffsetIsExplainedAndTheCostlierAlternativeAlsoFits) {
  const std::string scenario = SourceDir() + "/scenarios/closed_loop_encoder_offset.yaml";
  for (const int seed : {2, 3, 4, 11}) {
    TempDir tmp;
    scenarios::RunOptions o;
    o.scenario_path = scenario;
    o.out_dir = (tmp.path() / "out").string();
    o.seed = seed;
    o.quiet = true;
    ASSERT_EQ(scenarios::RunScenario(o), scenarios::kExitOk) << seed;
    const nlohmann::json s = nlohmann::json::parse(ReadFile(tmp.path() / "out" / "summary.json"));
    const nlohmann::json& m = s["metrics"];
    const nlohmann::json& id = s["identification"];
    EXPECT_EQ(m["effects_found"], nlohmann::json::array({"joint_offset@j3"})) << seed;
    EXPECT_EQ(m["verdict"], "explained") << seed << ": " << id["steps"].dump(1);
    EXPECT_TRUE(m["attribution_unique"].get<bool>()) << seed;
    ASSERT_EQ(id["also_fits"].size(), 1u) << seed << ": " << id["steps"].dump(1);
    const nlohmann::json& a = id["also_fits"][0];
    EXPECT_EQ(a["banned"], "joint_offset@j3") << seed;
    EXPECT_GE(a["effects"].size(), 2u) << seed << ": " << a.dump();
    EXPECT_EQ(a["chosen_num_params"], 1) << seed;
    EXPECT_GT(a["num_params"].get<int>(), 1) << seed;
    // As good on held-out data: within the share that would otherwise make it ambiguous.
    EXPECT_LT(a["cv_err"].get<double>(), 1.25 * m["cv_err_after"].get<double>()) << seed;
    bool said = false;
    for (const auto& line : id["steps"]) {
      said = said || line.get<std::string>().find("also fits, with") != std::string::npos;
    }
    EXPECT_TRUE(said) << seed << ": " << id["steps"].dump(1);
  }
}

}  // namespace
}  // namespace flexbench::testing
