// The guard that keeps the closed loop honest: for every effect type a closed_loop
// scenario plants in its truth, the same scenario with that type taken out of the candidate
// library must not claim to have explained the data, and must not make the validation error
// worse. A library that lacks the cause has to say so, not name a wrong one.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "scenarios/identify/effect_model.h"
#include "scenarios/runner/runner.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::identify {
namespace {

namespace fs = std::filesystem;

// Every family of the candidate library on the scenario's robot.
std::vector<std::string> AllFamilies(const std::string& declared) {
  const sim::DeclaredModel d = sim::LoadDeclaredModel(declared);
  const sim::MjModelPtr m = sim::LoadModel(d.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), d);
  const EffectModel em(m.get(), chain, chain.end_effector);
  std::vector<std::string> out;
  for (const Candidate& c : em.candidates()) {
    const std::string name = ToString(c.type);
    if (std::find(out.begin(), out.end(), name) == out.end()) out.push_back(name);
  }
  return out;
}

class ClosedLoopGuard : public ::testing::TestWithParam<std::string> {};

TEST_P(ClosedLoopGuard, WithoutThePlantedFamilyItDoesNotClaimAnExplanation) {
  const fs::path src = fs::path(testing::SourceDir()) / "scenarios" / (GetParam() + ".yaml");
  YAML::Node root = YAML::LoadFile(src.string());
  std::set<std::string> planted;
  for (const auto& e : root["truth"]["expected"]) {
    const std::string name = e.as<std::string>();
    planted.insert(name.substr(0, name.find('@')));
  }
  ASSERT_FALSE(planted.empty());
  for (const std::string& family : planted) {
    YAML::Node guarded = YAML::Clone(root);
    for (const char* key : {"model", "declared"}) {
      guarded[key] = (src.parent_path() / root[key].as<std::string>()).lexically_normal().string();
    }
    YAML::Node cands(YAML::NodeType::Sequence);
    for (const std::string& f : AllFamilies(guarded["declared"].as<std::string>())) {
      // Without angle-dependent errors at all: the generic error curve goes with the
      // transmission error it contains.
      const bool angle = family == "transmission_error" || family == "joint_error_curve";
      if (f == family || (angle && (f == "transmission_error" || f == "joint_error_curve"))) {
        continue;
      }
      cands.push_back(f);
    }
    guarded["candidates"] = cands;
    guarded.remove("gates");
    const fs::path dir = fs::temp_directory_path() /
                         ("flexbench_guard_" + GetParam() + "_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    {
      std::ofstream out(dir / "guard.yaml");
      out << guarded;
    }
    scenarios::RunOptions o;
    o.scenario_path = (dir / "guard.yaml").string();
    o.out_dir = (dir / "out").string();
    ASSERT_EQ(scenarios::RunScenario(o), scenarios::kExitOk) << family;
    const nlohmann::json s = nlohmann::json::parse(testing::ReadFile(dir / "out" / "summary.json"));
    const nlohmann::json& m = s["metrics"];
    const std::string verdict = m["verdict"];
    EXPECT_NE(verdict, "explained")
        << GetParam() << " without " << family << ": found " << m["effects_found"].dump()
        << ", validation " << m["val_err_before_m"] << " -> " << m["val_err_after_m"]
        << ", overlap " << m["effect_overlap"] << ", condition " << m["condition_number"];
    EXPECT_LE(m["val_err_after_m"].get<double>(), m["val_err_before_m"].get<double>())
        << GetParam() << " without " << family;
    // No augmented model is shipped unless the validation data supports it.
    if (verdict == "unexplained" || verdict == "no_effect") {
      EXPECT_FALSE(fs::exists(dir / "out" / "declared_augmented.yaml"));
    }
    fs::remove_all(dir);
  }
}

INSTANTIATE_TEST_SUITE_P(
    Planted, ClosedLoopGuard,
    ::testing::Values("closed_loop_base_plate", "closed_loop_link_bending",
                      "closed_loop_gear_elasticity", "closed_loop_encoder_offset",
                      "closed_loop_backlash", "closed_loop_payload_and_plate",
                      "closed_loop_offset_and_gear", "closed_loop_transmission_error",
                      "closed_loop_stiffening_spring", "closed_loop_error_curve"));

}  // namespace
}  // namespace flexbench::identify

namespace flexbench::identify {
namespace {

// Bad selection input: exit 2 with one line naming the file, and nothing written.
TEST(ClosedLoopBadInput, FoldsThatCannotExistAndUnknownFamilies) {
  const fs::path src = fs::path(testing::SourceDir()) / "scenarios" / "closed_loop_backlash.yaml";
  const YAML::Node root = YAML::LoadFile(src.string());
  const fs::path dir =
      fs::temp_directory_path() / ("flexbench_badsel_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const auto run = [&](const YAML::Node& n) {
    {
      std::ofstream out(dir / "bad.yaml");
      out << n;
    }
    const std::string cmd = testing::BinDir() + "/flexbench run " + (dir / "bad.yaml").string() +
                            " --out " + (dir / "out").string();
    return testing::RunCommand(cmd);
  };
  YAML::Node base = YAML::Clone(root);
  for (const char* key : {"model", "declared"}) {
    base[key] = (src.parent_path() / root[key].as<std::string>()).lexically_normal().string();
  }
  {
    YAML::Node n = YAML::Clone(base);
    n["calibration"]["simulate"]["placements"] = 1;
    n["folds_by"] = "set";
    const testing::CommandResult r = run(n);
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find("cross-validation by set needs at least two sets"), std::string::npos)
        << r.err;
    EXPECT_FALSE(fs::exists(dir / "out"));
  }
  {
    YAML::Node n = YAML::Clone(base);
    n["candidates"].push_back("joint_offsett");
    const testing::CommandResult r = run(n);
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find("bad.yaml"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("joint_offsett"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir / "out"));
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace flexbench::identify
