// libapriltag's tag families by name, with ownership.
#pragma once

#include <memory>
#include <string>
#include <vector>

struct apriltag_family;

namespace flexbench::render {

struct FamilyDeleter {
  std::string name;
  void operator()(apriltag_family* f) const;
};
using FamilyPtr = std::unique_ptr<apriltag_family, FamilyDeleter>;

// Creates a family ("tag36h11", "tag25h9", "tag16h5", "tagStandard41h12", ...). Throws
// InputError naming `key` for an unknown family.
FamilyPtr MakeFamily(const std::string& name, const std::string& key = "family");

}  // namespace flexbench::render
