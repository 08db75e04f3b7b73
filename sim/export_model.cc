#include "sim/export_model.h"

#include <mujoco/mujoco.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "estimators/error.h"
#include "estimators/format.h"
#include "estimators/kinematics/effect_table.h"
#include "estimators/kinematics/model_effects.h"
#include "sim/declared_chain.h"
#include "sim/dynamic_effects.h"
#include "sim/mujoco_model.h"

namespace flexbench::sim {
namespace {

using kinematics::FrameId;
using lie::SE3;

using K = kinematics::EffectKind;

// Identified effects that are geometry: folded into the MJCF's poses.
bool IsGeometric(K kind) {
  return kind == K::kJointOffset || kind == K::kLinkLength || kind == K::kLinkOffset ||
         kind == K::kAxisTilt || kind == K::kThermalExpansion || kind == K::kJointOrigin ||
         kind == K::kCameraOffset;
}

// The gear-stiffness annotations of the truth's joint_compliance effect (sim/effects): the
// effect's tag, effect:NAME.
std::string GearText() {
  return std::string("effect:") + kinematics::Row(K::kJointCompliance).name;
}
std::string GearNumbers() { return GearText() + ":stiffness"; }
// Their former names: read, and replaced by the current ones in what is written.
constexpr char kFormerGearText[] = "effect:joint_elasticity";
constexpr char kFormerGearNumbers[] = "effect:joint_elasticity:stiffness";

// MuJoCo's camera looks along -z with y up; the declared chain's optical frame has y down.
const SE3 kMjcamOptical(Mat3(Vec3(1.0, -1.0, -1.0).asDiagonal()), Vec3::Zero());

void SetPose(const SE3& T, double* pos, double* quat) {
  for (int k = 0; k < 3; ++k) pos[k] = T.translation()[k];
  QuatToWxyz(Quat(T.rotation()).normalized(), quat);
}

// Folds the corrected fixed parts of the declared chain (EffectiveChain at reading 0, the
// constant joint offsets as a turn of the joint's frame) into the model's poses, anchors and
// axes. MuJoCo places body b at P B Trans(a) Rot_w(q) Trans(-a); the chain at P Jc Rot_w(q) Bc
// (Jc the joint frame's fixed part, Bc the body frame's): B' = Jc Bc, a' = Bc^-1 0, w' = Rc^T w.
class Folder {
 public:
  Folder(mjModel* m, const DeclaredChain& chain, std::vector<std::string>* skipped)
      : m_(m), chain_(chain), kin_(chain.model, chain.effects_or_null()), skipped_(skipped) {
    kin_.Update(Eigen::VectorXd::Zero(chain.model.nq()));
  }

  void Fold() {
    for (int b = 1; b < m_->nbody; ++b) FoldBody(b);
    for (int s = 0; s < m_->nsite; ++s) {
      if (const FrameId f = Find("site/", mjOBJ_SITE, s); f > 0) {
        SetPose(Fixed(f), m_->site_pos + 3 * s, m_->site_quat + 4 * s);
      }
    }
    for (int g = 0; g < m_->ngeom; ++g) {
      if (const FrameId f = Find("geom/", mjOBJ_GEOM, g); f > 0) {
        SetPose(Fixed(f), m_->geom_pos + 3 * g, m_->geom_quat + 4 * g);
      }
    }
    for (int c = 0; c < m_->ncam; ++c) {
      if (const FrameId f = Find("camera/", mjOBJ_CAMERA, c); f > 0) {
        SetPose(Fixed(f) * kMjcamOptical, m_->cam_pos + 3 * c, m_->cam_quat + 4 * c);
      }
    }
  }

 private:
  FrameId Find(const char* prefix, mjtObj type, int id) const {
    const std::string name = ObjectName(m_, type, id);
    const std::string typed = prefix + name;
    return !name.empty() && chain_.model.HasFrame(typed) ? chain_.model.FindFrame(typed) : -1;
  }

  // Frame f's corrected fixed part; a joint frame's with its constant offset turned in.
  SE3 Fixed(FrameId f) const {
    const kinematics::PpoeFrame& fr = kin_.model().frame(f);
    if (fr.q_index < 0) return fr.T_parent_ip;
    return fr.T_parent_ip * fr.JointMotion(kin_.q()[fr.q_index]);
  }

