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

  void Run(RunContext& ctx) override {
    Json& metrics = (*ctx.summary)["metrics"];
    std::ofstream cov_csv(ctx.out->File("covariances.csv"));
    cov_csv << "case,method,row,c0,c1,c2,c3,c4,c5\n";
    for (size_t i = 0; i < cases_.size(); ++i) {
      const Case& c = cases_[i];
      const sim::DeclaredChain& chain = chains_[i];
      const kinematics::PpoeModel& model = chain.model;
      const FrameId ee = chain.end_effector;
      kinematics::PpoeData data(model);
      kinematics::ForwardKinematicsWithCovariance(model, data, c.q, lie::CompoundOrder::kSecond);
      const Mat6 cov2 = data.Sigma_frame[ee];
      kinematics::ForwardKinematicsWithCovariance(model, data, c.q, lie::CompoundOrder::kFourth);
      const Mat6 cov4 = data.Sigma_frame[ee];
      const lie::SE3 mean = data.T_base_frame[ee];

      // Monte Carlo of the exact chain, one stream per case.
      std::mt19937_64 rng(ctx.seed * 1000003ULL + i);
      kinematics::ChainSampler sampler(model);
      std::vector<lie::SE3> poses(model.num_frames());
      const RangeSpace range2 = Range(cov2);
      const RangeSpace range4 = Range(cov4);
      const double q2 = stats::ChiSquareQuantile(confidence_, range2.rank());
      const double q4 = stats::ChiSquareQuantile(confidence_, range4.rank());
      // The covariance oracle: control-variate Monte Carlo of the exact chain (chain_sampler.h).
      std::mt19937_64 rng_cov(ctx.seed * 1000003ULL + 500 + i);
      const Mat6 cov_mc =
          sampler.SampleCovarianceControlVariate(c.q, ee, covariance_samples_, rng_cov);
      Mat6 cov_raw = Mat6::Zero();
      int inside2 = 0, inside4 = 0;
      std::ofstream samples_csv(ctx.out->File("samples_" + c.name + ".csv"));
      samples_csv << "sample,x_m,y_m,z_m,rho_x,rho_y,rho_z,theta_x,theta_y,theta_z,maha2_2nd\n";
      PpoeFigure figure;
      figure.title = "case " + c.name;
      for (int s = 0; s < samples_; ++s) {
        sampler.Sample(c.q, rng, &poses);
        const Vec6 xi = mean.Between(poses[ee]).Log();
        cov_raw += xi * xi.transpose();
        const double d2 = range2.Mahalanobis2(xi);
        inside2 += d2 <= q2;
        inside4 += range4.Mahalanobis2(xi) <= q4;
        if (s < plot_samples_) {
          const Vec3& p = poses[ee].translation();
          char line[320];
          std::snprintf(line, sizeof(line),
                        "%d,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", s, p.x(), p.y(),
                        p.z(), xi[0], xi[1], xi[2], xi[3], xi[4], xi[5], d2);
          samples_csv << line;
          figure.samples.push_back(p);
        }
      }
      cov_raw /= samples_;
      const std::pair<const char*, const Mat6*> covs[] = {
          {"ppoe_2nd", &cov2}, {"ppoe_4th", &cov4}, {"monte_carlo", &cov_mc}};
      for (const auto& [method, cov] : covs) {
        for (int r = 0; r < 6; ++r) {
          cov_csv << c.name << "," << method << "," << r;
          for (int k = 0; k < 6; ++k) {
            char v[32];
            std::snprintf(v, sizeof(v), ",%.9g", (*cov)(r, k));
            cov_csv << v;
          }
          cov_csv << "\n";
        }
      }
      Json& m = metrics[c.name];
      m["inside80_frac"] = static_cast<double>(inside2) / samples_;
      m["inside80_frac_4th"] = static_cast<double>(inside4) / samples_;
      m["cov_rank"] = range2.rank();
      m["cov_relerr_2nd"] = RelativeFrobenius(cov2, cov_mc);
      m["cov_relerr_4th"] = RelativeFrobenius(cov4, cov_mc);
      // The plain second moment of the region samples, as a check on the oracle.
      m["cov_relerr_raw_mc"] = RelativeFrobenius(cov_raw, cov_mc);
      m["ee_pos_std_mc_m"] = std::sqrt(cov_mc.topLeftCorner<3, 3>().trace());

      // The 80% region's boundary: for every pair of principal directions, the ellipse of the
      // scaled covariance in the tangent space mapped through Exp (the paper's construction).
      for (int a = 0; a < range2.rank(); ++a) {
        for (int b = a; b < range2.rank(); ++b) {
          for (int k = 0; k < 180; ++k) {
            const double phi = 2.0 * M_PI * k / 180.0;
            const Vec6 xi =
                std::sqrt(q2 * range2.lambda[a]) * std::cos(phi) * range2.V.col(a) +
                (b == a ? Vec6::Zero()
                        : Vec6(std::sqrt(q2 * range2.lambda[b]) * std::sin(phi) * range2.V.col(b)));
            figure.boundary.push_back(mean.Plus(xi).translation());
          }
        }
      }
      // The arm: the nominal positions of the joint frames and the end effector.
      kinematics::ForwardKinematics(model, data, c.q);
      figure.arm.push_back(Vec3::Zero());
      for (const auto& f : model.frames()) {
        if (f.name.rfind("joint/", 0) == 0)
          figure.arm.push_back(data.T_base_frame[model.FindFrame(f.name)].translation());
      }
      figure.arm.push_back(mean.translation());
      DrawPpoeFigure(figure, (ctx.out->FramesDir() / ("planar3_" + c.name + ".png")).string());
      ctx.progress("cases", static_cast<int>(i + 1), static_cast<int>(cases_.size()));
    }
  }

 private:
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
