#include "render/apriltag_family.h"

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagStandard41h12.h>

#include "estimators/error.h"

namespace flexbench::render {
namespace {

struct FamilyEntry {
  const char* name;
  apriltag_family_t* (*create)();
  void (*destroy)(apriltag_family_t*);
};

// One explicit list of supported families.
constexpr FamilyEntry kFamilies[] = {
    {"tag36h11", tag36h11_create, tag36h11_destroy},
    {"tag25h9", tag25h9_create, tag25h9_destroy},
    {"tag16h5", tag16h5_create, tag16h5_destroy},
    {"tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy},
    {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
};

}  // namespace

void FamilyDeleter::operator()(apriltag_family* f) const {
  for (const auto& e : kFamilies) {
    if (name == e.name) {
      e.destroy(f);
      return;
    }
  }
}

FamilyPtr MakeFamily(const std::string& name, const std::string& key) {
  for (const auto& e : kFamilies) {
    if (name == e.name) return FamilyPtr(e.create(), FamilyDeleter{name});
  }
  std::string known;
  for (const auto& e : kFamilies) known += std::string(known.empty() ? "" : ", ") + e.name;
  throw InputError(key + ": unknown AprilTag family '" + name + "' (known: " + known + ")");
}

}  // namespace flexbench::render