  // With G_k = J_{k+1} ... J_n Bc (the corrected fixed parts after joint k), MuJoCo's
  // B' Rot_1 ... Rot_n equals J_1 R_1 J_2 ... R_n Bc for B' = J_1 G_1 and joint k about
  // axis Rg_k^T w_k through G_k^-1 0 (Rot_k = G_k^-1 R_k G_k).
  void FoldBody(int b) {
    const FrameId fb = Find("body/", mjOBJ_BODY, b);
    if (fb < 0) return;  // off the declared chain: as it was
    const int j0 = m_->body_jntadr[b];
    const int nj = m_->body_jntnum[b];
    for (int j = j0; j < j0 + nj; ++j) {
      if (Find("joint/", mjOBJ_JOINT, j) < 0) {
        skipped_->push_back("the geometry at body '" + ObjectName(m_, mjOBJ_BODY, b) +
                            "' (an unnamed joint)");
        return;
      }
    }
    SE3 G = Fixed(fb);
    for (int j = j0 + nj - 1; j >= j0; --j) {
      const SE3 G_inv = G.Inverse();
      const Vec3 anchor = G_inv.translation();
      const Vec3 axis = G_inv.rotation() * Eigen::Map<const Vec3>(m_->jnt_axis + 3 * j);
      for (int k = 0; k < 3; ++k)
        m_->jnt_pos[3 * j + k] = anchor[k], m_->jnt_axis[3 * j + k] = axis[k];
      G = Fixed(Find("joint/", mjOBJ_JOINT, j)) * G;
    }
    SetPose(G, m_->body_pos + 3 * b, m_->body_quat + 4 * b);
  }

