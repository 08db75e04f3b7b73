// What the data can observe of a candidate, and which candidates make the same correction.
//
// A candidate's sensitivity Jc (whitened residuals per parameter) is compared with what the
// model already explains: its columns with the span of the fit's own unknowns (effects and
// group points) projected out, R = (I - P_fit) Jc. Directions of the candidate's parameter
// space that R still sees (|R v| / |Jc v| above a tolerance) are observable; the others are
// absorbed by the rest and cannot be identified from this data.
//
// An equivalence set: with every other chosen effect and the nuisance parameters projected
// out, the correction a chosen effect makes, d = R_e alpha_e, lies (to a cosine) in the span
// of another candidate's R_c — that candidate explains the data as well. Every member is named,
// with the minimum-norm parameters that reproduce d (the observable part) and the directions
// of its parameters the data does not see.
#pragma once
#include <Eigen/Core>
#include <Eigen/QR>
#include <functional>
#include <string>
#include <vector>

#include "scenarios/identify/identify.h"

namespace flexbench::identify {

// Projection onto the complement of span(J_fit); J_fit may have no columns.
class Projector {
 public:
  explicit Projector(const Eigen::MatrixXd& J_fit);
  Eigen::MatrixXd Apply(const Eigen::MatrixXd& M) const;
  void ApplyInPlace(Eigen::MatrixXd* M) const;  // the same without a copy of M

 private:
  Eigen::MatrixXd Q_;  // orthonormal basis of span(J_fit)
};

// Observable directions of a candidate (columns of unit length in its parameter space; none
// when nothing is observable). `*rel`: the largest |R v| / |Jc v| over the directions tried.
Eigen::MatrixXd ObservableBasis(const Eigen::MatrixXd& Jc, const Projector& proj, double tol,
                                double* rel);

// ObservableBasis of candidate c beside `fit`'s unknowns, at fit's state. With many rows the
// two Jacobians are never held whole: the triangular factor R of [J_fit J_c], accumulated over
// row blocks (Problem::ForEachRowBlock; [J_fit J_c] = Q R, so R has their norms, projections
// and singular values), stands for them.
Eigen::MatrixXd CandidateBasis(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                               const Fit& fit, int c, const IdentifyOptions& opt, double* rel);

// The Jacobian of `fit`'s unknowns at its state, and the sensitivity of candidate c there.
Eigen::MatrixXd FitJacobian(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                            const Fit& fit, const IdentifyOptions& opt);
// Its whitened residuals there.
Eigen::VectorXd FitResiduals(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                             const Fit& fit, const IdentifyOptions& opt);
Eigen::MatrixXd CandidateJacobian(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                                  const Fit& fit, int c, const IdentifyOptions& opt);
// CandidateJacobian for each of `cs`, the analytic ones in one pass over the rows.
std::vector<Eigen::MatrixXd> CandidateJacobians(const EffectModel& em, const DataSet& data,
                                                const RowLoads& loads, const Fit& fit,
                                                const std::vector<int>& cs,
                                                const IdentifyOptions& opt);
// The same handed to fn(i, columns of cs[i]) in order, computed in batches of at most
// `max_bytes` of columns (one pass over the rows per batch), so memory does not grow with the
// number of candidates times the rows.
void ForEachCandidateJacobian(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                              const Fit& fit, const std::vector<int>& cs,
                              const IdentifyOptions& opt, double max_bytes,
                              const std::function<void(size_t, const Eigen::MatrixXd&)>& fn);
// The most candidates' columns take at once (more candidates: more passes).
inline constexpr double kCandidateColumnBytes = 64.0 * (1 << 20);

// Equivalence sets of the chosen effects of `fit` among `candidates`; fills
// result->equivalence and result->indistinguishable, and the effects' display names.
void FindEquivalents(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                     const Fit& fit, const std::vector<int>& candidates, const IdentifyOptions& opt,
                     IdentifyResult* result);

// Candidates (of `candidates`, not chosen, in no equivalence set) with no observable direction
// given `fit`: result->unidentifiable.
void FindUnidentifiable(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                        const Fit& fit, const std::vector<int>& candidates,
                        const IdentifyOptions& opt, IdentifyResult* result);

// Several chosen effects that together make the correction of one simpler candidate of the
// whole library (fewer parameters; in the candidate list or not): e.g. a translation plus a
// tilt of one joint's frame that is exactly a rotation about the previous joint's axis. The
// data cannot tell them apart, so the cause is not singled out: result->attribution_unique is
// cleared and the finding logged (result->simpler).
struct SimplerEquivalent {
  std::vector<int> effects;  // indices into fit.active
  int candidate = -1;        // the simpler candidate making the same correction
};
std::vector<SimplerEquivalent> SimplerEquivalents(const EffectModel& em, const DataSet& data,
                                                  const RowLoads& loads, const Fit& fit,
                                                  const IdentifyOptions& opt);
void FindSimplerEquivalents(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                            const Fit& fit, const std::vector<int>& candidates,
                            const IdentifyOptions& opt, IdentifyResult* result);

}  // namespace flexbench::identify
