// Compiled only by the ctest case build.estimators_refuse_mujoco, which expects this to FAIL with
// the #error of estimators/forbidden/mujoco/mujoco.h: what a MuJoCo include in estimators/ or
// in an estimator unit test would meet.
#include <mujoco/mujoco.h>

#include "estimators/lie/se3.h"

int BoundaryProbe() { return 0; }