  mjModel* m_;
  const DeclaredChain& chain_;
  kinematics::EffectiveChain kin_;
  std::vector<std::string>* skipped_;
};

SE3 PoseOf(const double* pos, const double* quat) {
  return SE3(QuatFromWxyz(quat).normalized(), Eigen::Map<const Vec3>(pos));
}

std::string Nums(const double* v, int n) {
  std::string s;
  for (int k = 0; k < n; ++k) s += (k ? " " : "") + ExactNum(v[k]);
  return s;
}

// Sets attribute `key` of the element opening `line` to `value` (added after the tag if absent).
void SetAttribute(std::string* line, const std::string& key, const std::string& value) {
  const std::string pat = " " + key + "=\"";
  const size_t at = line->find(pat);
  if (at != std::string::npos) {
    const size_t start = at + pat.size();
    line->replace(start, line->find('"', start) - start, value);
    return;
  }
  const size_t tag_end = line->find_first_of(" />", line->find('<') + 1);
  line->insert(tag_end, pat + value + "\"");
}

// MuJoCo's writer keeps six digits: every pose and inertial inside <worldbody>, and the joints'
// and actuators' dynamic numbers it wrote, get all of them again (the elements come in the model's
// order, type by type), and relative asset folders are made absolute (the file is written
// elsewhere). A mesh geom's pose in the model includes the mesh's own frame (centroid, principal
// axes), which the compiler adds to the written one: it is written as `mesh_geom_poses` gives it
// (identity when null).
std::string WithFullPrecision(const std::string& xml, const mjModel* m,
                              const std::filesystem::path& model_dir,
                              const std::vector<SE3>* mesh_geom_poses) {
  std::istringstream in(xml);
  std::ostringstream out;
  std::string line;
  bool world = false, actuators = false;
  int body = 1, joint = 0, geom = 0, site = 0, cam = 0, actuator = 0;
  // Rewritten only where the writer wrote it (a value equal to its class default is left out)
  // and its six digits do not read back as the value.
  const auto set_present = [&](const char* key, const double* v, int n) {
    const std::string pat = std::string(" ") + key + "=\"";
    const size_t at = line.find(pat);
    if (at == std::string::npos) return;
    const size_t from = at + pat.size();
    std::istringstream written(line.substr(from, line.find('"', from) - from));
    bool exact = true;
    for (int k = 0; k < n; ++k) {
      double x = 0.0;  // the writer leaves trailing zeros out
      if (!(written >> x)) x = 0.0;
      exact = exact && x == v[k];
    }
    if (!exact) SetAttribute(&line, key, Nums(v, n));
  };
  const auto is = [&](const char* tag) {
    return line.find(std::string("<") + tag + " ") != std::string::npos ||
           line.find(std::string("<") + tag + "/>") != std::string::npos ||
           line.find(std::string("<") + tag + ">") != std::string::npos;
  };
  while (std::getline(in, line)) {
    if (line.find("<worldbody") != std::string::npos) world = true;
    if (line.find("</worldbody") != std::string::npos) world = false;
    if (line.find("<actuator>") != std::string::npos) actuators = true;
    if (line.find("</actuator>") != std::string::npos) actuators = false;
    if (actuators && line.find("<actuator>") == std::string::npos &&
        line.find("</actuator>") == std::string::npos && line.find('<') != std::string::npos) {
      set_present("gainprm", m->actuator_gainprm + mjNGAIN * actuator, mjNGAIN);
      set_present("biasprm", m->actuator_biasprm + mjNBIAS * actuator, mjNBIAS);
      ++actuator;
    }
    if (line.find("<compiler") != std::string::npos) {
      for (const char* key : {"meshdir", "texturedir"}) {
        const std::string pat = std::string(" ") + key + "=\"";
        const size_t at = line.find(pat);
        std::string dir = model_dir.string() + "/";
        if (at != std::string::npos) {
          const size_t s = at + pat.size();
          const std::filesystem::path given = line.substr(s, line.find('"', s) - s);
          dir = (given.is_absolute() ? given : model_dir / given).lexically_normal().string() + "/";
        }
        SetAttribute(&line, key, dir);
      }
    }
    if (world) {
      if (is("body")) {
        SetAttribute(&line, "pos", Nums(m->body_pos + 3 * body, 3));
        SetAttribute(&line, "quat", Nums(m->body_quat + 4 * body, 4));
        ++body;
      } else if (is("joint")) {
        SetAttribute(&line, "pos", Nums(m->jnt_pos + 3 * joint, 3));
        SetAttribute(&line, "axis", Nums(m->jnt_axis + 3 * joint, 3));
        const int dof = m->jnt_dofadr[joint];
        set_present("stiffness", m->jnt_stiffness + joint, 1);
        set_present("damping", m->dof_damping + dof, 1);
        set_present("armature", m->dof_armature + dof, 1);
        set_present("frictionloss", m->dof_frictionloss + dof, 1);
        ++joint;
      } else if (is("freejoint")) {
        ++joint;
      } else if (is("inertial")) {
        const int b = body - 1;  // written first inside its body
        SetAttribute(&line, "pos", Nums(m->body_ipos + 3 * b, 3));
        SetAttribute(&line, "quat", Nums(m->body_iquat + 4 * b, 4));
        SetAttribute(&line, "mass", ExactNum(m->body_mass[b]));
        SetAttribute(&line, "diaginertia", Nums(m->body_inertia + 3 * b, 3));
      } else if (is("geom")) {
        if (m->geom_type[geom] != mjGEOM_MESH) {
          SetAttribute(&line, "pos", Nums(m->geom_pos + 3 * geom, 3));
          SetAttribute(&line, "quat", Nums(m->geom_quat + 4 * geom, 4));
        } else {
          double pos[3], quat[4];
          SetPose(mesh_geom_poses ? (*mesh_geom_poses)[geom] : SE3(), pos, quat);
          SetAttribute(&line, "pos", Nums(pos, 3));
          SetAttribute(&line, "quat", Nums(quat, 4));
        }
        ++geom;
      } else if (is("site")) {
        SetAttribute(&line, "pos", Nums(m->site_pos + 3 * site, 3));
        SetAttribute(&line, "quat", Nums(m->site_quat + 4 * site, 4));
        ++site;
      } else if (is("camera")) {
        SetAttribute(&line, "pos", Nums(m->cam_pos + 3 * cam, 3));
        SetAttribute(&line, "quat", Nums(m->cam_quat + 4 * cam, 4));
        ++cam;
      }
    }
    out << line << "\n";
  }
  if (body != m->nbody || joint != m->njnt || geom != m->ngeom || site != m->nsite ||
      cam != m->ncam || actuator != m->nu) {
    throw std::logic_error("export: MuJoCo's saved XML does not list the model's elements");
  }
  return out.str();
}

// The gear stiffnesses: the model's own annotation, the identified compliances' k = -1/c over it.
std::map<std::string, double> GearStiffness(const mjModel* m, const DeclaredChain& full,
                                            std::vector<std::string>* skipped) {
  std::map<std::string, double> k;
  // Each of the two under its current name, else its former one (a model may mix them).
  int t = mj_name2id(m, mjOBJ_TEXT, GearText().c_str());
  if (t < 0) t = mj_name2id(m, mjOBJ_TEXT, kFormerGearText);
  int n = mj_name2id(m, mjOBJ_NUMERIC, GearNumbers().c_str());
  if (n < 0) n = mj_name2id(m, mjOBJ_NUMERIC, kFormerGearNumbers);
  if (t >= 0 && n >= 0) {
    std::istringstream names(std::string(m->text_data + m->text_adr[t]));  // NUL-terminated
    std::string name;
    for (int i = 0; names >> name && i < m->numeric_size[n]; ++i) {
      k[name] = m->numeric_data[m->numeric_adr[n] + i];
    }
  }
  for (size_t q = 0; q < full.q_joints.size(); ++q) {
    const double c = full.effects.joints.empty() ? 0.0 : full.effects.joints[q].compliance;
    if (c < 0.0) {
      k[full.q_joints[q]] = -1.0 / c;
    } else if (c > 0.0) {
      skipped->push_back("the compliance of '" + full.q_joints[q] + "' (c > 0 is no spring)");
    }
  }
  return k;
}

// The saved XML with the gear annotation replaced by `k` (nothing when empty).
std::string WithGearAnnotation(std::string xml, const std::map<std::string, double>& k) {
  for (const std::string& name :
       {GearText(), GearNumbers(), std::string(kFormerGearText), std::string(kFormerGearNumbers)}) {
    const size_t at = xml.find("name=\"" + name + "\"");
    if (at == std::string::npos) continue;
    const size_t start = xml.rfind('\n', at) + 1;
    xml.erase(start, xml.find('\n', at) + 1 - start);
  }
  if (k.empty()) return xml;
  std::string joints, values;
  for (const auto& [j, v] : k) {
    joints += (joints.empty() ? "" : " ") + j;
    values += (values.empty() ? "" : " ") + ExactNum(v);
  }
  const std::string lines = "    <text name=\"" + GearText() + "\" data=\"" + joints +
                            "\"/>\n    <numeric name=\"" + GearNumbers() + "\" size=\"" +
                            std::to_string(k.size()) + "\" data=\"" + values + "\"/>\n";
  const size_t custom = xml.find("<custom>");
  if (custom != std::string::npos) return xml.insert(xml.find('\n', custom) + 1, lines);
  return xml.insert(xml.find("  <worldbody>"), "  <custom>\n" + lines + "  </custom>\n");
}

// MuJoCo's XML of the model it loaded last (mj_saveLastXML writes a file only).
std::string SaveLastXml(const mjModel* m) {
  const std::filesystem::path tmp = std::filesystem::temp_directory_path() /
                                    ("flexbench_export_" + std::to_string(::getpid()) + ".xml");
  char error[1024] = "";
  const int ok = mj_saveLastXML(tmp.c_str(), m, error, sizeof(error));
  std::ifstream in(tmp);
  std::stringstream text;
  text << in.rdbuf();
  std::error_code ec;
  std::filesystem::remove(tmp, ec);
  if (!ok) throw InputError(std::string("export: MuJoCo could not write the model: ") + error);
  return text.str();
}

// The model with the declared file's geometry folded in (Folder), and what MJCF cannot hold.
struct Folded {
  MjModelPtr model;
  std::map<std::string, double> gear;   // GearStiffness
  std::vector<std::string> compliance;  // the identified compliances (written as gear)
  bool tilt = false;                    // <option gravity> turned
  std::vector<std::string> skipped;
  // Passive joints a dynamic effect released (a link's mode, the base plate's sway): no longer
  // an undeclared effect's, they leave the effect's joint list and move as the model's own.
  std::vector<std::string> released;
};

// The dynamic effects (sim/dynamic_effects.h) onto the model's own numbers: damping,
// frictionloss, armature, the servo's kp, the bending or plate joints' stiffness and damping, a
// body's mass. A servo delay has no MJCF form.
void ApplyDynamics(const DeclaredModel& declared, mjModel* m, Folded* out) {
  const std::vector<DeclaredDynamic> entries = DynamicEntries(declared.identified_effects);
  if (entries.empty()) return;
  const ModelCatalog catalog = ModelCatalog::Build(m, declared.model_path);
  TruthSetup setup = NominalSetup(m, &catalog, declared.model_path);
  const std::vector<char> released_before = setup.released;
  for (const DeclaredDynamic& d : entries) {
    const std::string name = std::string(d.row->name) + "@" + d.location;
    ApplyDynamic(setup, d.row->kind, d.location, d.values.data(), d.where + ": " + name);
    if (d.row->kind == DynamicKind::kServoDelay) {
      out->skipped.push_back(name + " (MuJoCo has no actuator delay)");
    }
  }
  for (int j = 0; j < m->njnt; ++j) {
    if (setup.released[j] && !released_before[j]) {
      out->released.push_back(ObjectName(m, mjOBJ_JOINT, j));
    }
  }
}

// The saved XML with `joints` left out of every effect's joint list (a list left empty goes).
std::string WithoutEffectJoints(std::string xml, const std::vector<std::string>& joints) {
  if (joints.empty()) return xml;
  size_t at = 0;
  while ((at = xml.find("<text name=\"effect:", at)) != std::string::npos) {
    const size_t end = xml.find('\n', at);
    const size_t data = xml.find("data=\"", at);
    if (data == std::string::npos || data > end) {
      at = end;
      continue;
    }
    const size_t from = data + 6, to = xml.find('"', from);
    std::istringstream names(xml.substr(from, to - from));
    std::string kept, name;
    while (names >> name) {
      if (std::find(joints.begin(), joints.end(), name) == joints.end()) {
        kept += (kept.empty() ? "" : " ") + name;
      }
    }
    if (kept.empty()) {
      const size_t start = xml.rfind('\n', at) + 1;
      xml.erase(start, end + 1 - start);
      at = start;
    } else {
      xml.replace(from, to - from, kept);
      at = xml.find('\n', at);
    }
  }
  return xml;
}

Folded Fold(const DeclaredModel& declared) {
  const std::string ext = std::filesystem::path(declared.model_path).extension().string();
  if (ext != ".xml" && ext != ".XML") {
    throw InputError(declared.file + ": model " + CapForMessage(declared.model_path) +
                     " is not an MJCF file (.xml): export writes from an MJCF model");
  }
  Folded out;
  DeclaredModel geometric = declared;
  geometric.identified_effects.clear();
  for (const IdentifiedEffect& e : declared.identified_effects) {
    if (IsDynamicEffect(e.effect)) continue;  // ApplyDynamics below
    const kinematics::EffectRow* row =
        kinematics::FindEffect(e.effect.substr(0, e.effect.find('@')));
    if (row == nullptr) {
      out.skipped.push_back(e.effect);  // refused by BuildDeclaredChain below
    } else if (IsGeometric(row->kind)) {
      geometric.identified_effects.push_back(e);
    } else if (row->kind == K::kGravityTilt) {
      out.tilt = true;
    } else if (row->kind == K::kJointCompliance) {
      out.compliance.push_back(e.effect);
    } else if (row->kind == K::kStiffeningSpring) {
      out.compliance.push_back(e.effect);
      out.skipped.push_back(e.effect + " (its cubic term; the linear one is written)");
    } else {
      out.skipped.push_back(e.effect);
    }
  }
  out.model = LoadModel(declared.model_path);
  mjModel* m = out.model.get();
  // The whole file first: a bad effect is refused, not skipped.
  const DeclaredChain full = BuildDeclaredChain(m, declared, /*with_couplings=*/true);
  const DeclaredChain chain = BuildDeclaredChain(m, geometric, /*with_couplings=*/true);
  for (const DeclaredMarkerOffset& mo : declared.marker_offsets) {
    if (chain.model.HasFrame("body/" + mo.frame + "/moved")) {
      out.skipped.push_back("the marker offset of body '" + mo.frame + "' (move a site instead)");
    }
  }
  out.gear = GearStiffness(m, full, &out.skipped);
  Folder(m, chain, &out.skipped).Fold();
  ApplyDynamics(declared, m, &out);
  if (out.tilt) {
    MjDataPtr data = MakeData(m);
    mj_kinematics(m, data.get());
    const Mat3 R_w_base = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(
        data->xmat + 9 * full.base_body);
    const Vec3 g = R_w_base * full.effects.g_base;
    for (int k = 0; k < 3; ++k) m->opt.gravity[k] = g[k];
  }
  return out;
}

// URDF's origin: xyz and fixed-axis roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll)).
std::string Origin(const SE3& T) {
  const Mat3& R = T.rotation();
  const double roll = std::atan2(R(2, 1), R(2, 2));
  const double pitch = std::atan2(-R(2, 0), std::hypot(R(2, 1), R(2, 2)));
  const double yaw = std::atan2(R(1, 0), R(0, 0));
  const double xyz[3] = {T.translation().x(), T.translation().y(), T.translation().z()};
  const double rpy[3] = {roll, pitch, yaw};
  return "<origin xyz=\"" + Nums(xyz, 3) + "\" rpy=\"" + Nums(rpy, 3) + "\"/>";
}

// The folded model as URDF: a link per body (at its last joint's anchor, as URDF joints turn
// about their link's origin; a body with several joints gets one link per joint), a fixed link
// per site, camera and named geom, inertials. No visual or collision geometry.
class UrdfWriter {
 public:
  UrdfWriter(const mjModel* m, std::vector<std::string>* skipped) : m_(m), skipped_(skipped) {}

