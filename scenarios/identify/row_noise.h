// How consistent the declared and the augmented models are on measured rows: each row's noise
// (the stated point noise, or the joint readings' noise through the kinematics), the fitted
// parameters' covariance under that noise, the mean NEES of the rows' errors under the PPOE
// position covariance [PPOE eq. 18] plus that noise, and the factor on the declared sources that
// makes the NEES consistent (what the augmented model's sources are scaled by).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/kinematics/ppoe_model.h"
#include "scenarios/identify/identify.h"
#include "sim/declared_chain.h"

namespace flexbench::identify {

// What the rows' noise is made of, on the declared chain the effect model was built on.
struct NoiseModel {
  const EffectModel* em = nullptr;
  const sim::DeclaredChain* chain = nullptr;
  double point_std_m = 1e-4;     // a measured point's noise, when the readings' is not stated
  double reading_std_rad = 0.0;  // the joint readings' noise (0: not stated)
};

// Mean NEES over the rows in metres of their point errors p (row r's marker) under `model`'s
// PPOE position covariance (null: the declared chain's), its sources scaled by source_scale,
// plus noise[r]; each row against its group's mean or its measured point. NaN without such rows.
double MeanNees(const NoiseModel& nm, const DataSet& d, const std::vector<Vec3>& p,
                const std::vector<Mat3>& noise, double source_scale = 1.0,
                const kinematics::PpoeModel* model = nullptr);

// Per row, the covariance of its residual that is not the PPOE sources' (with `res`, the
// augmented model's, also the fitted parameters' share).
std::vector<Mat3> RowNoise(const NoiseModel& nm, const DataSet& d, const RowLoads& L,
                           const IdentifyResult* res);

// Replaces the fit's parameter covariance (and the effects' stds) by the least-squares sandwich
// under the stated readings' noise; returns rss / what that noise explains (NaN: nothing fitted).
double UseReadingNoiseCovariance(const NoiseModel& nm, const DataSet& cal, const RowLoads& L,
                                 IdentifyResult* res);

// The factor on `model`'s sources that brings the rows' mean NEES to `target` (bisection on a
// log scale, within [1e-12 or 1e-6, 1e6]).
double SourceScale(const NoiseModel& nm, const DataSet& d, const std::vector<Vec3>& p,
                   const std::vector<Mat3>& noise, double target,
                   const kinematics::PpoeModel& model);

// The upper 95% bound of the rows' mean NEES without sources, when their errors are the noise
// and the fitted parameters' error every row shares (stats::SharedNeesBounds).
double SharedNeesUpperBound(const NoiseModel& nm, const DataSet& d, const RowLoads& L,
                            const IdentifyResult& res, const std::vector<Mat3>& noise);

}  // namespace flexbench::identify
