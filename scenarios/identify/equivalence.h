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

class Problem;

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

// The columns that cols(block) gives for each row block of `pr` (Problem::ForEachRowBlock),
// stacked: C itself while pr is not in row blocks, else the triangular factor R of C = Q R,
// accumulated block by block. R has C's inner products (R^T R = C^T C), so its norms,
// projections and singular values, without C ever being held for every row. `*compressed`
// (optional): whether R it is.
Eigen::MatrixXd StackedColumns(const Problem& pr,
                               const std::function<Eigen::MatrixXd(const Problem& block)>& cols,
                               bool* compressed = nullptr);

// Columns for the stages that compare candidates with a fit: the fit's Jacobian at its state,
// its residuals there, the columns of some candidates always and of a batch of others. Whole,
// or (with many rows) the parts of StackedColumns' R of [J_fit r J_fixed J_batch] — the same
// products, so the same projections, bases and equivalences to rounding.
struct ColumnBatch {
  Eigen::MatrixXd fit;                 // J_fit
  Eigen::VectorXd r;                   // the residuals (when asked for)
  std::vector<Eigen::MatrixXd> fixed;  // of each `fixed` candidate
  std::vector<Eigen::MatrixXd> batch;  // of cs[begin], cs[begin + 1], ...
  size_t begin = 0;
  int rows = 0;             // residual entries the columns stand for
  bool compressed = false;  // R's parts (fit, fixed: new in each batch), not the columns
};
// fn for each batch of `cs` (at least once, with an empty batch when cs is): at most
// kCandidateColumnBytes of columns a batch, so memory grows neither with the candidates nor
// (in row blocks) with the rows.
void ForEachColumnBatch(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                        const Fit& fit, const std::vector<int>& fixed, const std::vector<int>& cs,
                        bool residuals, const IdentifyOptions& opt,
                        const std::function<void(const ColumnBatch&)>& fn);
// The most columns a batch takes at once (more candidates: more passes over the rows).
inline constexpr double kCandidateColumnBytes = 64.0 * (1 << 20);

// ObservableBasis of candidate c beside `fit`'s unknowns, at fit's state (from its
// ColumnBatch: with many rows, the triangular factor of [J_fit J_c]).
Eigen::MatrixXd CandidateBasis(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                               const Fit& fit, int c, const IdentifyOptions& opt, double* rel);

// The Jacobian of `fit`'s unknowns at its state, its whitened residuals there, and the
// sensitivity of candidate c there, whole (the references the batches are tested against).
Eigen::MatrixXd FitJacobian(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                            const Fit& fit, const IdentifyOptions& opt);
Eigen::VectorXd FitResiduals(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                             const Fit& fit, const IdentifyOptions& opt);
Eigen::MatrixXd CandidateJacobian(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                                  const Fit& fit, int c, const IdentifyOptions& opt);

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
