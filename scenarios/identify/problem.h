// The least-squares problem behind identification: whitened residuals of a data set under a
// declared chain augmented by a set of candidate effects, and its Levenberg-Marquardt fit.
//
// Unknowns x = [alpha; group points; frame poses]. Each active effect e moves its candidate's
// parameters only along the columns of a basis B_e (theta_e = B_e alpha_e): the identity when every
// direction of the candidate is observable, fewer columns when some direction lies in the span of
// the other unknowns (selection keeps only the observable directions instead of dropping the
// candidate). A measurement frame f (DataSet::frames) contributes xi_f (6), T_base_frame = T_ref
// Exp(xi_f); a row measured in it compares the prediction with the measurement mapped into the base
// frame (a rigid map: the same distance as in the tracker frame), and a frame with a prior adds the
// residual xi_f / std (6 entries after the distances).
#pragma once
#include <Eigen/Core>
#include <functional>
#include <string>
#include <vector>

#include "estimators/format.h"
#include "scenarios/identify/identify.h"

namespace flexbench::identify {

// Number of parameters of the candidates `active` (sum of their num_params).
int NumTheta(const EffectModel& em, const std::vector<int>& active);

// BIC = N ln(RSS / N) + k ln N.
double Bic(double rss, int n, int k);

// `opt` for one of several tasks run at once on `threads` threads (parallel.h ForEachTask):
// its row passes on one thread then (the same bits: a pass's result does not depend on it).
IdentifyOptions TaskOptions(const IdentifyOptions& opt, int threads);

// Residual entries of one row: 3 (point, group), 6 (pose), 2 (pixel, gravity).
int RowDim(const Observation& o);

// Pixel of a base-frame point; far off when behind the camera, so a fit never goes there.
Eigen::Vector2d Project(const CameraModel& cam, const lie::SE3& T_base_cam, const Vec3& p_base);

// The base frame's up direction (a unit vector, -g): MuJoCo's gravity in the base frame
// (EffectModel::g_base) turned by the gravity_tilt of the declared file and of `active`
// (kinematics::TiltedGravity), as the loads see it.
Vec3 GravityUp(const EffectModel& em, const std::vector<int>& active, const double* theta);

// An orthonormal basis (columns) of the plane normal to the unit vector `up`: a gravity row's
// residual is the measured up's offset from the predicted one in that plane.
Eigen::Matrix<double, 3, 2> NormalPlane(const Vec3& up);

// The camera with the active camera_offset (if any) applied.
lie::SE3 CameraPose(const EffectModel& em, const DataSet& data, const std::vector<int>& active,
                    const double* theta);

class Problem {
 public:
  // `basis`: per active effect its B_e (num_params x m_e); empty: identity for all.
  // `rows`: the rows of `data` (and `loads`) it fits, read in place (a cross-validation fold's
  // rows, not copied); null: all. Only for data without groups (a subset renumbers them).
  Problem(const EffectModel& em, const DataSet& data, const RowLoads& loads,
          const std::vector<int>& active, const std::vector<Eigen::MatrixXd>& basis,
          const IdentifyOptions& opt, const std::vector<int>* rows = nullptr);

  int num_alpha() const { return num_alpha_; }
  int num_theta() const { return num_theta_; }
  int num_params() const {
    return frame_col(static_cast<int>(data_.frames.size())) + 3 * num_offsets_;
  }
  int num_residuals() const {
    return rows_dim_ + static_cast<int>(data_.distances.size()) + 6 * num_priors_;
  }
  // Column of frame f's xi in x.
  int frame_col(int f) const {
    return num_alpha_ + 3 * static_cast<int>(data_.groups.size()) + 6 * f;
  }
  // T_base_frame of every measurement frame at state x.
  std::vector<lie::SE3> FramePoses(const Eigen::VectorXd& x) const;
  // Column of marker k's unknown offset in x (-1: declared, not fitted).
  int offset_col(int k) const {
    return k < static_cast<int>(offset_col_.size()) ? offset_col_[k] : -1;
  }
  // Each marker's offset at state x (zero where declared); empty when none is unknown.
  std::vector<Vec3> MarkerOffsets(const Eigen::VectorXd& x) const;
  int row_offset(size_t r) const { return offset_[r]; }
  // Residual entries of the rows (the distances and priors follow them).
  int rows_dim() const { return rows_dim_; }
  // The rows in blocks, for passes whose memory must not grow with the rows: fn(block, at) with
  // `block` this problem on opt.row_block consecutive rows (the last block takes the rest) and `at`
  // the residual offset of its first row here; the first block's residuals end with the
  // priors. One call fn(*this, 0) while the rows are fewer than two blocks or the data has
  // groups (a block would renumber them): then what fn computes has the bits of one pass.
  void ForEachRowBlock(const std::function<void(const Problem& block, int at)>& fn) const;
  // Whether ForEachRowBlock hands out blocks (else the problem whole).
  bool InRowBlocks() const;
  // Its rows in `data` (null: all), for another problem on the same rows.
  const std::vector<int>* rows() const { return rows_; }
  // The rows it fits: the i-th one and its loads.
  size_t num_rows() const { return rows_ ? rows_->size() : data_.rows.size(); }
  const Observation& row(size_t i) const { return data_.rows[RowIndex(i)]; }
  // (Computed into ws when RowLoads keeps none for it.)
  const ConfigLoads& loads(size_t i, EffectModel::Workspace& ws) const {
    return loads_.At(RowIndex(i), row(i), ws);
  }
  const Eigen::MatrixXd& basis(size_t e) const { return basis_[e]; }
  const DataSet& data() const { return data_; }

