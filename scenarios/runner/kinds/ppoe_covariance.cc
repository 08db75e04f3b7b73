// The PPOE paper's Fig. 3: probabilistic forward kinematics of a declared model against the
// Monte-Carlo truth of the same perturbations. For each case (a joint configuration and a set of
// active sources) the end-effector covariance is compounded to 2nd order [PPOE eqs. 15/18] and 4th
// order, and compared with 10,000 samples of the exact chain: the fraction of samples inside
// the 80% region and the relative Frobenius error of each covariance.
#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>

#include "estimators/kinematics/chain_sampler.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/stats/chi_square.h"
#include "scenarios/runner/kinds/kinds.h"
#include "scenarios/runner/kinds/ppoe_figure.h"
#include "sim/declared_chain.h"
#include "sim/mujoco_model.h"

namespace flexbench::scenarios {
namespace {

using kinematics::FrameId;

struct Case {
  std::string name;
  Eigen::VectorXd q;
  std::vector<std::string> sources;  // empty: every declared source
};

// The covariance restricted to its range: eigenvectors with eigenvalues above a relative
// tolerance. Mahalanobis distances are taken there; the rank sets the chi-square dof.
struct RangeSpace {
  Eigen::Matrix<double, 6, Eigen::Dynamic> V;  // 6 x rank
  Eigen::VectorXd lambda;
  int rank() const { return static_cast<int>(lambda.size()); }
  double Mahalanobis2(const Vec6& xi) const {
    const Eigen::VectorXd y = V.transpose() * xi;
    return (y.array().square() / lambda.array()).sum();
  }
};

RangeSpace Range(const Mat6& cov) {
  Eigen::SelfAdjointEigenSolver<Mat6> eig(0.5 * (cov + cov.transpose()));
  const double tol = 1e-9 * std::max(eig.eigenvalues().maxCoeff(), 1e-300);
  RangeSpace r;
  std::vector<int> keep;
  for (int i = 0; i < 6; ++i) {
    if (eig.eigenvalues()[i] > tol) keep.push_back(i);
  }
  r.V.resize(6, keep.size());
  r.lambda.resize(keep.size());
  for (size_t k = 0; k < keep.size(); ++k) {
    r.V.col(k) = eig.eigenvectors().col(keep[k]);
    r.lambda[k] = eig.eigenvalues()[keep[k]];
  }
  return r;
}

double RelativeFrobenius(const Mat6& approx, const Mat6& reference) {
  return (approx - reference).norm() / reference.norm();
}

class PpoeCovarianceKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    const ConfigNode declared = root.Child("declared");
    declared_ = sim::LoadDeclaredModel(declared.ResolvePath(declared.AsString()));
    model_ = sim::LoadModel(declared_.model_path);
    samples_ = root.GetInt("samples", 10000);
    covariance_samples_ = root.GetInt("covariance_samples", samples_);
    if (covariance_samples_ < 100) root.Child("covariance_samples").Fail("needs at least 100");
    plot_samples_ = root.GetInt("plot_samples", 200);
    confidence_ = root.GetDouble("confidence", 0.8);
    if (samples_ < 100) root.Child("samples").Fail("needs at least 100 samples");
    if (!(confidence_ > 0.0 && confidence_ < 1.0)) {
      root.Child("confidence").Fail("must be in (0, 1)");
    }
    const ConfigNode cases = root.Child("cases");
    for (const std::string& name : cases.Keys()) {
      const ConfigNode c = cases.Child(name);
      Case cs;
      cs.name = name;
      const ConfigNode q_node = c.Child("q_deg");
      const std::vector<double> q = q_node.AsDoubleList();
      if (q.size() != declared_.actuated_joints.size()) {
        q_node.Fail("needs " + std::to_string(declared_.actuated_joints.size()) +
                    " angles, one per actuated joint");
      }
      cs.q = Eigen::Map<const Eigen::VectorXd>(q.data(), q.size()) * (M_PI / 180.0);
      if (const auto s = c.Optional("sources")) {
        for (const ConfigNode& item : s->Items()) {
          const std::string at = item.AsString();
          bool found = false;
          for (const auto& src : declared_.sources) found = found || src.at == at;
          if (!found) item.Fail("no declared source at '" + at + "'");
          cs.sources.push_back(at);
        }
      }
      cases_.push_back(cs);
    }
    if (cases_.empty()) cases.Fail("needs at least one case");
    // Build every chain now: a bad declared file fails before any output exists.
    for (const Case& c : cases_)
      chains_.push_back(sim::BuildDeclaredChain(model_.get(), Declared(c)));
  }

