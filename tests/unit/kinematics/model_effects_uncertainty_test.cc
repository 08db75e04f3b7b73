// The identified parameters' uncertainty as PPOE sources (ModelEffects::Uncertainty)
// against Monte Carlo: draw every parameter from N(value, std^2), apply the drawn effects with
// EffectiveChain (no uncertainty, no declared sources) and compare the sample covariance of
// Log(T_nominal^-1 T_drawn) at the end effector with the covariance EffectiveChain's sources
// give the 2nd-order FK. One case per term, and all at once.
#include <gtest/gtest.h>

#include <functional>
#include <random>
#include <string>

#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/model_effects.h"
#include "tests/unit/kinematics/ppoe_test_models.h"

namespace flexbench::kinematics {
namespace {

// A 4R arm on a compliant plate, links along x, one fixed part turned (so parent and local axes
// differ), masses on every link; no declared sources.
struct Arm {
  PpoeModel model{"arm4"};
  FrameId plate, j1, j2, j3, j4, ee;
  Arm() {
    plate = model.AddFrame(kBaseFrame, "plate", lie::SE3::Translation(Vec3(0, 0, 0.1)));
    j1 = model.AddLink(plate, "j1", lie::SE3::Translation(Vec3(0, 0, 0.05)),
                       Joint::Revolute(Vec3::UnitZ()));
    j2 = model.AddLink(j1, "j2", lie::SE3::Translation(Vec3(0, 0, 0.3)),
                       Joint::Revolute(Vec3::UnitY()));
    j3 = model.AddLink(j2, "j3", lie::SE3::Translation(Vec3(0.4, 0, 0)),
                       Joint::Revolute(Vec3::UnitY()));
    const Mat3 Rz = Eigen::AngleAxisd(0.5, Vec3::UnitZ()).toRotationMatrix();
    j4 = model.AddLink(j3, "j4", lie::SE3(Rz, Vec3(0.35, 0.05, 0)), Joint::Revolute(Vec3::UnitX()));
    ee = model.AddFrame(j4, "ee", lie::SE3::Translation(Vec3(0.1, 0, 0.02)));
  }
};

ModelEffects Values(const Arm& a) {
  ModelEffects e = ModelEffects::None(a.model);
  for (FrameId f : {a.j1, a.j2, a.j3, a.j4, a.ee}) e.masses[f] = {2.0, Vec3(0.2, 0.0, 0.0)};
  for (FrameId f : {a.plate, a.j1, a.j2, a.j3, a.j4, a.ee}) e.on_path[f] = 1;
  e.joints[0].offset = 0.01;
  e.joints[0].harmonic = {2e-3, -1e-3, 0, 0, 5e-4, 0};
  e.joints[1].compliance = 2e-4;
  e.joints[2].backlash = 1e-3;
  e.joints[2].cubic = 1e-8;
  e.frames[a.j3].bend = 1e-4;
  e.frames[a.j3].bend_start = a.j2;
  e.frames[a.j3].bend_dir = Vec3::UnitX();
  e.frames[a.j4].offset = Vec3(1e-3, -2e-3, 5e-4);
  e.frames[a.j4].dlen = 2e-3;
  e.frames[a.j4].tilt = Vec3(0, 1e-3, 0);
  e.frames[a.j2].origin << 1e-3, 0, 2e-3, 0, 1e-3, 0;
  e.mount = a.plate;
  e.mount_compliance = Eigen::Vector2d(3e-4, 5e-4);
  e.thermal = 1e-4;
  return e;
}

// One uncertain term: how it widens the ModelEffects' uncertainty, and how a draw perturbs the
// values (n: a standard normal source).
struct Term {
  std::string name;
  std::function<void(const Arm&, ModelEffects*)> declare;
  std::function<void(const Arm&, std::normal_distribution<double>&, std::mt19937_64&,
                     ModelEffects*)>
      draw;
};

std::vector<Term> Terms() {
  using N = std::normal_distribution<double>;
  using R = std::mt19937_64;
  std::vector<Term> t;
  t.push_back(
      {"joint_offset", [](const Arm&, ModelEffects* e) { e->uncertainty.joints[0].offset = 4e-6; },
       [](const Arm&, N& n, R& r, ModelEffects* e) { e->joints[0].offset += 2e-3 * n(r); }});
  t.push_back({"harmonic",
               [](const Arm&, ModelEffects* e) {
                 e->uncertainty.joints[0].harmonic = {1e-6, 4e-6, 0, 0, 2.25e-6, 0};
               },
               [](const Arm&, N& n, R& r, ModelEffects* e) {
                 e->joints[0].harmonic[0] += 1e-3 * n(r);
                 e->joints[0].harmonic[1] += 2e-3 * n(r);
                 e->joints[0].harmonic[4] += 1.5e-3 * n(r);
               }});
  t.push_back(
      {"joint_compliance",
       [](const Arm&, ModelEffects* e) { e->uncertainty.joints[1].compliance = 1e-8; },
       [](const Arm&, N& n, R& r, ModelEffects* e) { e->joints[1].compliance += 1e-4 * n(r); }});
  t.push_back(
      {"backlash", [](const Arm&, ModelEffects* e) { e->uncertainty.joints[2].backlash = 2.5e-7; },
       [](const Arm&, N& n, R& r, ModelEffects* e) { e->joints[2].backlash += 5e-4 * n(r); }});
  t.push_back({"cubic", [](const Arm&, ModelEffects* e) { e->uncertainty.joints[2].cubic = 1e-16; },
               [](const Arm&, N& n, R& r, ModelEffects* e) { e->joints[2].cubic += 1e-8 * n(r); }});
  t.push_back(
      {"link_bending", [](const Arm& a, ModelEffects* e) { e->uncertainty.bend[a.j3] = 2.5e-9; },
       [](const Arm& a, N& n, R& r, ModelEffects* e) { e->frames[a.j3].bend += 5e-5 * n(r); }});
  t.push_back({"base_compliance",
               [](const Arm&, ModelEffects* e) { e->uncertainty.mount_compliance << 1e-8, 4e-8; },
               [](const Arm&, N& n, R& r, ModelEffects* e) {
                 e->mount_compliance.x() += 1e-4 * n(r);
                 e->mount_compliance.y() += 2e-4 * n(r);
               }});
  // Translations in parent axes: at the source (local axes) they are R^T d.
  t.push_back({"link_offset",
               [](const Arm& a, ModelEffects* e) {
                 const Mat3 R = a.model.frame(a.j4).T_parent_ip.rotation();
                 const Vec3 s(1e-3, 2e-3, 5e-4);
                 e->uncertainty.frames[a.j4].block<3, 3>(kTransIdx, kTransIdx) +=
                     R.transpose() * s.cwiseAbs2().asDiagonal() * R;
               },
               [](const Arm& a, N& n, R& r, ModelEffects* e) {
                 for (int k = 0; k < 3; ++k) {
                   e->frames[a.j4].offset[k] += Vec3(1e-3, 2e-3, 5e-4)[k] * n(r);
                 }
               }});
  t.push_back(
      {"link_length",
       [](const Arm& a, ModelEffects* e) {
         const lie::SE3& T = a.model.frame(a.j4).T_parent_ip;
         const Vec3 d = T.rotation().transpose() * T.translation().normalized();
         e->uncertainty.frames[a.j4].block<3, 3>(kTransIdx, kTransIdx) += 4e-6 * d * d.transpose();
       },
       [](const Arm& a, N& n, R& r, ModelEffects* e) { e->frames[a.j4].dlen += 2e-3 * n(r); }});
  t.push_back(
      {"axis_tilt",
       [](const Arm& a, ModelEffects* e) {
         e->uncertainty.frames[a.j4](kRotIdx + 1, kRotIdx + 1) += 4e-6;
       },
       [](const Arm& a, N& n, R& r, ModelEffects* e) { e->frames[a.j4].tilt.y() += 2e-3 * n(r); }});
  t.push_back({"joint_origin",
               [](const Arm& a, ModelEffects* e) {
                 for (int k = 0; k < 6; ++k) e->uncertainty.frames[a.j2](k, k) += 1e-6;
               },
               [](const Arm& a, N& n, R& r, ModelEffects* e) {
                 for (int k = 0; k < 6; ++k) e->frames[a.j2].origin[k] += 1e-3 * n(r);
               }});
  t.push_back({"thermal_expansion",
               [](const Arm&, ModelEffects* e) { e->uncertainty.thermal = 1e-6; },
               [](const Arm&, N& n, R& r, ModelEffects* e) { e->thermal += 1e-3 * n(r); }});
  return t;
}

class UncertaintyMonteCarlo : public ::testing::TestWithParam<int> {};

TEST_P(UncertaintyMonteCarlo, SourcesMatchDrawnParameters) {
  const Arm arm;
  const std::vector<Term> terms = Terms();
  const int which = GetParam();  // -1: every term at once
  ModelEffects declared = Values(arm);
  for (int i = 0; i < static_cast<int>(terms.size()); ++i) {
    if (which < 0 || which == i) terms[i].declare(arm, &declared);
  }
  ASSERT_FALSE(declared.uncertainty.empty());
  Eigen::VectorXd q(4);
  q << 0.3, 0.5, -0.8, 0.4;
  EffectiveChain chain(arm.model, &declared);
  chain.Update(q);
  PpoeData data(chain.model());
  ForwardKinematicsWithCovariance(chain.model(), data, chain.q(), lie::CompoundOrder::kSecond);
  const lie::SE3 T0 = data.T_base_frame[arm.ee];
  const Mat6 Sigma = data.Sigma_frame[arm.ee];

  std::mt19937_64 rng(23);
  std::normal_distribution<double> n(0.0, 1.0);
  const int samples = 20000;
  Mat6 mc = Mat6::Zero();
  PpoeData d2(arm.model);
  const ModelEffects values = Values(arm);
  for (int s = 0; s < samples; ++s) {
    ModelEffects drawn = values;
    for (int i = 0; i < static_cast<int>(terms.size()); ++i) {
      if (which < 0 || which == i) terms[i].draw(arm, n, rng, &drawn);
    }
    EffectiveChain c(arm.model, &drawn);
    c.Update(q);
    ForwardKinematics(c.model(), d2, c.q());
    const Vec6 xi = T0.Between(d2.T_base_frame[arm.ee]).Log();
    mc += xi * xi.transpose() / samples;
  }
  SCOPED_TRACE(which < 0 ? std::string("all terms") : terms[which].name);
  // Relative to the largest entry: 20000 draws leave ~1-2% sampling error; linearisation less.
  EXPECT_GT(Sigma.cwiseAbs().maxCoeff(), 0.0);
  EXPECT_LT((mc - Sigma).cwiseAbs().maxCoeff(), 0.05 * Sigma.cwiseAbs().maxCoeff())
      << "Monte Carlo\n"
      << mc << "\nsources\n"
      << Sigma;
}

INSTANTIATE_TEST_SUITE_P(EachTermAndAll, UncertaintyMonteCarlo, ::testing::Range(-1, 12));

TEST(Uncertainty, NoneAddsNoSource) {
  const Arm arm;
  const ModelEffects values = Values(arm);
  EXPECT_TRUE(values.uncertainty.empty());
  EffectiveChain chain(arm.model, &values);
  Eigen::VectorXd q(4);
  q << 0.3, 0.5, -0.8, 0.4;
  chain.Update(q);
  for (FrameId f = 1; f < chain.model().num_frames(); ++f) {
    EXPECT_FALSE(chain.model().frame(f).has_source) << chain.model().frame(f).name;
  }
}

}  // namespace
}  // namespace flexbench::kinematics