  // theta (full candidate parameters) of x.
  Eigen::VectorXd Theta(const Eigen::VectorXd& x) const;
  // alpha that reproduces theta best (least squares in each basis).
  Eigen::VectorXd Alpha(const Eigen::VectorXd& theta) const;

  void Poses(const Eigen::VectorXd& theta, std::vector<lie::SE3>* T) const;
  Eigen::VectorXd Residuals(const Eigen::VectorXd& x) const;
  // d residuals / dx: analytic columns for the effects EffectModel::HasTangent covers (one
  // prediction a row for all of them), central differences for the others, exact columns for
  // the group points, distances and frame poses.
  Eigen::MatrixXd Jacobian(const Eigen::VectorXd& x) const;
  // Sensitivity (whitened) of the row residuals to the full parameters of candidate `c` added
  // to the model at zero, at state x: analytic where covered, else central differences.
  Eigen::MatrixXd CandidateColumns(const Eigen::VectorXd& x, int c) const;
  // The same for each of `cs`, the analytic ones in one pass over the rows.
  std::vector<Eigen::MatrixXd> CandidateColumns(const Eigen::VectorXd& x,
                                                const std::vector<int>& cs) const;
  // The same two by central differences throughout (the reference the analytic columns are
  // tested against; each column re-predicts every row twice).
  Eigen::MatrixXd NumericJacobian(const Eigen::VectorXd& x) const;
  Eigen::MatrixXd NumericCandidateColumns(const Eigen::VectorXd& x, int c) const;

 private:
  int threads() const;  // for a pass over the rows (parallel.h)
  size_t RowIndex(size_t i) const { return rows_ ? static_cast<size_t>((*rows_)[i]) : i; }
  Eigen::VectorXd ResidualsAt(const Eigen::VectorXd& x, const Eigen::VectorXd& theta,
                              const std::vector<int>& active) const;
  // Central-difference columns of active effect e (its alpha directions) into J.
  void NumericEffectColumns(const Eigen::VectorXd& x, const Eigen::VectorXd& theta, size_t e,
                            int col, int t, Eigen::MatrixXd* J) const;
  // Analytic d residuals / d theta for the full parameters of candidates `cs` (concatenated),
  // at theta of the active effects, into the columns `cols` (one per parameter, num_residuals()
  // entries each, zero beforehand; the distance rows stay zero): where the caller keeps them,
  // so that no second copy of the columns is made.
  // `poses` (optional): each row's predicted pose, which the pass computes anyway.
  // Of the rows [row_begin, row_end) only (row_end -1: all), their entries at their residual
  // offset less `base` (a block of rows in a buffer of its own).
  void TangentColumns(const Eigen::VectorXd& x, const Eigen::VectorXd& theta,
                      const std::vector<int>& cs, const std::vector<double*>& cols,
                      std::vector<lie::SE3>* poses = nullptr, int row_begin = 0, int row_end = -1,
                      int base = 0) const;
  // The same into one matrix (the parameters' columns in order).
  Eigen::MatrixXd TangentColumns(const Eigen::VectorXd& x, const Eigen::VectorXd& theta,
                                 const std::vector<int>& cs) const;
  // Per active effect: whether its analytic columns go straight into the Jacobian (its basis is
  // the identity, so the product with it would only copy them).
  std::vector<char> DirectColumns() const;
  // The analytic columns of effects with a reduced basis into J, a block of rows at a time
  // through a buffer of that block's full-parameter columns (D B per block: no copy of all the
  // rows' columns); `poses` as TangentColumns'.
  void ReducedColumns(const Eigen::VectorXd& x, const Eigen::VectorXd& theta,
                      const std::vector<int>& analytic, const std::vector<char>& direct,
                      std::vector<lie::SE3>* poses, Eigen::MatrixXd* J) const;
  // The group-point and distance columns (exact) into J.
  void PointColumns(const Eigen::VectorXd& x, Eigen::MatrixXd* J) const;
  // The frame-pose columns of the rows measured in frames and of the priors (exact) into J.
  void FrameColumns(const Eigen::VectorXd& x, Eigen::MatrixXd* J) const;
  // The unknown marker offsets' columns (exact) into J; `poses`: the rows' predicted poses at
  // x (empty: predicted here).
  void OffsetColumns(const Eigen::VectorXd& x, const std::vector<lie::SE3>& poses,
                     Eigen::MatrixXd* J) const;