  std::string Write() {
    // MuJoCo's names start with the model's own.
    const std::string model = m_->names;
    u_ << "<?xml version=\"1.0\"?>\n<robot name=\"" << (model.empty() ? "model" : model) << "\">\n";
    u_ << "  <link name=\"" << kRoot << "\"/>\n";
    used_.insert(kRoot);
    link_of_.assign(m_->nbody, kRoot);
    offset_.assign(m_->nbody, SE3());
    for (int b = 1; b < m_->nbody; ++b) Body(b);
    Attach(mjOBJ_SITE, m_->nsite, m_->site_bodyid, m_->site_pos, m_->site_quat, false);
    Attach(mjOBJ_CAMERA, m_->ncam, m_->cam_bodyid, m_->cam_pos, m_->cam_quat, false);
    Attach(mjOBJ_GEOM, m_->ngeom, m_->geom_bodyid, m_->geom_pos, m_->geom_quat, true);
    u_ << "</robot>\n";
    return u_.str();
  }

 private:
  static constexpr const char* kRoot = "flexbench_world";

  std::string Name(mjtObj type, int id, const std::string& fallback) const {
    const std::string n = ObjectName(m_, type, id);
    return n.empty() ? fallback : n;
  }

  void Joint(const std::string& name, const std::string& type, const std::string& parent,
             const std::string& child, const SE3& origin, const std::string& extra) {
    u_ << "  <joint name=\"" << name << "\" type=\"" << type << "\">\n    " << Origin(origin)
       << "\n    <parent link=\"" << parent << "\"/>\n    <child link=\"" << child << "\"/>\n"
       << extra << "  </joint>\n";
  }

