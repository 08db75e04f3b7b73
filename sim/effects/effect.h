// Effects: one entry per physical effect the truth can contain. A scenario switches effects on
// by name; an effect that is off leaves the truth equal to the nominal model in its respect
// (passive joints locked at their reference, zero extra mass, no offset...).
//
//   effects:
//     base_compliance: {}
//     payload: {mass_kg: 0.5, offset_m: [0, 0, 0.05]}
//
// Names are the effect table's (estimators/kinematics/effect_table.h): an effect identification
// can find is a row, whose name it reports (the truth's `joint_offset@j3` is what
// `flexbench identify` names `joint_offset@j3`, with the same sign); the others are its
// truth-only rows. docs/design.md ("Effect vocabulary") has the list; each former name is still
// read.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "sim/config.h"
#include "sim/effects/truth_setup.h"
#include "sim/params.h"

namespace flexbench::sim {

class Effect {
 public:
  virtual ~Effect() = default;
  const std::string& name() const { return name_; }
  // Reads and validates the parameters (model-independent checks).
  virtual void Configure(const ComponentParams& params) = 0;
  // Whether the model has what the effect acts on; `why` says what is missing.
  virtual bool SupportedBy(const ModelCatalog& catalog, const mjModel* m,
                           std::string* why) const = 0;
  // Applies the effect to the truth. Throws InputError (naming the effect's entry and the model)
  // when the model lacks a part the parameters name.
  virtual void Apply(TruthSetup& setup) const = 0;
  // Parameters as given, for logs and summaries ("" when none).
  virtual std::string Describe() const { return ""; }

  // Where the effect was configured ("file:line: effect 'x'"), for messages.
  const std::string& where() const { return where_; }
  void set_identity(std::string name, std::string where) {
    name_ = std::move(name);
    where_ = std::move(where);
  }

 private:
  std::string name_;
  std::string where_;
};

struct EffectEntry {
  const char* name;  // a simulated row's of the effect table, or a truth-only row's
  const char* description;
  std::unique_ptr<Effect> (*make)();
  // The name scenario files and MJCF annotations (<custom><text name="effect:NAME">) used
  // before truth and identification shared one vocabulary (nullptr: none). Still read, with a
  // note; the effect's name() is then the former name, which joint_offset needs
  // (encoder_offset took the encoder's error, the opposite sign).
  const char* former_name = nullptr;
};

// The registry name for a current or former name ("" when unknown): two spellings of one effect
// are one effect.
std::string CanonicalEffectName(const std::string& name);

// The explicit list of effects (EffectRegistry in sim/effects/effects.cc).
const std::vector<EffectEntry>& EffectRegistry();

// A configured effect by name; throws InputError "<where>: unknown effect '<name>' (known: ...)".
std::unique_ptr<Effect> MakeEffect(const std::string& name, const ComponentParams& params);
// Same from YAML text for the parameters (tests and programmatic set-ups).
std::unique_ptr<Effect> MakeEffect(const std::string& name, const std::string& params_yaml = "{}");

// Reads an `effects:` mapping {name: {params}} of a scenario file.
std::vector<std::unique_ptr<Effect>> ParseEffects(const ConfigNode& effects);

using EffectList = std::vector<std::unique_ptr<Effect>>;

}  // namespace flexbench::sim
