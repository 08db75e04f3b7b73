#include "estimators/kinematics/model_effects.h"

#include <algorithm>
#include <cmath>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/lie/sincos.h"
#include "estimators/lie/so3.h"

namespace flexbench::kinematics {

ModelEffects ModelEffects::None(const PpoeModel& model) {
  ModelEffects e;
  e.joints.assign(model.nq(), JointTerms{});
  e.frames.assign(model.num_frames(), FrameTerms{});
  e.on_path.assign(model.num_frames(), 0);
  e.masses.assign(model.num_frames(), FrameMass{});
  e.uncertainty.joints.assign(model.nq(), JointTerms{});
  e.uncertainty.frames.assign(model.num_frames(), Mat6::Zero());
  e.uncertainty.bend.assign(model.num_frames(), 0.0);
  e.uncertainty.lateral.assign(model.num_frames(), Eigen::Vector2d::Zero());
  return e;
}

bool ModelEffects::Uncertainty::empty() const {
  for (const JointTerms& j : joints) {
    if (j.offset != 0.0 || j.backlash != 0.0 || j.compliance != 0.0 || j.cubic != 0.0) return false;
    for (double h : j.harmonic) {
      if (h != 0.0) return false;
    }
  }
  for (const Mat6& c : frames) {
    if (!c.isZero(0.0)) return false;
  }
  for (double b : bend) {
    if (b != 0.0) return false;
  }
  for (const Eigen::Vector2d& l : lateral) {
    if (!l.isZero(0.0)) return false;
  }
  return mount_compliance.isZero(0.0) && thermal == 0.0;
}

bool ModelEffects::NeedsLoads() const {
  for (const JointTerms& j : joints) {
    if (j.backlash != 0.0 || j.compliance != 0.0 || j.cubic != 0.0) return true;
  }
  for (const FrameTerms& f : frames) {
    if (f.bend != 0.0 || !f.lateral.isZero(0.0)) return true;
  }
  return !mount_compliance.isZero(0.0);
}

bool ModelEffects::FrameVaries(FrameId f) const {
  return frames[f].bend != 0.0 || !frames[f].lateral.isZero(0.0) ||
         (f == mount && !mount_compliance.isZero(0.0));
}

bool ModelEffects::empty() const {
  if (NeedsLoads() || thermal != 0.0) return false;
  for (const JointTerms& j : joints) {
    if (j.offset != 0.0) return false;
    for (double h : j.harmonic) {
      if (h != 0.0) return false;
    }
  }
  for (const FrameTerms& f : frames) {
    if (f.dlen != 0.0 || !f.offset.isZero(0.0) || !f.origin.isZero(0.0) || !f.tilt.isZero(0.0))
      return false;
  }
  return true;
}

namespace {

// Frame f's own mass with the payload where it hangs.
FrameMass WithPayload(const ModelEffects& effects, FrameId f) {
  FrameMass fm = effects.masses[f];
  if (f == effects.payload_frame) {
    fm.mass += effects.payload.mass;
    fm.first_moment += effects.payload.first_moment;
  }
  return fm;
}

}  // namespace

void SubtreeMasses(const PpoeModel& model, const PpoeData& data, const ModelEffects& effects,
                   std::vector<double>* subtree_mass, std::vector<Vec3>* subtree_first) {
  std::vector<double>& m = *subtree_mass;
  std::vector<Vec3>& s = *subtree_first;
  const int n = model.num_frames();
  for (FrameId f = 0; f < n; ++f) {
    const FrameMass fm = WithPayload(effects, f);
    m[f] = fm.mass;
    if (fm.mass == 0.0 && fm.first_moment.isZero(0.0)) {
      s[f].setZero();
      continue;
    }
    const lie::SE3& T = data.T_base_frame[f];
    s[f] = fm.mass * T.translation() + T.rotation() * fm.first_moment;
  }
  // Children have larger ids than their parents.
  for (FrameId f = n - 1; f > 0; --f) {
    const FrameId p = model.frame(f).parent;
    m[p] += m[f];
    s[p] += s[f];
  }
}

namespace {

// Sines and cosines of the two hinge angles, carried along the Newton steps of MountTilt.
struct HingeTrig {
  double sx = 0.0, cx = 1.0, sy = 0.0, cy = 1.0;
};

HingeTrig TrigAt(const Vec3& theta) {
  HingeTrig t;
  lie::SinCos(theta.x(), &t.sx, &t.cx);
  lie::SinCos(theta.y(), &t.sy, &t.cy);
  return t;
}

// sin and cos of a + d from those of a, for |d| < kSmallStep: the step's own sine and cosine
// from their series (the first terms left out, d^7 / 7! and d^6 / 6!, are below 1e-21 there).
// The coefficients are constants to multiply by: dividing by 6.0 is a division at run time.
constexpr double kSmallStep = 1e-3;
void AddSmallAngle(double d, double* s, double* c) {
  const double d2 = d * d;
  const double sd = d * (1.0 + d2 * (-1.0 / 6.0 + d2 * (1.0 / 120.0)));
  const double cd = 1.0 + d2 * (-1.0 / 2.0 + d2 * (1.0 / 24.0));
  const double s0 = *s, c0 = *c;
  *s = s0 * cd + c0 * sd;
  *c = c0 * cd - s0 * sd;
}

// The trigonometry at theta = the previous tilt + step. A Newton step from the linearised tilt
// is a few urad and the next one far less, so two angle additions replace two sincos calls (the
// same values but for the last bit); a larger step takes them afresh.
void Advance(const Vec3& theta, const Eigen::Vector2d& step, HingeTrig* t) {
  if (std::abs(step.x()) < kSmallStep && std::abs(step.y()) < kSmallStep) {
    AddSmallAngle(step.x(), &t->sx, &t->cx);
    AddSmallAngle(step.y(), &t->sy, &t->cy);
  } else {
    *t = TrigAt(theta);
  }
}

// MountRotation from the hinges' trigonometry.
Mat3 RotationFrom(const HingeTrig& t) {
  Mat3 R;
  R << t.cy, t.sy * t.sx, t.sy * t.cx,  //
      0.0, t.cx, -t.sx,                 //
      -t.sy, t.cy * t.sx, t.cy * t.cx;
  return R;
}

// What each hinge's spring holds at the tilt whose trigonometry is `t`: the load's weight moment
// M = (R(theta) s) x g about the roll axis (x, turned by the pitch) and about the pitch axis (y),
// and its derivative D = dm/dtheta. From the potential -g . R(theta) s: d/d theta_y gives y . M,
// d/d theta_x gives (R_y x) . M. With R = R_y R_x: dR/dtheta_x = R [x]x, dR/dtheta_y = [y]x R.
Eigen::Vector2d HingeMoments(const HingeTrig& t, const Vec3& s, const Vec3& g, Eigen::Matrix2d* D) {
  const Mat3 R = RotationFrom(t);
  const Vec3 Rs = R * s;
  const Vec3 M = Rs.cross(g);
  const double sy = t.sy, cy = t.cy;
  const Eigen::Vector2d m(cy * M.x() - sy * M.z(), M.y());
  if (D) {
    const Vec3 dM_x = (R * Vec3::UnitX().cross(s)).cross(g);
    const Vec3 dM_y = Vec3::UnitY().cross(Rs).cross(g);
    (*D)(0, 0) = cy * dM_x.x() - sy * dM_x.z();
    (*D)(0, 1) = cy * dM_y.x() - sy * dM_y.z() - sy * M.x() - cy * M.z();
    (*D)(1, 0) = dM_x.y();
    (*D)(1, 1) = dM_y.y();
  }
  return m;
}

// One division, not four: the Newton steps are a chain of these.
Eigen::Matrix2d Inverse2(const Eigen::Matrix2d& A) {
  const double inv_det = 1.0 / (A(0, 0) * A(1, 1) - A(0, 1) * A(1, 0));
  Eigen::Matrix2d inv;
  inv << A(1, 1) * inv_det, -A(0, 1) * inv_det, -A(1, 0) * inv_det, A(0, 0) * inv_det;
  return inv;
}

// T_parent_ip Exp(zeta q) of frame f at the joint values q.
EIGEN_ALWAYS_INLINE lie::SE3 RelativePose(const PpoeFrame& f,
                                          const Eigen::Ref<const Eigen::VectorXd>& q) {
  return f.FixedTimesMotion(f.q_index >= 0 ? q[f.q_index] : 0.0);
}

// Exp of a rotation vector below kSmallRotation rad, as lie::SO3Exp without its square root,
// divisions and sincos: sin x / x and (1 - cos x) / x^2 by their series in x^2 (the first terms
// left out, x^12 / 13! and x^12 / 14!, are below 1e-17 there). A link's bend is milliradians.
constexpr double kSmallRotation = 0.25;
Mat3 SmallRotationExp(const Vec3& w) {
  const double x2 = w.squaredNorm();
  if (!(x2 < kSmallRotation * kSmallRotation)) return lie::SO3Exp(w);
  // (-1)^k / (2k+1)! and (-1)^k / (2k+2)!, k = 0..5.
  constexpr double a1 = -1.0 / 6, a2 = 1.0 / 120, a3 = -1.0 / 5040, a4 = 1.0 / 362880,
                   a5 = -1.0 / 39916800;
  constexpr double b1 = -1.0 / 24, b2 = 1.0 / 720, b3 = -1.0 / 40320, b4 = 1.0 / 3628800,
                   b5 = -1.0 / 479001600;
  const double a = 1.0 + x2 * (a1 + x2 * (a2 + x2 * (a3 + x2 * (a4 + x2 * a5))));
  const double b = 0.5 + x2 * (b1 + x2 * (b2 + x2 * (b3 + x2 * (b4 + x2 * b5))));
  // I + a [w]x + b [w]x^2, with [w]x^2 = w w^T - x^2 I.
  Mat3 R = b * w * w.transpose();
  R.diagonal().array() += 1.0 - b * x2;
  R(0, 1) -= a * w.z();
  R(1, 0) += a * w.z();
  R(0, 2) += a * w.y();
  R(2, 0) -= a * w.y();
  R(1, 2) -= a * w.x();
  R(2, 1) += a * w.x();
  return R;
}

}  // namespace

Vec3 MountTilt(const Eigen::Vector2d& compliance, const Vec3& M0, const Vec3& first_moment,
               const Vec3& g, Eigen::Matrix2d* J_theta_c, Mat3* rotation) {
  const Vec3& s = first_moment;
  const double sg = s.dot(g);
  // The linearised equilibrium first: A = I - C S on the x, y block (S = g s^T - (s . g) I).
  const double cx = compliance.x(), cy = compliance.y();
  const Eigen::Matrix2d C = compliance.asDiagonal();
  Eigen::Matrix2d A;
  A << 1.0 - cx * (g.x() * s.x() - sg), -cx * g.x() * s.y(),  //
      -cy * g.y() * s.x(), 1.0 - cy * (g.y() * s.y() - sg);
  const double det = A(0, 0) * A(1, 1) - A(0, 1) * A(1, 0);
  if (!(det > 0.0)) {
    // The load would tip the mount over (no stable equilibrium): the linear tilt, C M0.
    if (J_theta_c) *J_theta_c = Eigen::Vector2d(M0.x(), M0.y()).asDiagonal();
    const Vec3 theta(cx * M0.x(), cy * M0.y(), 0.0);
    if (rotation) *rotation = MountRotation(theta);
    return theta;
  }
  Vec3 theta = Vec3::Zero();
  theta.head<2>() = Inverse2(A) * Eigen::Vector2d(cx * M0.x(), cy * M0.y());
  // Then the exact one, theta = C m(theta), by Newton on theta - C m(theta) from there. It
  // converges quadratically with a factor of about |C dm/dtheta| ~ c m g h (< 0.1), so once a
  // step is below 1e-8 of the tilt what is left is below rounding, and the implicit Jacobian
  // below is the derivative of what is returned (an identification differentiates it). From
  // the linearised solution (a few urad off stretched out) that is the second step.
  HingeTrig trig = TrigAt(theta);
  Eigen::Matrix2d D;
  Eigen::Vector2d m = HingeMoments(trig, s, g, &D);
  bool fresh = true;  // m and D are at theta
  for (int it = 0; it < 20; ++it) {
    const Eigen::Vector2d step =
        Inverse2(Eigen::Matrix2d::Identity() - C * D) * (C * m - theta.head<2>());
    theta.head<2>() += step;
    Advance(theta, step, &trig);
    fresh = false;
    if (step.lpNorm<Eigen::Infinity>() <= 1e-8 * theta.head<2>().lpNorm<Eigen::Infinity>()) break;
    m = HingeMoments(trig, s, g, &D);
    fresh = true;
  }
  if (J_theta_c) {
    // Implicit: (I - C D) dtheta = dC m(theta).
    if (!fresh) m = HingeMoments(trig, s, g, &D);
    *J_theta_c = Inverse2(Eigen::Matrix2d::Identity() - C * D) * m.asDiagonal();
  }
  if (rotation) *rotation = RotationFrom(trig);
  return theta;
}

void TiltAxes(const Vec3& axis, Vec3* a, Vec3* b) {
  const Vec3 w = axis.normalized();
  const Vec3 any = std::abs(w.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  *a = (any - any.dot(w) * w).normalized();
  *b = w.cross(*a);
}

Mat3 MountRotation(const Vec3& theta) { return RotationFrom(TrigAt(theta)); }

void GravityTiltAxes(const Vec3& g, Vec3* a1, Vec3* a2) {
  const Vec3 up = -g.normalized();
  const Vec3 any = std::abs(up.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  *a1 = (any - any.dot(up) * up).normalized();
  *a2 = up.cross(*a1);
}

Vec3 GravityTiltWeights(double phi1, double phi2) {
  const double t = std::hypot(phi1, phi2);
  // sin(t) / t, by its series where the quotient would lose digits.
  const double sinc = t < 1e-4 ? 1.0 - t * t / 6.0 : std::sin(t) / t;
  return Vec3(std::cos(t), sinc * phi1, sinc * phi2);
}

Vec3 TiltedGravity(const Vec3& g, double phi1, double phi2) {
  Vec3 a1, a2;
  GravityTiltAxes(g, &a1, &a2);
  const Vec3 w = GravityTiltWeights(phi1, phi2);
  return w[0] * g + w[1] * a1.cross(g) + w[2] * a2.cross(g);
}

EffectiveChain::EffectiveChain(const PpoeModel& declared, const ModelEffects* effects)
    : declared_(&declared),
      effects_(effects && !effects->empty() ? effects : nullptr),
      effective_(declared),
      nominal_(declared) {
  const int n = declared.num_frames();
  q_ = Eigen::VectorXd::Zero(declared.nq());
  tau_ = Eigen::VectorXd::Zero(declared.nq());
  if (!effects_) return;
  const ModelEffects& e = *effects_;
  if (static_cast<int>(e.frames.size()) != n ||
      static_cast<int>(e.joints.size()) != declared.nq() ||
      static_cast<int>(e.masses.size()) != n || static_cast<int>(e.on_path.size()) != n) {
    throw InputError("EffectiveChain: the effects were made for another model than '" +
                     declared.name() + "'");
  }
  needs_loads_ = e.NeedsLoads();
  torque_needed_.assign(declared.nq(), 0);
  harmonic_.assign(declared.nq(), 0);
  joint_frames_.resize(declared.nq());
  for (int k = 0; k < declared.nq(); ++k) {
    joint_frames_[k] = declared.joint_frame(k);
    const ModelEffects::JointTerms& j = e.joints[k];
    torque_needed_[k] =
        declared.frame(declared.joint_frame(k)).joint.type == JointType::kRevolute &&
        (j.backlash != 0.0 || j.compliance != 0.0 || j.cubic != 0.0);
    for (double h : j.harmonic) harmonic_[k] = harmonic_[k] || h != 0.0;
  }
  static_.assign(n, lie::SE3());
  bend_.assign(n, Vec3::Zero());
  lateral_moment_.assign(n, Eigen::Vector2d::Zero());
  for (FrameId f = 1; f < n; ++f) {
    const ModelEffects::FrameTerms& t = e.frames[f];
    const lie::SE3& T_ip = declared.frame(f).T_parent_ip;
    const Vec3& t0 = T_ip.translation();
    Vec3 tr = e.on_path[f] ? Vec3(t0 * (1.0 + e.thermal)) : t0;
    if (t.dlen != 0.0) tr += t.dlen * t0.normalized();
    tr += t.offset;
    lie::SE3 S(T_ip.rotation(), tr);
    if (!t.origin.isZero(0.0)) S = S * lie::SE3::Exp(t.origin);
    static_[f] = S;
    if (e.FrameVaries(f)) {
      last_varying_ = f;
      varying_frames_.push_back(f);
      continue;
    }
    if (!t.tilt.isZero(0.0)) S = S * lie::SE3(lie::SO3Exp(t.tilt), Vec3::Zero());
    effective_.SetFixedTransform(f, S);
  }
  if (needs_loads_) SetConstantLoads();
  if (!e.uncertainty.empty()) SetConstantSources();
}

// The masses do not change with the configuration: each frame's own first moment and each
// subtree's mass are summed once, and the frames whose poses the loads need are found once.
void EffectiveChain::SetConstantLoads() {
  const ModelEffects& e = *effects_;
  const PpoeModel& model = *declared_;
  const int n = model.num_frames();
  frame_first_.assign(n, Vec3::Zero());
  subtree_mass_.assign(n, 0.0);
  loaded_.assign(n, 0);
  for (FrameId f = 0; f < n; ++f) {
    const FrameMass fm = WithPayload(e, f);
    subtree_mass_[f] = fm.mass;
    frame_first_[f] = fm.first_moment;
    loaded_[f] = fm.mass != 0.0 || !fm.first_moment.isZero(0.0);
  }
  // Children have larger ids than their parents.
  for (FrameId f = n - 1; f > 0; --f) {
    const FrameId p = model.frame(f).parent;
    subtree_mass_[p] += subtree_mass_[f];
    loaded_[p] = loaded_[p] || loaded_[f];
    if (loaded_[f]) last_rel_ = std::max(last_rel_, f);
  }
  // Gravity is needed in the axes of a joint with a torque-driven term, of a bent link's start
  // and of the mount's parent; its ancestors' relative poses carry it there.
  for (int k = 0; k < model.nq(); ++k) {
    if (torque_needed_[k]) last_gravity_ = std::max(last_gravity_, model.joint_frame(k));
  }
  for (const FrameId f : varying_frames_) {
    if (e.frames[f].bend != 0.0) last_gravity_ = std::max(last_gravity_, e.frames[f].bend_start);
    if (!e.frames[f].lateral.isZero(0.0)) last_gravity_ = std::max(last_gravity_, f);
    if (f == e.mount) last_gravity_ = std::max(last_gravity_, model.frame(f).parent);
    last_rel_ = std::max(last_rel_, model.frame(f).parent);  // a bend's end: rel_ to its parent
  }
  last_rel_ = std::max(last_rel_, last_gravity_);
  rel_.assign(n, lie::SE3());
  first_.assign(n, Vec3::Zero());
  gravity_.assign(n, Vec3::Zero());
  gravity_[kBaseFrame] = e.g_base;
}

// The parameters' variances as twists at each frame's source (F_{i,p}): a joint term moves the
// joint variable (xi = zeta dq: Exp(zeta (q + dq)) = Exp(zeta dq) Exp(zeta q)); the geometric
// terms come as a twist covariance already; the mount turns about its x and y axes; a bent link
// turns about its middle; thermal expansion scales every translation on the path at once, which
// moves the end of the path by dtheta times its position (for joints whose axes pass through
// their frames' origins: a joint point off the origin is not scaled). Terms that do not change
// with the reading are set here, once.
void EffectiveChain::SetConstantSources() {
  const ModelEffects& e = *effects_;
  const ModelEffects::Uncertainty& u = e.uncertainty;
  const int n = declared_->num_frames();
  source_fixed_.assign(n, Mat6::Zero());
  source_varies_.assign(n, 0);
  bend_twist_.assign(n, Vec6::Zero());
  std::vector<char> changed(n, 0);
  for (FrameId f = 1; f < n; ++f) {
    source_fixed_[f] = declared_->frame(f).source_cov + u.frames[f];
    changed[f] = !u.frames[f].isZero(0.0);
    source_varies_[f] = (f == e.mount && !u.mount_compliance.isZero(0.0)) ||
                        (u.bend[f] != 0.0 && e.frames[f].bend != 0.0) || !u.lateral[f].isZero(0.0);
    if (e.on_path[f]) path_end_ = f;
  }
  if (u.thermal != 0.0 && path_end_ > 0) source_varies_[path_end_] = 1;
  for (int k = 0; k < declared_->nq(); ++k) {
    const ModelEffects::JointTerms& v = u.joints[k];
    const FrameId f = declared_->joint_frame(k);
    const Vec6& zeta = declared_->frame(f).zeta;
    if (v.offset != 0.0) {
      source_fixed_[f] += v.offset * zeta * zeta.transpose();
      changed[f] = 1;
    }
    bool varies = v.backlash != 0.0 || v.compliance != 0.0 || v.cubic != 0.0;
    for (double h : v.harmonic) varies = varies || h != 0.0;
    if (varies) source_varies_[f] = 1;
  }
  for (FrameId f = 1; f < n; ++f) {
    sources_vary_ = sources_vary_ || source_varies_[f];
    if (changed[f] && !source_varies_[f]) effective_.SetSourceCovariance(f, source_fixed_[f]);
  }
}

void EffectiveChain::UpdateSources(const Eigen::Ref<const Eigen::VectorXd>& q_read) {
  const ModelEffects& e = *effects_;
  const ModelEffects::Uncertainty& u = e.uncertainty;
  for (FrameId f = 1; f < declared_->num_frames(); ++f) {
    if (!source_varies_[f]) continue;
    Mat6 c = source_fixed_[f];
    const PpoeFrame& fr = declared_->frame(f);
    if (fr.q_index >= 0) {
      const int k = fr.q_index;
      const ModelEffects::JointTerms& v = u.joints[k];
      const double qk = q_read[k];
      double var = 0.0;
      for (int h = 1; h <= 3; ++h) {
        const double ch = std::cos(h * qk), sh = std::sin(h * qk);
        var += v.harmonic[2 * h - 2] * ch * ch + v.harmonic[2 * h - 1] * sh * sh;
      }
      if (torque_needed_[k]) {
        const double tau = tau_[k], tau3 = tau * tau * tau;
        var += (std::abs(tau) > 1e-3 ? v.backlash : 0.0) + v.compliance * tau * tau +
               v.cubic * tau3 * tau3;
      }
      c.noalias() += var * fr.zeta * fr.zeta.transpose();
    }
    if (f == e.mount) {
      c.block<2, 2>(kRotIdx, kRotIdx).noalias() +=
          J_mount_c_ * u.mount_compliance.asDiagonal() * J_mount_c_.transpose();
    }
    if (u.bend[f] != 0.0) c.noalias() += u.bend[f] * bend_twist_[f] * bend_twist_[f].transpose();
    if (!u.lateral[f].isZero(0.0)) {
      // A turn about a (b) of M_a (M_b) per unit compliance, where the tilt acts.
      const ModelEffects::FrameTerms& t = e.frames[f];
      const Eigen::Vector2d& M = lateral_moment_[f];
      c.block<3, 3>(kRotIdx, kRotIdx).noalias() +=
          (u.lateral[f].x() * M.x() * M.x()) * t.lateral_a * t.lateral_a.transpose() +
          (u.lateral[f].y() * M.y() * M.y()) * t.lateral_b * t.lateral_b.transpose();
    }
    if (f == path_end_ && u.thermal != 0.0) {
      // Where the source sits (F_{f,p}), from the declared chain at the reading.
      const lie::SE3 T = nominal_.T_base_frame[fr.parent] * fr.T_parent_ip;
      const Vec3 d = T.rotation().transpose() * T.translation();
      c.block<3, 3>(kTransIdx, kTransIdx).noalias() += u.thermal * d * d.transpose();
    }
    effective_.SetSourceCovariance(f, c);
  }
}

// Each subtree's first moment about its frame's origin, in its frame's axes (the backward pass
// of a recursive Newton-Euler at rest), and gravity in each frame's axes (forward): the moments
// the effects need then follow without any frame's pose in base coordinates.
void EffectiveChain::SubtreeLoads(const Eigen::Ref<const Eigen::VectorXd>& q_read) {
  const std::vector<PpoeFrame>& frames = declared_->frames();  // ids checked at construction
  for (FrameId f = 1; f <= last_rel_; ++f) {
    const PpoeFrame& fr = frames[f];
    rel_[f] = RelativePose(fr, q_read);
    if (f <= last_gravity_) {
      gravity_[f].noalias() = rel_[f].rotation().transpose() * gravity_[fr.parent];
    }
    first_[f] = frame_first_[f];
  }
  first_[kBaseFrame] = frame_first_[kBaseFrame];
  for (FrameId f = last_rel_; f > 0; --f) {
    if (!loaded_[f]) continue;
    first_[frames[f].parent] +=
        subtree_mass_[f] * rel_[f].translation() + rel_[f].rotation() * first_[f];
  }
}

void EffectiveChain::ComputeLoads(const Eigen::Ref<const Eigen::VectorXd>& q_read) {
  const ModelEffects& e = *effects_;
  const std::vector<PpoeFrame>& frames = declared_->frames();
  SubtreeLoads(q_read);
  // The weight's moment about point a of frame f's subtree, both in f's axes.
  const auto moment = [&](FrameId f, const Vec3& a) {
    return Vec3((first_[f] - subtree_mass_[f] * a).cross(gravity_[f]));
  };
  for (int k = 0; k < tau_.size(); ++k) {
    if (!torque_needed_[k]) continue;
    const FrameId f = joint_frames_[k];
    const Joint& joint = frames[f].joint;
    tau_[k] = -joint.axis.dot(moment(f, joint.point));
  }
  for (const FrameId f : varying_frames_) {
    const ModelEffects::FrameTerms& t = e.frames[f];
    const PpoeFrame& fr = frames[f];
    if (t.bend != 0.0) {
      // About the link's middle: halfway from the start's origin to the link's end.
      const FrameId p = t.bend_start;
      Vec3 end = fr.T_parent_ip.translation();
      for (FrameId k = fr.parent; k != p; k = frames[k].parent) end = rel_[k] * end;
      const Vec3 M = moment(p, 0.5 * end);
      bend_[f] = t.bend * (M - M.dot(t.bend_dir) * t.bend_dir);
    }
    if (!t.lateral.isZero(0.0)) {
      // About the joint's anchor, in the frame's axes before the joint moves: rel_ is
      // T_parent_ip Exp(zeta q), so the joint's own turn is R_ip^T rel_'s.
      const Vec3 M =
          fr.T_parent_ip.rotation().transpose() * rel_[f].rotation() * moment(f, fr.joint.point);
      lateral_moment_[f] = Eigen::Vector2d(t.lateral_a.dot(M), t.lateral_b.dot(M));
    }
    if (f == e.mount && !e.mount_compliance.isZero(0.0)) {
      // The subtree's first moment about the mount's pivot, and gravity, in the pivot's axes.
      const Mat3& R_ip = fr.T_parent_ip.rotation();
      const Vec3 s = R_ip.transpose() *
                     (subtree_mass_[f] * (rel_[f].translation() - fr.T_parent_ip.translation()) +
                      rel_[f].rotation() * first_[f]);
      const Vec3 g = R_ip.transpose() * gravity_[fr.parent];
      // The compliance's Jacobian only where its uncertainty is carried (UpdateSources).
      const bool need_J = sources_vary_ && !e.uncertainty.mount_compliance.isZero(0.0);
      MountTilt(e.mount_compliance, s.cross(g), s, g, need_J ? &J_mount_c_ : nullptr, &mount_R_);
    }
  }
}

// The fixed parts that change with the configuration: a bent link turns about its middle by the
// rotation its start joint's frame carries (at the corrected poses upstream), the mount tilts.
void EffectiveChain::CorrectFrames() {
  const ModelEffects& e = *effects_;
  for (const FrameId f : varying_frames_) {
    lie::SE3 local = e.frames[f].bend != 0.0 ? BentFixedPart(f) : static_[f];
    if (f == e.mount) local = lie::SE3(local.rotation() * mount_R_, local.translation());
    const ModelEffects::FrameTerms& t = e.frames[f];
    const Vec3 tilt = t.tilt + t.lateral.x() * lateral_moment_[f].x() * t.lateral_a +
                      t.lateral.y() * lateral_moment_[f].y() * t.lateral_b;
    if (!tilt.isZero(0.0)) local = local * lie::SE3(lie::SO3Exp(tilt), Vec3::Zero());
    // The source stays where the static geometry put it: the load turns it by milliradians.
    effective_.SetFixedTransform(f, local, /*move_source=*/false);
  }
}

// The turn of a bent link about its middle, in the parent's coordinates (conjugated there rather
// than applied in base coordinates and undone: one product instead of three). The start's pose
// relative to the parent is that of the corrected chain (frames above f are corrected first).
lie::SE3 EffectiveChain::BentFixedPart(FrameId f) {
  const ModelEffects::FrameTerms& t = effects_->frames[f];
  const std::vector<PpoeFrame>& frames = effective_.frames();
  // The link's start (origin) and its bend, in the parent's coordinates: where the link starts
  // at the parent (the usual case) they are there already.
  Vec3 start = Vec3::Zero();
  Vec3 w = bend_[f];
  if (frames[f].parent != t.bend_start) {
    // T_start_parent: the corrected chain from the link's start down to f's parent.
    lie::SE3 T_start_parent;
    for (FrameId k = frames[f].parent; k != t.bend_start; k = frames[k].parent) {
      T_start_parent = RelativePose(frames[k], q_) * T_start_parent;
    }
    const Mat3 R_parent_start = T_start_parent.rotation().transpose();
    start = -(R_parent_start * T_start_parent.translation());
    w = R_parent_start * bend_[f];
  }
  const Vec3 mid = 0.5 * (start + static_[f].translation());
  const Mat3 Rb = SmallRotationExp(w);
  const lie::SE3 local = lie::SE3(Rb, mid - Rb * mid) * static_[f];
  if (sources_vary_ && effects_->uncertainty.bend[f] != 0.0) {
    // A unit of bending compliance turns the frame by dw about `mid` (parent axes): the twist
    // [mid x dw; dw] there, taken to the frame's own coordinates.
    const Vec3 dw = w / t.bend;
    Vec6& xi = bend_twist_[f];
    xi.segment<3>(kRotIdx).noalias() = local.rotation().transpose() * dw;
    xi.segment<3>(kTransIdx).noalias() =
        local.rotation().transpose() * Vec3(mid.cross(dw) - local.translation().cross(dw));
  }
  return local;
}

void EffectiveChain::Update(const Eigen::Ref<const Eigen::VectorXd>& q_read) {
  if (q_read.size() != declared_->nq()) {
    throw InputError("EffectiveChain: reading has " + std::to_string(q_read.size()) +
                     " joints, PPOE model '" + declared_->name() + "' has " +
                     std::to_string(declared_->nq()));
  }
  q_ = q_read;
  if (!effects_) return;
  if (!q_read.allFinite()) {
    throw InputError("EffectiveChain: a joint reading of '" + declared_->name() +
                     "' is not finite");
  }
  const ModelEffects& e = *effects_;
  const bool loads = needs_loads_;
  if (sources_vary_ && e.uncertainty.thermal != 0.0)
    ForwardKinematics(*declared_, nominal_, q_read);
  // The kinematic joint terms first (offset, periodic error): the weight acts where the arm
  // is, at the corrected angles, so the loads are taken there (a 0.4 deg encoder
  // offset at j2 moves the centre of mass, and a compliant mount's tilt with it, by ~1% of the
  // tilt; 39-69 um at a raised hand). identify::EffectModel::LoadsFor does the same.
  for (int k = 0; k < declared_->nq(); ++k) {
    const ModelEffects::JointTerms& j = e.joints[k];
    const double qk = q_read[k];
    double dq = j.offset;
    for (int h = 1; h <= 3 && harmonic_[k]; ++h) {
      if (j.harmonic[2 * h - 2] != 0.0 || j.harmonic[2 * h - 1] != 0.0) {
        dq += j.harmonic[2 * h - 2] * std::cos(h * qk) + j.harmonic[2 * h - 1] * std::sin(h * qk);
      }
    }
    q_[k] = qk + dq;
  }
  if (loads) {
    ComputeLoads(q_);
    for (int k = 0; k < declared_->nq(); ++k) {
      if (!torque_needed_[k]) continue;
      const ModelEffects::JointTerms& j = e.joints[k];
      const double tau = tau_[k];
      // The identification's flank: the side the gravity load presses (none below 1 mN m).
      const double flank = tau > 1e-3 ? 1.0 : tau < -1e-3 ? -1.0 : 0.0;
      q_[k] += j.backlash * flank + j.compliance * tau + j.cubic * tau * tau * tau;
    }
  }
  if (last_varying_ > 0) CorrectFrames();
  if (sources_vary_) UpdateSources(q_read);
}

}  // namespace flexbench::kinematics
