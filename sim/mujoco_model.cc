#include "sim/mujoco_model.h"

#include <cctype>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <mutex>
#include <sstream>

#include "estimators/error.h"
#include "sim/config.h"
#include "sim/mesh_check.h"

namespace flexbench::sim {
namespace {

// MuJoCo reports warnings through a global C callback; collect them per load. Loading is rare
// and guarded by a mutex, so the global hook is safe to swap.
std::mutex g_load_mutex;
std::vector<std::string>* g_warnings = nullptr;

void PrintWarning(const char* msg) {
  std::string m = msg ? msg : "";
  while (!m.empty() && (m.back() == '\n' || m.back() == ' ')) m.pop_back();
  for (char& c : m) {
    if (c == '\n') c = ' ';
  }
  std::fprintf(stderr, "[flexbench] MuJoCo warning: %s\n", CapForMessage(m, 400).c_str());
}

[[noreturn]] void FatalError(const char* msg) {
  std::string m = msg ? msg : "";
  while (!m.empty() && (m.back() == '\n' || m.back() == ' ')) m.pop_back();
  for (char& c : m) {
    if (c == '\n') c = ' ';
  }
  // MuJoCo assumes the handler never returns: an exception leaves the failed call for good.
  throw MujocoError("MuJoCo: " + CapForMessage(m, 400));
}

void CollectWarning(const char* msg) {
  if (g_warnings) g_warnings->emplace_back(msg);
}

struct WarningScope {
  explicit WarningScope(std::vector<std::string>* sink) : previous(mju_user_warning) {
    g_warnings = sink;
    mju_user_warning = CollectWarning;
  }
  ~WarningScope() {
    mju_user_warning = previous;
    g_warnings = nullptr;
  }
  void (*previous)(const char*);
};

std::string Trim(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  for (char& c : s) {
    if (c == '\n') c = ' ';
  }
  return s;
}

int IdOrThrow(const mjModel* m, mjtObj type, const char* what, const std::string& name,
              const std::string& model_name) {
  int id = mj_name2id(m, type, name.c_str());
  if (id < 0) {
    throw InputError(model_name + ": no " + what + " named '" + name + "'");
  }
  return id;
}

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

void InstallMujocoHandlers() {
  if (mju_user_error != FatalError) mju_user_error = FatalError;
  if (mju_user_warning == nullptr) mju_user_warning = PrintWarning;
}

std::string PrepareUrdf(const std::string& urdf, const std::string& path,
                        std::vector<std::string>* warnings) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(path).parent_path();
  std::string out;
  size_t pos = 0;
  // Drop <visual>/<collision> elements whose mesh MuJoCo cannot read (missing file, or a format
  // other than STL/OBJ/MSH such as COLLADA): they carry no kinematics.
  for (;;) {
    size_t start = std::string::npos;
    std::string tag;
    for (const char* t : {"<visual", "<collision"}) {
      const size_t p = urdf.find(t, pos);
      if (p < start) {
        start = p;
        tag = t + 1;
      }
    }
    if (start == std::string::npos) break;
    const std::string close = "</" + tag + ">";
    const size_t end_self = urdf.find("/>", start);
    const size_t end_open = urdf.find('>', start);
    size_t end = urdf.find(close, start);
    if (end_open != std::string::npos && end_self != std::string::npos &&
        end_self + 1 == end_open) {
      end = end_open + 1;  // <visual .../>
    } else if (end != std::string::npos) {
      end += close.size();
    } else {
      break;
    }
    const std::string element = urdf.substr(start, end - start);
    bool drop = false;
    const size_t mesh = element.find("filename=\"");
    if (mesh != std::string::npos) {
      const size_t q0 = mesh + 10;
      const std::string file = element.substr(q0, element.find('"', q0) - q0);
      std::string lower = file;
      for (char& c : lower) c = static_cast<char>(std::tolower(c));
      const bool readable_format =
          EndsWith(lower, ".stl") || EndsWith(lower, ".obj") || EndsWith(lower, ".msh");
      if (!readable_format || !fs::exists(dir / file)) {
        drop = true;
        warnings->push_back(path + ": mesh '" + file + "' cannot be read; its " + tag +
                            " geometry is dropped (the kinematics are kept)");
      } else {
        // MuJoCo 2.2.2 corrupts memory on out-of-range face indices (sim/mesh_check.h).
        CheckMeshFile(dir / file, CapForMessage(path) + ": mesh '" + CapForMessage(file) + "'");
      }
    }
    out += urdf.substr(pos, start - pos);
    if (!drop) out += element;
    pos = end;
  }
  out += urdf.substr(pos);
  // Kinematics-only import: keep fixed links as bodies (a tool or ball frame must survive), and
  // give massless links a tiny inertia so the compiler accepts them.
  if (out.find("<mujoco>") == std::string::npos) {
    const size_t robot = out.find("<robot");
    const size_t open_end = robot == std::string::npos ? robot : out.find('>', robot);
    if (open_end != std::string::npos) {
      // On the <robot> line, so that lines in messages are the URDF's own.
      char bounds[96];
      std::snprintf(bounds, sizeof(bounds), "boundmass=\"%.17g\" boundinertia=\"%.17g\"",
                    kUrdfBoundMass, kUrdfBoundInertia);
      // strippath off: MuJoCo's URDF default keeps only a mesh's file name, whereas the checks
      // above find it where the URDF says.
      out.insert(open_end + 1,
                 "<mujoco><compiler fusestatic=\"false\" discardvisual=\"false\" "
                 "strippath=\"false\" " +
                     std::string(bounds) + "/></mujoco>");
    }
  }
  return out;
}

bool IsUrdfPath(const std::string& path) {
  const std::string ext = std::filesystem::path(path).extension().string();
  return ext == ".urdf" || ext == ".URDF";
}

MjModelPtr LoadModel(const std::string& path, std::vector<std::string>* warnings) {
  InstallMujocoHandlers();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    throw InputError(CapForMessage(path) + ": model file not found");
  }
  CheckInputFile(path, kMaxModelFileBytes);
  if (IsUrdfPath(path)) {
    std::ifstream in(path);
    std::stringstream text;
    text << in.rdbuf();
    std::vector<std::string> local;
    std::vector<std::string>* sink = warnings ? warnings : &local;
    const std::string prepared = PrepareUrdf(text.str(), path, sink);
    return LoadModelFromString(prepared, path, sink);
  }
  {
    // Meshes MuJoCo 2.2.2 would corrupt memory on are refused first (sim/mesh_check.h).
    std::ifstream in(path, std::ios::binary);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    CheckMjcfMeshes(text, path);
  }
  std::lock_guard<std::mutex> lock(g_load_mutex);
  std::vector<std::string> local;
  WarningScope scope(warnings ? warnings : &local);
  char error[1024] = "";
  MjModelPtr m(mj_loadXML(path.c_str(), nullptr, error, sizeof(error)));
  if (!m) {
    throw InputError(CapForMessage(path) +
                     ": MuJoCo rejected the model: " + CapForMessage(Trim(error), 400));
  }
  CheckRenderSizes(m.get(), path);
  return m;
}

