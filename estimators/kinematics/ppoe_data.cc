#include "estimators/kinematics/ppoe_data.h"

namespace flexbench::kinematics {

PpoeData::PpoeData(const PpoeModel& model)
    : T_base_frame(model.num_frames()),
      T_parent_frame(model.num_frames()),
      Sigma_frame(model.num_frames(), Mat6::Zero()),
      sigma_is_zero(model.num_frames(), 1),
      num_frames(model.num_frames()),
      nq(model.nq()) {}

}  // namespace flexbench::kinematics
