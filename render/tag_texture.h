// AprilTags in MuJoCo models.
//
// Model convention: a tag is a mesh geom whose material uses a 2-D texture named
// "apriltag_<family>_<id>" (e.g. apriltag_tag36h11_3). The mesh's front face carries the four
// texture coordinates (0,0) (1,0) (1,1) (0,1) exactly once each; every other vertex has texture
// coordinates inside the quiet zone. The texture is declared with builtin="flat" and a size;
// ApplyTagTextures fills it with the tag from libapriltag's own family data, plus a white quiet
// zone of `quiet_cells` cells, upscaled nearest-neighbour. Texture row 0 (v = 0) is the top of
// the tag as printed.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

namespace flexbench::render {

struct TagInModel {
  std::string family;
  int id = -1;
  int geom_id = -1;
  int texture_id = -1;
  // Cells across the black border square (libapriltag's width_at_border, 8 for tag36h11).
  int border_cells = 0;
  // Edge length of the black border square, the size libapriltag's pose estimation expects.
  double size_m = 0.0;
  // Corners of the black border square in the geom frame, in libapriltag's order (det->p):
  // tag-frame (-1,+1), (+1,+1), (+1,-1), (-1,-1) with x right and y down on the printed tag.
  std::array<Eigen::Vector3d, 4> corners_geom;
};

inline constexpr int kDefaultQuietCells = 1;

// Finds every tag texture, writes the tag image into m->tex_rgb and returns the tags found.
// Throws InputError naming the texture for an unknown family, an id outside the family, a
// non-square texture or one smaller than the tag's cells, and a tag geom that is not a mesh
// with the texture coordinates described above. Re-upload the textures to any Renderer made
// before this call.
std::vector<TagInModel> ApplyTagTextures(mjModel* m, int quiet_cells = kDefaultQuietCells);

// World positions of a tag's four corners (libapriltag order) for the state in `d`.
std::array<Eigen::Vector3d, 4> TagCornersWorld(const mjData* d, const TagInModel& tag);

}  // namespace flexbench::render
