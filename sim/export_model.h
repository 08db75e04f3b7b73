// The calibrated model as files other tools load (`flexbench export`): a declared model's robot
// with its identified effects (sim/declared_effects.h) folded into the MJCF.
//
// What goes where:
//   - geometry (joint_origin, link_offset, link_length, joint_axis_tilt_a/b, thermal_expansion,
//     camera_offset) and the constant joint_offset fold into the body, site, geom and camera
//     poses and the joints' anchors and axes: with the readings as qpos, MuJoCo's poses are the
//     declared chain's with those effects applied (EffectiveChain);
//   - marker offsets (marker_offsets:) move their sites, geoms or cameras;
//   - gravity_tilt@base turns <option gravity>;
//   - joint_compliance (and stiffening_spring's linear term) become the gear-stiffness
//     annotations the truth's joint_compliance effect reads (<custom> text
//     effect:joint_compliance and numeric effect:joint_compliance:stiffness, k = -1/c). Not
//     <joint stiffness>: that spring pulls the link towards a fixed springref, whereas a gear
//     spring sits between the motor and the link, which is what the truth effect simulates.
//   - dynamic effects (sim/dynamic_effects.h) become the joints' damping, frictionloss and
//     armature, the position servo's kp, a body's mass, and a link's mode or the base plate's
//     sway the stiffness and damping of its passive joints, which leave the effect:link_bending
//     (effect:base_compliance) list: they move as the model's own physics. servo_delay has no
//     MJCF form.
// Everything else (backlash, link_bending, base_compliance, payload, transmission_error,
// joint_error_curve, stiffening_spring's cubic term, a moved body frame) has no MJCF form: the
// caller names it in one warning line.
#pragma once

#include <mujoco/mujoco.h>

#include <filesystem>
#include <string>
#include <vector>

#include "sim/declared_model.h"
#include "sim/mujoco_model.h"

namespace flexbench::sim {

struct ExportedModel {
  std::string text;                  // the file's text
  std::vector<std::string> skipped;  // identified effects (or parts) the MJCF cannot hold
};

// The calibrated MJCF of `declared` (its model must be an MJCF file). Numbers that place
// frames carry every digit. Throws InputError naming the declared file for a bad model or
// effect (as BuildDeclaredChain does).
ExportedModel ExportMjcf(const DeclaredModel& declared);

// MuJoCo's MJCF of `m`, which must be the model MuJoCo loaded last (mj_saveLastXML; changes
// made to `m` since are written): poses and inertials inside <worldbody> with every digit, mesh
// and texture folders absolute from `model_dir` (the model file's folder), so the text loads
// from any folder.
std::string SavedMjcf(const mjModel* m, const std::filesystem::path& model_dir);

// The same model as URDF (loaded by sim::LoadModel's URDF path): a link per body at its last
// joint's anchor (URDF joints turn about their link's origin; a body with several joints gets
// a link per joint, named BODY__JOINT), a fixed link per site, camera and named geom (named as
// it), the bodies' inertials; no visual or collision geometry. Compliances and a gravity tilt
// have no URDF form and are in `skipped` as well.
ExportedModel ExportUrdf(const DeclaredModel& declared);

// The stiffness of the position servos a URDF gets when it is the truth (N m/rad; N/m on a
// prismatic joint). The static solves hold a servoed joint at its command whatever kp is; kp
// sets how stiffly dynamic kinds track it.
inline constexpr double kDefaultServoKp = 100.0;

// A URDF as MJCF with a position servo per hinge and slide joint.
struct ConvertedUrdf {
  std::string text;                   // the MJCF
  std::vector<std::string> servoed;   // joints given a servo (actuator named as the joint)
  std::vector<std::string> skipped;   // joints MJCF gives no position servo (floating)
  std::vector<std::string> warnings;  // the URDF import's (meshes dropped, MuJoCo's)
};

// MuJoCo's import of `urdf_path` (sim::LoadModel: its links' inertials, unreadable meshes
// dropped) written as MJCF (SavedMjcf: the compiled poses and inertials with every digit,
// mesh folders absolute) with a <position kp> servo per hinge and slide joint: `flexbench
// convert`, and how a URDF becomes the truth (LoadTruthModel). Loaded, its bodies stand where
// the URDF's do. Throws InputError naming the file for anything but a loadable URDF, or kp <= 0.
ConvertedUrdf UrdfToMjcf(const std::string& urdf_path, double kp = kDefaultServoKp);

}  // namespace flexbench::sim
