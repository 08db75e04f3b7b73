#include "sim/effects/truth_setup.h"

namespace flexbench::sim {

TruthSetup NominalSetup(mjModel* model, const ModelCatalog* catalog, const std::string& name) {
  TruthSetup s;
  s.model = model;
  s.catalog = catalog;
  s.model_name = name;
  s.released.assign(model->njnt, 0);
  s.gear.assign(model->njnt, GearSpec{});
  s.joint_offset.assign(model->njnt, 0.0);
  s.servo_delay.assign(model->njnt, 0.0);
  s.stribeck.assign(model->njnt, StribeckSpec{});
  // Passive joints and linkages no effect claims are part of the model's own physics: always
  // free (a linkage: always following its drivers).
  for (const JointEntry& j : catalog->joints) {
    if (j.role != JointRole::kActuated && j.effect.empty()) s.released[j.id] = 1;
  }
  return s;
}

}  // namespace flexbench::sim