  void Body(int b) {
    const std::string name = Name(mjOBJ_BODY, b, "body" + std::to_string(b));
    const std::string parent = link_of_[m_->body_parentid[b]];
    const SE3 B = offset_[m_->body_parentid[b]].Inverse() *
                  PoseOf(m_->body_pos + 3 * b, m_->body_quat + 4 * b);
    const int j0 = m_->body_jntadr[b], nj = m_->body_jntnum[b];
    std::string prev = parent;
    SE3 origin = B;
    for (int j = j0; j < j0 + nj; ++j) {
      const Vec3 a = Eigen::Map<const Vec3>(m_->jnt_pos + 3 * j);
      origin = origin * SE3::Translation(a);
      const std::string jname = Name(mjOBJ_JOINT, j, "joint" + std::to_string(j));
      const std::string link = j + 1 == j0 + nj ? name : name + "__" + jname;
      const bool hinge = m_->jnt_type[j] == mjJNT_HINGE;
      if (!hinge && m_->jnt_type[j] != mjJNT_SLIDE) {
        skipped_->push_back("joint '" + jname + "' (ball or free: no URDF form)");
      }
      const Vec3 w = Eigen::Map<const Vec3>(m_->jnt_axis + 3 * j).normalized();
      const double axis[3] = {w.x(), w.y(), w.z()};
      std::string extra = "    <axis xyz=\"" + Nums(axis, 3) + "\"/>\n";
      std::string type = hinge ? "continuous" : "prismatic";
      if (m_->jnt_limited[j]) {
        type = hinge ? "revolute" : "prismatic";
        extra += "    <limit lower=\"" + ExactNum(m_->jnt_range[2 * j]) + "\" upper=\"" +
                 ExactNum(m_->jnt_range[2 * j + 1]) + "\" effort=\"0\" velocity=\"0\"/>\n";
      }
      if (j + 1 < j0 + nj) Link(link, -1, SE3());
      Joint(jname, type, prev, link, origin, extra);
      prev = link;
      origin = SE3::Translation(-a);
    }
    // The body's link stands at its last joint's anchor (the body's own pose without joints).
    const SE3 L =
        nj > 0 ? SE3::Translation(Eigen::Map<const Vec3>(m_->jnt_pos + 3 * (j0 + nj - 1))) : SE3();
    if (nj == 0) Joint(name + "__fixed", "fixed", parent, name, B, "");
    Link(name, b, L);
    link_of_[b] = name;
    offset_[b] = L;
  }

