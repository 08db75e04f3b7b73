// Test oracles for Lie-group code: central finite differences on the manifold and a fixed set of
// test points (identity, near identity, random with a fixed seed, near pi), as in manif's
// common_tester.h. Also used by tests/unit/kinematics.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <functional>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/lie/sampling.h"
#include "estimators/lie/se3.h"
#include "estimators/lie/so3.h"

namespace flexbench::lie::testing {

// Step sizes for every finite-difference check (central differences: O(h^2) truncation,
// O(eps / h) rounding; both are below 1e-7 on this range).
inline const std::vector<double> kFdSteps = {1e-6, 1e-5, 1e-4};

// "Manifold traits" for the types the Jacobians map between: X (+) d and Y (-) X.
inline SE3 Plus(const SE3& X, const Eigen::VectorXd& d) { return X * SE3::Exp(Vec6(d)); }
inline Eigen::VectorXd Minus(const SE3& Y, const SE3& X) { return X.Between(Y).Log(); }
inline Mat3 Plus(const Mat3& R, const Eigen::VectorXd& d) { return R * SO3Exp(Vec3(d)); }
inline Eigen::VectorXd Minus(const Mat3& Y, const Mat3& X) { return SO3Log(X.transpose() * Y); }
template <int N>
Eigen::Matrix<double, N, 1> Plus(const Eigen::Matrix<double, N, 1>& x, const Eigen::VectorXd& d) {
  return x + d;
}
template <int N>
Eigen::VectorXd Minus(const Eigen::Matrix<double, N, 1>& y, const Eigen::Matrix<double, N, 1>& x) {
  return y - x;
}

inline int Dof(const SE3&) { return 6; }
inline int Dof(const Mat3&) { return 3; }
template <int N>
int Dof(const Eigen::Matrix<double, N, 1>&) {
  return N;
}
inline int Dof(const Eigen::VectorXd& x) { return static_cast<int>(x.size()); }
inline Eigen::VectorXd Plus(const Eigen::VectorXd& x, const Eigen::VectorXd& d) { return x + d; }
inline Eigen::VectorXd Minus(const Eigen::VectorXd& y, const Eigen::VectorXd& x) { return y - x; }

// J_f_x by central differences: column k = (f(x (+) h e_k) (-) f(x (+) -h e_k)) / 2h. With right
// perturbations on both sides, this converges to the right Jacobian at O(h^2).
template <class In, class F>
Eigen::MatrixXd NumericalJacobian(const F& f, const In& x, double h) {
  const int n = Dof(x);
  const auto f0 = f(x);
  Eigen::MatrixXd J(Dof(f0), n);
  for (int k = 0; k < n; ++k) {
    Eigen::VectorXd d = Eigen::VectorXd::Zero(n);
    d[k] = h;
    const auto f_plus = f(Plus(x, d));
    const auto f_minus = f(Plus(x, Eigen::VectorXd(-d)));
    J.col(k) = Minus(f_plus, f_minus) / (2.0 * h);
  }
  return J;
}

// Max-abs error scaled by the Jacobian's size, for EXPECT_LT(..., tol).
inline double JacobianError(const Eigen::MatrixXd& J, const Eigen::MatrixXd& J_num) {
  return (J - J_num).cwiseAbs().maxCoeff() / std::max(1.0, J_num.cwiseAbs().maxCoeff());
}

// A named test point.
struct PoseCase {
  std::string name;
  SE3 X;
};
inline void PrintTo(const PoseCase& c, std::ostream* os) { *os << c.name; }

// A unit vector with a fixed direction per seed.
inline Vec3 RandomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Vec3 v;
  for (int i = 0; i < 3; ++i) v[i] = n(rng);
  return v.normalized();
}

inline Vec6 TangentWithAngle(std::mt19937_64& rng, double angle, double rho_norm) {
  Vec6 xi;
  xi.segment<3>(kTransIdx) = rho_norm * RandomUnit(rng);
  xi.segment<3>(kRotIdx) = angle * RandomUnit(rng);
  return xi;
}

// Identity, near identity, random and near-pi poses; the same list on every run.
inline std::vector<PoseCase> StandardPoseCases() {
  std::mt19937_64 rng(20240611);
  std::vector<PoseCase> cases;
  cases.push_back({"identity", SE3::Identity()});
  cases.push_back({"near_identity_1em9", SE3::Exp(TangentWithAngle(rng, 1e-9, 1e-9))});
  cases.push_back({"near_identity_1em6", SE3::Exp(TangentWithAngle(rng, 1e-6, 1e-6))});
  for (int i = 0; i < 5; ++i) {
    cases.push_back({"random_" + std::to_string(i), RandomSE3(rng, 2.0)});
  }
  cases.push_back({"near_pi", SE3::Exp(TangentWithAngle(rng, M_PI - 1e-2, 1.5))});
  return cases;
}

// Tangent vectors: zero, tiny, both sides of the Taylor-branch switches (0.2, 0.5 rad), large,
// near pi.
struct TangentCase {
  std::string name;
  Vec6 xi;
};
inline void PrintTo(const TangentCase& c, std::ostream* os) {
  *os << c.name << " [" << c.xi.transpose() << "]";
}

inline std::vector<TangentCase> StandardTangentCases() {
  std::mt19937_64 rng(777);
  std::vector<TangentCase> cases;
  cases.push_back({"zero", Vec6::Zero()});
  const std::vector<std::pair<std::string, double>> angles = {{"1em9", 1e-9},
                                                              {"1em6", 1e-6},
                                                              {"1em4_below", 0.99e-4},
                                                              {"1em4_above", 1.01e-4},
                                                              {"0p2_below", 0.1999},
                                                              {"0p2_above", 0.2001},
                                                              {"0p5_below", 0.4999},
                                                              {"0p5_above", 0.5001},
                                                              {"1p0", 1.0},
                                                              {"2p5", 2.5},
                                                              {"pi_minus_1em2", M_PI - 1e-2}};
  for (const auto& [name, angle] : angles) {
    cases.push_back({"angle_" + name, TangentWithAngle(rng, angle, 1.3)});
  }
  Vec6 pure_translation = Vec6::Zero();
  pure_translation.segment<3>(kTransIdx) = Vec3(0.3, -1.2, 0.7);
  cases.push_back({"pure_translation", pure_translation});
  return cases;
}

}  // namespace flexbench::lie::testing