  // Per case: the PPOE covariances (2nd and 4th order) -> the Monte Carlo oracle and the
  // region samples -> scores -> the covariance CSV and the figure.
  void Run(RunContext& ctx) override {
    std::ofstream cov_csv(ctx.out->File("covariances.csv"));
    cov_csv << "case,method,row,c0,c1,c2,c3,c4,c5\n";
    for (size_t i = 0; i < cases_.size(); ++i) {
      const Case& c = cases_[i];
      const Propagated p = Propagate(i);
      PpoeFigure figure;
      figure.title = "case " + c.name;
      const Sampled mc = Sample(i, p, ctx, &figure);
      WriteCovariances(c.name, p, mc.cov_mc, &cov_csv);
      Score(c.name, p, mc, (*ctx.summary)["metrics"][c.name]);
      DrawCase(i, p, &figure, ctx);
      ctx.progress("cases", static_cast<int>(i + 1), static_cast<int>(cases_.size()));
    }
  }

 private:
  // A case's end-effector pose and its PPOE covariances, with their ranges and 80% quantiles.
  struct Propagated {
    lie::SE3 mean;
    Mat6 cov2, cov4;
    RangeSpace range2, range4;
    double q2 = 0.0, q4 = 0.0;
  };

  // What the Monte Carlo gives: the oracle's covariance, the plain second moment of the
  // region samples, and how many of those fall inside each order's 80% region.
  struct Sampled {
    Mat6 cov_mc, cov_raw;
    int inside2 = 0, inside4 = 0;
  };

  Propagated Propagate(size_t i) const {
    const kinematics::PpoeModel& model = chains_[i].model;
    const FrameId ee = chains_[i].end_effector;
    kinematics::PpoeData data(model);
    Propagated p;
    kinematics::ForwardKinematicsWithCovariance(model, data, cases_[i].q,
                                                lie::CompoundOrder::kSecond);
    p.cov2 = data.Sigma_frame[ee];
    kinematics::ForwardKinematicsWithCovariance(model, data, cases_[i].q,
                                                lie::CompoundOrder::kFourth);
    p.cov4 = data.Sigma_frame[ee];
    p.mean = data.T_base_frame[ee];
    p.range2 = Range(p.cov2);
    p.range4 = Range(p.cov4);
    p.q2 = stats::ChiSquareQuantile(confidence_, p.range2.rank());
    p.q4 = stats::ChiSquareQuantile(confidence_, p.range4.rank());
    return p;
  }

  // Monte Carlo of the exact chain, one stream per case: the covariance oracle
  // (control-variate, chain_sampler.h) and the region samples (the first plot_samples_ into
  // samples_<case>.csv and the figure).
  Sampled Sample(size_t i, const Propagated& p, RunContext& ctx, PpoeFigure* figure) const {
    const Case& c = cases_[i];
    const kinematics::PpoeModel& model = chains_[i].model;
    const FrameId ee = chains_[i].end_effector;
    std::mt19937_64 rng(ctx.seed * 1000003ULL + i);
    kinematics::ChainSampler sampler(model);
    std::vector<lie::SE3> poses(model.num_frames());
    std::mt19937_64 rng_cov(ctx.seed * 1000003ULL + 500 + i);
    Sampled out;
    out.cov_mc = sampler.SampleCovarianceControlVariate(c.q, ee, covariance_samples_, rng_cov);
    out.cov_raw = Mat6::Zero();
    std::ofstream samples_csv(ctx.out->File("samples_" + c.name + ".csv"));
    samples_csv << "sample,x_m,y_m,z_m,rho_x,rho_y,rho_z,theta_x,theta_y,theta_z,maha2_2nd\n";
    for (int s = 0; s < samples_; ++s) {
      sampler.Sample(c.q, rng, &poses);
      const Vec6 xi = p.mean.Between(poses[ee]).Log();
      out.cov_raw += xi * xi.transpose();
      const double d2 = p.range2.Mahalanobis2(xi);
      out.inside2 += d2 <= p.q2;
      out.inside4 += p.range4.Mahalanobis2(xi) <= p.q4;
      if (s < plot_samples_) {
        const Vec3& pos = poses[ee].translation();
        char line[320];
        std::snprintf(line, sizeof(line), "%d,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n",
                      s, pos.x(), pos.y(), pos.z(), xi[0], xi[1], xi[2], xi[3], xi[4], xi[5], d2);
        samples_csv << line;
        figure->samples.push_back(pos);
      }
    }
    out.cov_raw /= samples_;
    return out;
  }

