#include "estimators/pf/bingham.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <vector>

#include "estimators/error.h"
#include "estimators/format.h"
#include "estimators/pf/bessel.h"

namespace flexbench::pf {
namespace {

std::string Format(const Vec4& v) {
  return "[" + ShortNum(v(0)) + ", " + ShortNum(v(1)) + ", " + ShortNum(v(2)) + ", " +
         ShortNum(v(3)) + "]";
}

// Gauss-Kronrod 7/15 nodes on [-1, 1] (abscissae >= 0; the rest by symmetry) and weights.
constexpr std::array<double, 8> kXgk = {
    0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
    0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
    0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
    0.207784955007898467600689403773245, 0.0};
constexpr std::array<double, 8> kWgk = {
    0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
    0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
    0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
    0.204432940075298892414161999234649, 0.209482141084727828012999174891714};
// Gauss 7-point weights at kXgk[1], kXgk[3], kXgk[5], kXgk[7].
constexpr std::array<double, 4> kWg = {
    0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
    0.381830050505118944950369775488975, 0.417959183673469387755102040816327};

struct Segment {
  double a = 0.0;
  double b = 0.0;
  double value = 0.0;
  double error = 0.0;
};

template <class F>
Segment Kronrod(const F& f, double a, double b) {
  const double c = 0.5 * (a + b);
  const double h = 0.5 * (b - a);
  const double fc = f(c);
  double k = fc * kWgk[7];
  double g = fc * kWg[3];
  for (int j = 0; j < 7; ++j) {
    const double dx = h * kXgk[j];
    const double f2 = f(c - dx) + f(c + dx);
    k += kWgk[j] * f2;
    if (j % 2 == 1) g += kWg[j / 2] * f2;
  }
  Segment s;
  s.a = a;
  s.b = b;
  s.value = k * h;
  s.error = std::abs((k - g) * h);
  return s;
}

// Globally adaptive integration of a smooth, positive f on [0, 1] to relative accuracy rel_tol.
// The initial partition is geometric towards both ends, where concentrated integrands peak.
template <class F>
double IntegrateUnitInterval(const F& f, double rel_tol) {
  std::vector<double> breaks = {0.0};
  for (int k = 16; k >= 1; --k) breaks.push_back(std::pow(10.0, -k));
  breaks.push_back(0.5);
  for (int k = 1; k <= 8; ++k) breaks.push_back(1.0 - std::pow(10.0, -k));
  breaks.push_back(1.0);
  std::vector<Segment> segs;
  segs.reserve(4096);
  for (size_t i = 0; i + 1 < breaks.size(); ++i)
    segs.push_back(Kronrod(f, breaks[i], breaks[i + 1]));
  for (int iter = 0; iter < 4000; ++iter) {
    double total = 0.0;
    double err = 0.0;
    size_t worst = 0;
    for (size_t i = 0; i < segs.size(); ++i) {
      total += segs[i].value;
      err += segs[i].error;
      if (segs[i].error > segs[worst].error) worst = i;
    }
    if (err <= rel_tol * std::abs(total) || segs[worst].b - segs[worst].a < 1e-300) break;
    const Segment w = segs[worst];
    const double mid = 0.5 * (w.a + w.b);
    segs[worst] = Kronrod(f, w.a, mid);
    segs.push_back(Kronrod(f, mid, w.b));
  }
  double total = 0.0;
  for (const Segment& s : segs) total += s.value;
  return total;
}

}  // namespace

void ValidateBinghamLambda(const Vec4& lambda, const std::string& what) {
  if (!lambda.allFinite()) {
    throw InputError(what + ": bingham lambda must be finite, got " + Format(lambda));
  }
  if (!(lambda(0) <= lambda(1) && lambda(1) <= lambda(2) && lambda(2) <= lambda(3))) {
    throw InputError(what +
                     ": bingham lambda must be sorted ascending (lambda1 <= lambda2 <= "
                     "lambda3 <= lambda4, [PF eq. 9]), got " +
                     Format(lambda));
  }
  if (lambda(3) != 0.0) {
    const Vec4 shifted = lambda - Vec4::Constant(lambda(3));
    throw InputError(what +
                     ": bingham lambda must be shifted so that its largest entry is 0 "
                     "[PF eqs. 8-9], got " +
                     Format(lambda) + "; the same distribution is " + Format(shifted));
  }
}

void ValidateUnitQuaternion(const Vec4& x, const char* what) {
  if (!x.allFinite()) {
    throw InputError(std::string(what) + ": quaternion has a NaN or infinite entry: " + Format(x));
  }
  const double n = x.norm();
  if (std::abs(n - 1.0) > kUnitQuaternionTol) {
    std::ostringstream msg;
    msg << what << ": quaternion " << Format(x) << " is not unit length (norm " << n << ")";
    throw InputError(msg.str());
  }
}

double BinghamLogNormaliser(const Vec4& lambda_in) {
  if (!lambda_in.allFinite()) {
    throw InputError("BinghamLogNormaliser: lambda must be finite, got " + Format(lambda_in));
  }
  std::array<double, 4> l = {lambda_in(0), lambda_in(1), lambda_in(2), lambda_in(3)};
  std::sort(l.begin(), l.end());
  const double shift = l[3];
  for (double& v : l) v -= shift;
  const double l1 = l[0], l2 = l[1], l3 = l[2];  // l4 = 0
  const auto h = [&](double u) {
    return std::exp(u * l2) * BesselI0Scaled(0.5 * u * (l2 - l1)) *
           BesselI0Scaled(0.5 * (1.0 - u) * (-l3));
  };
  const double integral = IntegrateUnitInterval(h, 1e-13);
  return shift + std::log(2.0 * M_PI * M_PI) + std::log(integral);
}

Bingham::Bingham(const Vec4& lambda, const Mat4& M) : lambda_(lambda), M_(M) {
  ValidateBinghamLambda(lambda, "Bingham");
  if (!M.allFinite() || (M.transpose() * M - Mat4::Identity()).cwiseAbs().maxCoeff() > 1e-9) {
    throw InputError("Bingham: M must be orthogonal (max |M^T M - I| <= 1e-9)");
  }
  A_ = M_ * lambda_.asDiagonal() * M_.transpose();
  A_ = 0.5 * (A_ + A_.transpose());
  log_c_ = BinghamLogNormaliser(lambda_);
}

Bingham Bingham::AxisSymmetric(double l, const Vec3& axis) {
  if (!(l < 0.0) || !std::isfinite(l)) {
    std::ostringstream msg;
    msg << "Bingham::AxisSymmetric: concentration must be finite and < 0, got " << l;
    throw InputError(msg.str());
  }
  const double n = axis.norm();
  if (!(n > 1e-12) || !std::isfinite(n)) throw InputError("Bingham::AxisSymmetric: zero axis");
  const Vec3 a = axis / n;
  // Two unit vectors orthogonal to a (a right-handed triad b1, b2, a).
  const Vec3 helper = std::abs(a.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  const Vec3 b1 = (helper - helper.dot(a) * a).normalized();
  const Vec3 b2 = a.cross(b1);
  Mat4 M = Mat4::Zero();
  M.block<3, 1>(0, 0) = b1;
  M.block<3, 1>(0, 1) = b2;
  M.block<3, 1>(0, 2) = a;
  M(3, 3) = 1.0;
  return Bingham(Vec4(l, l, 0.0, 0.0), M);
}

double Bingham::UnnormalisedLogDensity(const Vec4& x) const {
  ValidateUnitQuaternion(x, "Bingham density");
  return x.dot(A_ * x);
}

BinghamRotationForm Bingham::RotationForm(const Quat& q_obs) const {
  ValidateUnitQuaternion(Vec4(q_obs.x(), q_obs.y(), q_obs.z(), q_obs.w()), "Bingham observation");
  const Mat4& A = A_;  // indices 0..3 = x, y, z, w
  // q^T A q = tr(A)/4 + sum_ij G(i,j) R(i,j) for the rotation matrix R of q: from
  // 4x^2 = 1 + R00 - R11 - R22, 4xy = R01 + R10, 4wx = R21 - R12, and so on.
  Mat3 G;
  G(0, 0) = 0.25 * (A(0, 0) - A(1, 1) - A(2, 2) + A(3, 3));
  G(1, 1) = 0.25 * (-A(0, 0) + A(1, 1) - A(2, 2) + A(3, 3));
  G(2, 2) = 0.25 * (-A(0, 0) - A(1, 1) + A(2, 2) + A(3, 3));
  G(0, 1) = 0.5 * (A(0, 1) - A(2, 3));
  G(1, 0) = 0.5 * (A(0, 1) + A(2, 3));
  G(0, 2) = 0.5 * (A(0, 2) + A(1, 3));
  G(2, 0) = 0.5 * (A(0, 2) - A(1, 3));
  G(1, 2) = 0.5 * (A(1, 2) - A(0, 3));
  G(2, 1) = 0.5 * (A(1, 2) + A(0, 3));
  // R_err = R_obs R_pred^T: sum_ij G_ij sum_m R_obs(i,m) R_pred(j,m) = sum_jm (G^T R_obs)(j,m)
  // R_pred(j,m).
  BinghamRotationForm form;
  form.c0 = 0.25 * A.trace();
  form.C = G.transpose() * q_obs.normalized().toRotationMatrix();
  return form;
}

BinghamSampler::BinghamSampler(const Bingham& dist) : M_(dist.M()) {
  a_ = -dist.lambda();
  // b in (0, 4] with sum 1 / (b + 2 a_i) = 1; the left side decreases in b, is +inf at 0 (a_4 =
  // 0) and <= 1 at b = 4. Bisection to full precision.
  double lo = 0.0;
  double hi = 4.0;
  for (int it = 0; it < 200; ++it) {
    const double mid = 0.5 * (lo + hi);
    double sum = 0.0;
    for (int i = 0; i < 4; ++i) sum += 1.0 / (mid + 2.0 * a_(i));
    (sum > 1.0 ? lo : hi) = mid;
    if (hi - lo <= 1e-15 * hi) break;
  }
  b_ = hi;
  for (int i = 0; i < 4; ++i) {
    omega_(i) = 1.0 + 2.0 * a_(i) / b_;
    stddev_(i) = 1.0 / std::sqrt(omega_(i));
  }
  log_bound_ = 0.5 * (4.0 - b_) - 2.0 * std::log(4.0 / b_);
}

double BinghamSampler::Normal(std::mt19937_64& rng) {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  for (;;) {
    const double u = 2.0 * (static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0)) - 1.0;
    const double v = 2.0 * (static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0)) - 1.0;
    const double s = u * u + v * v;
    if (s >= 1.0 || s == 0.0) continue;
    const double f = std::sqrt(-2.0 * std::log(s) / s);
    spare_ = v * f;
    has_spare_ = true;
    return u * f;
  }
}

Vec4 BinghamSampler::Sample(std::mt19937_64& rng) {
  for (;;) {
    ++proposed_;
    Vec4 z;
    for (int i = 0; i < 4; ++i) z(i) = stddev_(i) * Normal(rng);
    const double n = z.norm();
    if (!(n > 0.0)) continue;
    const Vec4 w = z / n;  // in M's eigenbasis
    double xax = 0.0;
    double xox = 0.0;
    for (int i = 0; i < 4; ++i) {
      xax += a_(i) * w(i) * w(i);
      xox += omega_(i) * w(i) * w(i);
    }
    const double log_ratio = -xax + 2.0 * std::log(xox) + log_bound_;
    const double u = (static_cast<double>(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    if (std::log(u) < log_ratio) {
      ++accepted_;
      Vec4 x = M_ * w;
      if (x(3) < 0.0) x = -x;
      return x;
    }
  }
}

}  // namespace flexbench::pf
