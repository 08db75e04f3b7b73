#include "scenarios/runner/kinds/kinds.h"
#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

const std::vector<KindEntry>& ScenarioKinds() {
  // One line per kind.
  static const std::vector<KindEntry> kinds = {
      {"smoke", "one rendered frame through every layer: MJCF, OSMesa, libapriltag, truth",
       MakeSmokeKind},
  };
  return kinds;
}

}  // namespace flexbench::scenarios