  static void WriteCovariances(const std::string& name, const Propagated& p, const Mat6& cov_mc,
                               std::ofstream* csv) {
    const std::pair<const char*, const Mat6*> covs[] = {
        {"ppoe_2nd", &p.cov2}, {"ppoe_4th", &p.cov4}, {"monte_carlo", &cov_mc}};
    for (const auto& [method, cov] : covs) {
      for (int r = 0; r < 6; ++r) {
        *csv << name << "," << method << "," << r;
        for (int k = 0; k < 6; ++k) {
          char v[32];
          std::snprintf(v, sizeof(v), ",%.9g", (*cov)(r, k));
          *csv << v;
        }
        *csv << "\n";
      }
    }
  }

  void Score(const std::string& name, const Propagated& p, const Sampled& mc, Json& m) const {
    m["inside80_frac"] = static_cast<double>(mc.inside2) / samples_;
    m["inside80_frac_4th"] = static_cast<double>(mc.inside4) / samples_;
    m["cov_rank"] = p.range2.rank();
    m["cov_relerr_2nd"] = RelativeFrobenius(p.cov2, mc.cov_mc);
    m["cov_relerr_4th"] = RelativeFrobenius(p.cov4, mc.cov_mc);
    // The plain second moment of the region samples, as a check on the oracle.
    m["cov_relerr_raw_mc"] = RelativeFrobenius(mc.cov_raw, mc.cov_mc);
    m["ee_pos_std_mc_m"] = std::sqrt(mc.cov_mc.topLeftCorner<3, 3>().trace());
  }

  // The 80% region's boundary: for every pair of principal directions, the ellipse of the
  // scaled covariance in the tangent space mapped through Exp (the paper's construction); the
  // arm at its nominal joint frames; planar3_<case>.png.
  void DrawCase(size_t i, const Propagated& p, PpoeFigure* figure, RunContext& ctx) const {
    const RangeSpace& r = p.range2;
    for (int a = 0; a < r.rank(); ++a) {
      for (int b = a; b < r.rank(); ++b) {
        for (int k = 0; k < 180; ++k) {
          const double phi = 2.0 * M_PI * k / 180.0;
          const Vec6 xi =
              std::sqrt(p.q2 * r.lambda[a]) * std::cos(phi) * r.V.col(a) +
              (b == a ? Vec6::Zero()
                      : Vec6(std::sqrt(p.q2 * r.lambda[b]) * std::sin(phi) * r.V.col(b)));
          figure->boundary.push_back(p.mean.Plus(xi).translation());
        }
      }
    }
    const kinematics::PpoeModel& model = chains_[i].model;
    kinematics::PpoeData data(model);
    kinematics::ForwardKinematics(model, data, cases_[i].q);
    figure->arm.push_back(Vec3::Zero());
    for (const auto& f : model.frames()) {
      if (f.name.rfind("joint/", 0) == 0)
        figure->arm.push_back(data.T_base_frame[model.FindFrame(f.name)].translation());
    }
    figure->arm.push_back(p.mean.translation());
    DrawPpoeFigure(*figure,
                   (ctx.out->FramesDir() / ("planar3_" + cases_[i].name + ".png")).string());
  }

  sim::DeclaredModel Declared(const Case& c) const {
    sim::DeclaredModel d = declared_;
    if (!c.sources.empty()) {
      d.sources.clear();
      for (const auto& src : declared_.sources) {
        for (const auto& keep : c.sources) {
          if (src.at == keep) d.sources.push_back(src);
        }
      }
    }
    return d;
  }

  sim::DeclaredModel declared_;
  sim::MjModelPtr model_;
  int samples_ = 10000;
  // Draws of the control-variate covariance oracle.
  int covariance_samples_ = 10000;
  int plot_samples_ = 200;
  double confidence_ = 0.8;
  std::vector<Case> cases_;
  std::vector<sim::DeclaredChain> chains_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakePpoeCovarianceKind() {
  return std::make_unique<PpoeCovarianceKind>();
}

}  // namespace flexbench::scenarios
