// One vocabulary for effects: a truth effect that identification can find carries the
// name identification reports for it, so a scenario's `truth.effects` and `expected:` speak the
// same words. The effect table says which rows the truth simulates and lists the effects only the
// truth has; the truth's effect list (sim/effects/) must match it, so a new truth effect takes a
// side there; the dynamic rows (sim/dynamic_effects.h) are truth effects as well. Former names are
// still read and build the same truth.
#include <gtest/gtest.h>

#include <map>
#include <set>
#include <string>

#include "estimators/error.h"
#include "estimators/kinematics/effect_table.h"
#include "scenarios/identify/effect_model.h"
#include "sim/dynamic_effects.h"
#include "sim/effects/effect.h"

namespace flexbench::identify {
namespace {

TEST(EffectVocabulary, TheTruthSimulatesWhatTheEffectTableSays) {
  // Every name the truth must have: the simulated rows and the truth-only rows.
  std::map<std::string, std::string> expected;  // name -> which table
  std::set<std::string> fit_only;
  for (const kinematics::EffectRow& r : kinematics::EffectTable()) {
    if (r.truth == kinematics::EffectTruth::kSimulated) {
      expected[r.name] = "simulated row";
    } else {
      fit_only.insert(r.name);
    }
  }
  for (const kinematics::TruthOnlyRow& r : kinematics::TruthOnlyTable()) {
    EXPECT_TRUE(expected.emplace(r.name, "truth-only row").second) << r.name << " is a row too";
    EXPECT_EQ(kinematics::FindEffect(r.name), nullptr) << r.name;
  }
  for (const sim::DynamicRow& r : sim::DynamicTable()) {
    EXPECT_TRUE(expected.emplace(r.name, "dynamic row").second) << r.name << " is a row too";
  }
  std::set<std::string> simulated;
  for (const sim::EffectEntry& e : sim::EffectRegistry()) {
    EXPECT_TRUE(expected.count(e.name))
        << e.name << " is in sim/effects/ but neither a simulated row nor a truth-only row"
        << (fit_only.count(e.name) ? " (its row says kFitOnly)" : "");
    simulated.insert(e.name);
  }
  for (const auto& [name, table] : expected) {
    EXPECT_TRUE(simulated.count(name)) << name << " is a " << table << " without truth physics";
  }
}

// The identification names its families from the table's rows.
TEST(EffectVocabulary, IdentificationNamesTheRows) {
  for (int t = 0; t < kinematics::kNumEffectKinds; ++t) {
    const auto type = static_cast<EffectType>(t);
    EXPECT_STREQ(ToString(type), kinematics::Row(type).name);
    EXPECT_EQ(kinematics::FindEffect(kinematics::FileName(type, 1)), &kinematics::Row(type));
  }
}

TEST(EffectVocabulary, FormerNamesAreNoCurrentNameAndStillRead) {
  std::set<std::string> current;
  for (const sim::EffectEntry& e : sim::EffectRegistry()) {
    EXPECT_TRUE(current.insert(e.name).second) << "two entries named " << e.name;
  }
  for (const sim::EffectEntry& e : sim::EffectRegistry()) {
    if (!e.former_name) continue;
    EXPECT_FALSE(current.count(e.former_name)) << e.former_name;
    try {  // without its parameters an effect may refuse; it must not be unknown
      EXPECT_EQ(sim::MakeEffect(e.former_name)->name(), e.former_name);
    } catch (const InputError& error) {
      EXPECT_EQ(std::string(error.what()).find("unknown effect"), std::string::npos)
          << error.what();
    }
  }
}

}  // namespace
}  // namespace flexbench::identify