MjModelPtr LoadModelFromString(const std::string& xml, const std::string& name,
                               std::vector<std::string>* warnings) {
  InstallMujocoHandlers();
  CheckMjcfMeshes(xml, name);  // see LoadModel
  std::lock_guard<std::mutex> lock(g_load_mutex);
  std::vector<std::string> local;
  WarningScope scope(warnings ? warnings : &local);
  // mjVFS holds its file table inline (megabytes): keep it off the stack.
  auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  if (mj_makeEmptyFileVFS(vfs.get(), name.c_str(), static_cast<int>(xml.size())) != 0) {
    throw InputError(name + ": cannot create an in-memory model file");
  }
  int index = mj_findFileVFS(vfs.get(), name.c_str());
  std::memcpy(vfs->filedata[index], xml.data(), xml.size());
  char error[1024] = "";
  MjModelPtr m(mj_loadXML(name.c_str(), vfs.get(), error, sizeof(error)));
  mj_deleteVFS(vfs.get());
  if (!m) {
    throw InputError(CapForMessage(name) +
                     ": MuJoCo rejected the model: " + CapForMessage(Trim(error), 400));
  }
  CheckRenderSizes(m.get(), name);
  return m;
}

MjDataPtr MakeData(const mjModel* m) { return MjDataPtr(mj_makeData(m)); }

void CheckRenderSizes(const mjModel* m, const std::string& model_name) {
  // OSMesa allocates these in memory; 8192 is the largest texture a software GL promises.
  constexpr int kMaxPixels = 8192;
  const std::string name = CapForMessage(model_name);
  const int width = m->vis.global.offwidth;
  const int height = m->vis.global.offheight;
  if (width < 1 || height < 1 || width > kMaxPixels || height > kMaxPixels) {
    throw InputError(name + ": <visual><global offwidth=\"" + std::to_string(width) +
                     "\" offheight=\"" + std::to_string(height) +
                     "\">: the offscreen buffer must be 1.." + std::to_string(kMaxPixels) +
                     " pixels each way");
  }
  if (m->vis.quality.offsamples < 0 || m->vis.quality.offsamples > 16) {
    throw InputError(name + ": <visual><quality offsamples=\"" +
                     std::to_string(m->vis.quality.offsamples) + "\">: must be 0..16");
  }
  const int shadow = m->vis.quality.shadowsize;
  if (shadow < 0 || shadow > kMaxPixels) {
    throw InputError(name + ": <visual><quality shadowsize=\"" + std::to_string(shadow) +
                     "\">: the shadow map must be 0.." + std::to_string(kMaxPixels) +
                     " pixels (0: no shadows)");
  }
}

int JointId(const mjModel* m, const std::string& name, const std::string& model_name) {
  return IdOrThrow(m, mjOBJ_JOINT, "joint", name, model_name);
}
int BodyId(const mjModel* m, const std::string& name, const std::string& model_name) {
  return IdOrThrow(m, mjOBJ_BODY, "body", name, model_name);
}
int SiteId(const mjModel* m, const std::string& name, const std::string& model_name) {
  return IdOrThrow(m, mjOBJ_SITE, "site", name, model_name);
}
int GeomId(const mjModel* m, const std::string& name, const std::string& model_name) {
  return IdOrThrow(m, mjOBJ_GEOM, "geom", name, model_name);
}
int CameraId(const mjModel* m, const std::string& name, const std::string& model_name) {
  return IdOrThrow(m, mjOBJ_CAMERA, "camera", name, model_name);
}

std::string ObjectName(const mjModel* m, mjtObj type, int id) {
  const char* n = mj_id2name(m, type, id);
  return n ? std::string(n) : std::string();
}

}  // namespace flexbench::sim
