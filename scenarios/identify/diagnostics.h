// Residual diagnostics: structure the chosen effects leave in the data, and where it lives.
//
// Each row's position residual e (whitened) is projected on the sensitivity s_k of the point to
// joint k's angle: z = s.e / |s|^2 is the angle error of joint k that explains the row best
// (rad), with weight |s|^2. Per joint, z is regressed (weighted least squares) on
//   - harmonics of the joint angle, 1..3 cycles per revolution (a transmission error, an
//     eccentric bearing, an error curve), and
//   - the gravity torque the joint holds and its cube (a spring, a stiffening spring);
// and each residual coordinate on the row order within the data (drift over time) and on the
// set it belongs to (a placement or session that errs as a whole). Each test
// compares the reduction of the weighted sum of squares with the remaining variance,
// stat = (SS0 - SS1) / (SS1 / (n - p - 1)), asymptotically chi-square with p degrees of freedom
// under pure noise; its p-value is the significance. The strongest finding is the one with the
// smallest p-value.
#pragma once
#include <vector>

#include "scenarios/identify/identify.h"

namespace flexbench::identify {

ResidualFinding FindResidualStructure(const EffectModel& em, const DataSet& data,
                                      const RowLoads& loads, const Fit& fit,
                                      const IdentifyOptions& opt);

// The candidates of `candidates` that a significant finding points to (needs_evidence families
// at its joint: periodic -> transmission_error, joint_error_curve; load -> stiffening_spring).
std::vector<int> CandidatesFor(const EffectModel& em, const ResidualFinding& finding,
                               const std::vector<int>& candidates);

}  // namespace flexbench::identify
