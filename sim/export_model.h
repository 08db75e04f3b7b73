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
//     effect:joint_elasticity and numeric effect:joint_elasticity:stiffness, k = -1/c). Not
//     <joint stiffness>: that spring pulls the link towards a fixed springref, whereas a gear
//     spring sits between the motor and the link, which is what the truth effect simulates.
// Everything else (backlash, link_bending, base_compliance, payload, transmission_error,
// joint_error_curve, stiffening_spring's cubic term, a moved body frame) has no MJCF form: the
// caller names it in one warning line.
#pragma once

#include <string>
#include <vector>

#include "sim/declared_model.h"

namespace flexbench::sim {

struct ExportedModel {
  std::string text;                  // the file's text
  std::vector<std::string> skipped;  // identified effects (or parts) the MJCF cannot hold
};

// The calibrated MJCF of `declared` (its model must be an MJCF file). Numbers that place
// frames carry every digit. Throws InputError naming the declared file for a bad model or
// effect (as BuildDeclaredChain does).
ExportedModel ExportMjcf(const DeclaredModel& declared);

// The same model as URDF (loaded by sim::LoadModel's URDF path): a link per body at its last
// joint's anchor (URDF joints turn about their link's origin; a body with several joints gets
// a link per joint, named BODY__JOINT), a fixed link per site, camera and named geom (named as
// it), the bodies' inertials; no visual or collision geometry. Compliances and a gravity tilt
// have no URDF form and are in `skipped` as well.
ExportedModel ExportUrdf(const DeclaredModel& declared);

}  // namespace flexbench::sim