  // A link; with its body's inertial when b >= 0 (L: the link's pose in the body).
  void Link(const std::string& name, int b, const SE3& L) {
    used_.insert(name);
    if (b < 0 || !(m_->body_mass[b] > 0.0)) {
      u_ << "  <link name=\"" << name << "\"/>\n";
      return;
    }
    const SE3 I = L.Inverse() * PoseOf(m_->body_ipos + 3 * b, m_->body_iquat + 4 * b);
    const double* d = m_->body_inertia + 3 * b;
    u_ << "  <link name=\"" << name << "\">\n    <inertial>\n      " << Origin(I)
       << "\n      <mass value=\"" << ExactNum(m_->body_mass[b]) << "\"/>\n      <inertia ixx=\""
       << ExactNum(d[0]) << "\" ixy=\"0\" ixz=\"0\" iyy=\"" << ExactNum(d[1])
       << "\" iyz=\"0\" izz=\"" << ExactNum(d[2]) << "\"/>\n    </inertial>\n  </link>\n";
  }

  // Sites, cameras and (named) geoms as fixed links named as they are.
  void Attach(mjtObj type, int n, const int* body, const double* pos, const double* quat,
              bool named_only) {
    for (int i = 0; i < n; ++i) {
      std::string name = ObjectName(m_, type, i);
      if (name.empty()) {
        if (named_only) continue;
        name = std::string(type == mjOBJ_SITE ? "site" : "camera") + std::to_string(i);
      }
      if (used_.count(name)) {
        skipped_->push_back("the frame of '" + name + "' (a link of that name exists)");
        continue;
      }
      const int b = body[i];
      Joint(name + "__fixed", "fixed", link_of_[b], name,
            offset_[b].Inverse() * PoseOf(pos + 3 * i, quat + 4 * i), "");
      Link(name, -1, SE3());
    }
  }

