// One vocabulary for effects: a truth effect that identification can find carries the
// name identification reports for it, so a scenario's `truth.effects` and `expected:` speak the
// same words; the effects identification has no family for are listed here by name, so a new
// truth effect must take a side. Former names are still read and build the same truth.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "estimators/error.h"
#include "scenarios/identify/effect_model.h"
#include "sim/effects/effect.h"

namespace flexbench::identify {
namespace {

std::set<std::string> IdentifiedTypes() {
  std::set<std::string> names;
  // kLateralCompliance is the last enumerator (effect_model.h); a type added after it must move
  // this.
  for (int t = 0; t <= static_cast<int>(EffectType::kLateralCompliance); ++t) {
    names.insert(ToString(static_cast<EffectType>(t)));
  }
  return names;
}

TEST(EffectVocabulary, EveryTruthEffectIsNamedAsIdentificationNamesIt) {
  // Truth effects no identification family stands for: a neck of many spring joints, a camera
  // mount's sag (camera_offset is a constant pose error), a nonlinear wrist linkage (declared as
  // `coupled:`, not found), and IMU biases (not kinematics).
  const std::set<std::string> truth_only = {"neck_elasticity", "camera_mount_sag",
                                            "nonlinear_wrist", "imu_bias"};
  const std::set<std::string> identified = IdentifiedTypes();
  for (const sim::EffectEntry& e : sim::EffectRegistry()) {
    EXPECT_TRUE(identified.count(e.name) || truth_only.count(e.name))
        << e.name << " is neither an identified effect type nor listed as truth-only";
    EXPECT_FALSE(identified.count(e.name) && truth_only.count(e.name)) << e.name;
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
