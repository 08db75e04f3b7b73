#include "sim/mujoco_model.h"

#include <cstring>
#include <filesystem>
#include <mutex>

#include "estimators/error.h"

namespace flexbench::sim {
namespace {

// MuJoCo reports warnings through a global C callback; collect them per load. Loading is rare
// and guarded by a mutex, so the global hook is safe to swap.
std::mutex g_load_mutex;
std::vector<std::string>* g_warnings = nullptr;

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

}  // namespace

MjModelPtr LoadModel(const std::string& path, std::vector<std::string>* warnings) {
  if (!std::filesystem::is_regular_file(path)) {
    throw InputError(path + ": model file not found");
  }
  std::lock_guard<std::mutex> lock(g_load_mutex);
  std::vector<std::string> local;
  WarningScope scope(warnings ? warnings : &local);
  char error[1024] = "";
  mjModel* m = mj_loadXML(path.c_str(), nullptr, error, sizeof(error));
  if (!m) {
    throw InputError(path + ": MuJoCo rejected the model: " + Trim(error));
  }
  return MjModelPtr(m);
}

MjModelPtr LoadModelFromString(const std::string& xml, const std::string& name,
                               std::vector<std::string>* warnings) {
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
  mjModel* m = mj_loadXML(name.c_str(), vfs.get(), error, sizeof(error));
  mj_deleteVFS(vfs.get());
  if (!m) {
    throw InputError(name + ": MuJoCo rejected the model: " + Trim(error));
  }
  return MjModelPtr(m);
}

MjDataPtr MakeData(const mjModel* m) { return MjDataPtr(mj_makeData(m)); }

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