  const mjModel* m_;
  std::vector<std::string>* skipped_;
  std::ostringstream u_;
  std::set<std::string> used_;
  std::vector<std::string> link_of_;  // per body: its (last) link
  std::vector<SE3> offset_;           // per body: that link's pose in the body
};

// Text as an XML attribute value.
std::string XmlEscaped(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '&')
      out += "&amp;";
    else if (c == '<')
      out += "&lt;";
    else if (c == '>')
      out += "&gt;";
    else if (c == '"')
      out += "&quot;";
    else
      out += c;
  }
  return out;
}

}  // namespace

std::string SavedMjcf(const mjModel* m, const std::filesystem::path& model_dir) {
  const std::string saved = SaveLastXml(m);
  std::string xml = WithFullPrecision(saved, m, model_dir, nullptr);
  bool meshes = false;
  for (int g = 0; g < m->ngeom; ++g) meshes = meshes || m->geom_type[g] == mjGEOM_MESH;
  if (!meshes) return xml;
  // Written at the identity, a mesh geom compiles to the mesh's own frame O; written as
  // G O^-1 it compiles to the model's G, every digit (the writer's own pose has six).
  const MjModelPtr frames = LoadModelFromString(xml, (model_dir / "saved.xml").string());
  std::vector<SE3> poses(m->ngeom);
  for (int g = 0; g < m->ngeom; ++g) {
    poses[g] = PoseOf(m->geom_pos + 3 * g, m->geom_quat + 4 * g) *
               PoseOf(frames->geom_pos + 3 * g, frames->geom_quat + 4 * g).Inverse();
  }
  return WithFullPrecision(saved, m, model_dir, &poses);
}