  const EffectModel& em_;
  const DataSet& data_;
  const RowLoads& loads_;
  const std::vector<int>* rows_;
  std::vector<int> active_;
  std::vector<Eigen::MatrixXd> basis_;
  const IdentifyOptions& opt_;
  int num_alpha_ = 0;
  int num_theta_ = 0;
  std::vector<int> offset_;
  int rows_dim_ = 0;
  int num_priors_ = 0;
  std::vector<int> prior_row_;   // per frame: its prior's first residual, -1 without one
  int num_offsets_ = 0;          // markers with an unknown offset
  std::vector<int> offset_col_;  // per marker: its offset's column in x, -1 when declared
};

// The frame poses' xi and marker offsets of `fit` into x (zero for those the fit lacks).
void SetFrameStates(const Problem& pr, const Fit& fit, Eigen::VectorXd* x);

// The state vector x of a fit (alpha, then group points, then frame poses' xi).
Eigen::VectorXd StateOf(const Problem& pr, const Fit& fit);

// The fit of `pr`'s effects `active` at state x with sum of squares rss.
Fit MakeFit(const Problem& pr, const std::vector<int>& active, const Eigen::VectorXd& x,
            double rss);

// J^T J of `pr` at x and, with r (its residuals there), J^T r: from one Jacobian, or summed over
// row blocks (ForEachRowBlock) when the rows are many, so that no Jacobian of every row is held.
void NormalEquations(const Problem& pr, const Eigen::VectorXd& x, const Eigen::VectorXd* r,
                     Eigen::MatrixXd* A, Eigen::VectorXd* g);

// For each effect of `fit` (a fit of `pr`'s effects, at its optimum), the linearised rise of the
// sum of squares when it is removed and the other unknowns refitted: a_e^T Sigma_ee^-1 a_e,
// Sigma = (J^T J)^-1 at the fit (the Schur complement of the others; one factorisation for
// all). NaN where the information is singular.
std::vector<double> RemovalRises(const Problem& pr, const Fit& fit);

// Fits `active` (in the directions of `basis`, empty = all) plus the group points by
// Levenberg-Marquardt from `init` (theta; may be empty or shorter), on the rows `rows` of `data`
// (null: all; as Problem's).
Fit FitEffects(const EffectModel& em, const DataSet& data, const RowLoads& loads,
               const std::vector<int>& active, const std::vector<Eigen::MatrixXd>& basis,
               const Eigen::VectorXd& init, const IdentifyOptions& options,
               const std::vector<int>* rows = nullptr);

// Screening (a screening fit per candidate was most of identifying 10,000 rows): c
// added to `fit` by Levenberg-Marquardt's first step from fit's state with the columns
// already computed (J_fit: fit's Jacobian at its state, J_c: c's full-parameter columns there,
// r_fit: fit's residuals; or the parts of their triangular factor, which have the same products),
// scored by one residual pass. Where that step does not lower the sum
// of squares, FitWith from zero instead.
Fit ScreenWith(const EffectModel& em, const DataSet& data, const RowLoads& loads, const Fit& fit,
               int c, const Eigen::MatrixXd& basis_c, const Eigen::MatrixXd& J_fit,
               const Eigen::MatrixXd& J_c, const Eigen::VectorXd& r_fit,
               const IdentifyOptions& opt);

// The same fit with `fit`'s e-th effect removed (the others start from their values).
Fit FitWithout(const EffectModel& em, const DataSet& data, const RowLoads& loads, const Fit& fit,
               size_t e, const IdentifyOptions& opt);

// The same fit with candidate c added in the directions `basis_c` (from zero).
Fit FitWith(const EffectModel& em, const DataSet& data, const RowLoads& loads, const Fit& fit,
            int c, const Eigen::MatrixXd& basis_c, const IdentifyOptions& opt);

}  // namespace flexbench::identify
