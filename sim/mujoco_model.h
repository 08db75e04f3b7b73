// Loading MuJoCo models (MJCF, and URDF through MuJoCo's own importer) with errors that name
// the file, and RAII ownership of mjModel / mjData.
#pragma once

#include <mujoco/mujoco.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "estimators/error.h"

namespace flexbench::sim {

struct MjModelDeleter {
  void operator()(mjModel* m) const { mj_deleteModel(m); }
};
struct MjDataDeleter {
  void operator()(mjData* d) const { mj_deleteData(d); }
};
using MjModelPtr = std::unique_ptr<mjModel, MjModelDeleter>;
using MjDataPtr = std::unique_ptr<mjData, MjDataDeleter>;

// A fatal MuJoCo error (mju_error): in practice a model MuJoCo cannot serve (an allocation it
// cannot make, a GL buffer it cannot create), so bad input. The message is "MuJoCo: <text>".
class MujocoError : public InputError {
 public:
  using InputError::InputError;
};

// Installs MuJoCo's process-wide error and warning handlers (idempotent; LoadModel calls it):
// a warning goes to stderr as one line "[flexbench] MuJoCo warning: ..." (never to
// MUJOCO_LOG.TXT); a fatal MuJoCo error (MuJoCo's default would print "Press Enter to exit",
// wait on stdin and write MUJOCO_LOG.TXT) throws MujocoError out of the MuJoCo call, so the
// caller's destructors run (an output temporary is removed) and a host process such as the
// Python interpreter survives. The exception crosses MuJoCo's C frames: libmujoco is built with
// unwind tables (.eh_frame covers every function), and those frames hold no cleanups, so what
// MuJoCo allocated in them leaks; callers free what they own (Renderer frees its context).
void InstallMujocoHandlers();

// Largest model file read (bytes).
inline constexpr std::uintmax_t kMaxModelFileBytes = 64u << 20;

// Loads an MJCF or URDF file. URDF goes through MuJoCo's own importer after PrepareUrdf. Throws
// InputError("<path>: <MuJoCo's message>") when the file is missing or MuJoCo rejects it. Warnings
// MuJoCo emits while compiling are appended to `warnings` when given (e.g. URDF meshes it cannot
// read).
MjModelPtr LoadModel(const std::string& path, std::vector<std::string>* warnings = nullptr);

// Loads a model from an in-memory MJCF string (tests use inline models). `name` is used in
// error messages. Inline models must not reference asset files.
MjModelPtr LoadModelFromString(const std::string& xml, const std::string& name = "inline.xml",
                               std::vector<std::string>* warnings = nullptr);

MjDataPtr MakeData(const mjModel* m);

// The model's offscreen buffer (<visual><global offwidth offheight>), multisampling and shadow
// map (<visual><quality offsamples shadowsize>) within what the software GL can allocate;
// outside, MuJoCo ends in mju_error or OSMesa fails. InputError naming `model_name` and the
// attribute. LoadModel checks every model it loads; Renderer checks again.
void CheckRenderSizes(const mjModel* m, const std::string& model_name);

// Whether LoadModel reads `path` as URDF (.urdf or .URDF).
bool IsUrdfPath(const std::string& path);

// The mass and inertia LoadModel gives a massless URDF link (<compiler boundmass boundinertia>).
inline constexpr double kUrdfBoundMass = 1e-6;
inline constexpr double kUrdfBoundInertia = 1e-9;

// URDF text made loadable for kinematics: <visual>/<collision> elements with meshes MuJoCo
// cannot read (missing, or not STL/OBJ/MSH) are dropped with a warning each, fixed links stay
// bodies (fusestatic off), mesh paths stay relative to the URDF's folder (strippath off) and
// massless links get a tiny inertia. `path` resolves mesh files.
std::string PrepareUrdf(const std::string& urdf, const std::string& path,
                        std::vector<std::string>* warnings);

// Name -> id lookups that throw InputError naming the model and the missing name.
int JointId(const mjModel* m, const std::string& name, const std::string& model_name = "model");
int BodyId(const mjModel* m, const std::string& name, const std::string& model_name = "model");
int SiteId(const mjModel* m, const std::string& name, const std::string& model_name = "model");
int GeomId(const mjModel* m, const std::string& name, const std::string& model_name = "model");
int CameraId(const mjModel* m, const std::string& name, const std::string& model_name = "model");

// MuJoCo's name of an object, or "" for unnamed ones.
std::string ObjectName(const mjModel* m, mjtObj type, int id);

}  // namespace flexbench::sim