ExportedModel ExportMjcf(const DeclaredModel& declared) {
  Folded f = Fold(declared);
  ExportedModel out;
  out.skipped = std::move(f.skipped);
  out.text = WithoutEffectJoints(
      WithGearAnnotation(
          SavedMjcf(f.model.get(), std::filesystem::absolute(declared.model_path).parent_path()),
          f.gear),
      f.released);
  return out;
}

ExportedModel ExportUrdf(const DeclaredModel& declared) {
  Folded f = Fold(declared);
  ExportedModel out;
  out.skipped = std::move(f.skipped);
  for (const std::string& c : f.compliance) out.skipped.push_back(c + " (URDF has no spring)");
  if (f.tilt) out.skipped.push_back("gravity_tilt@base (URDF has no gravity)");
  for (const DeclaredDynamic& d : DynamicEntries(declared.identified_effects)) {
    const DynamicKind k = d.row->kind;
    if (k == DynamicKind::kPayloadMass || k == DynamicKind::kServoDelay) continue;  // done
    out.skipped.push_back(std::string(d.row->name) + "@" + d.location +
                          " (the URDF writer has no joint dynamics; the MJCF holds it)");
  }
  out.text = UrdfWriter(f.model.get(), &out.skipped).Write();
  return out;
}

ConvertedUrdf UrdfToMjcf(const std::string& urdf_path, double kp) {
  if (!IsUrdfPath(urdf_path)) {
    throw InputError(CapForMessage(urdf_path) + ": not a URDF file (.urdf)");
  }
  if (!(kp > 0.0 && std::isfinite(kp))) {
    throw InputError(CapForMessage(urdf_path) + ": servo kp " + ExactNum(kp) +
                     ": expected a positive number (N m/rad, N/m)");
  }
  ConvertedUrdf out;
  const MjModelPtr m = LoadModel(urdf_path, &out.warnings);
  std::string xml = SavedMjcf(m.get(), std::filesystem::absolute(urdf_path).parent_path());
  // The writer leaves out the importer's bounds: a massless moving link would be refused.
  const size_t compiler = xml.find("<compiler");
  const size_t compiler_end = xml.find('\n', compiler);
  if (compiler == std::string::npos || compiler_end == std::string::npos) {
    throw std::logic_error("convert: MuJoCo's saved XML has no <compiler> line");
  }
  std::string line = xml.substr(compiler, compiler_end - compiler);
  SetAttribute(&line, "boundmass", ExactNum(kUrdfBoundMass));
  SetAttribute(&line, "boundinertia", ExactNum(kUrdfBoundInertia));
  xml.replace(compiler, compiler_end - compiler, line);
  std::string servos;
  for (int j = 0; j < m->njnt; ++j) {
    const std::string name = ObjectName(m.get(), mjOBJ_JOINT, j);
    if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE) {
      out.skipped.push_back(name + " (a floating joint: no position servo)");
      continue;
    }
    servos += "    <position name=\"" + XmlEscaped(name) + "\" joint=\"" + XmlEscaped(name) +
              "\" kp=\"" + ExactNum(kp) + "\"/>\n";
    out.servoed.push_back(name);
  }
  if (!servos.empty()) {
    xml.insert(xml.rfind("</mujoco>"), "  <actuator>\n" + servos + "  </actuator>\n");
  }
  out.text = std::move(xml);
  return out;
}

}  // namespace flexbench::sim
