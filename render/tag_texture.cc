#include "render/tag_texture.h"

#include <apriltag/apriltag.h>

#include <cmath>
#include <optional>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "render/apriltag_family.h"
#include "sim/mujoco_model.h"

namespace flexbench::render {
namespace {

constexpr char kPrefix[] = "apriltag_";

// "apriltag_tag36h11_3" -> ("tag36h11", 3).
std::optional<std::pair<std::string, int>> ParseTagTextureName(const std::string& name) {
  if (name.rfind(kPrefix, 0) != 0) return std::nullopt;
  const std::string rest = name.substr(sizeof(kPrefix) - 1);
  const size_t us = rest.rfind('_');
  if (us == std::string::npos || us + 1 >= rest.size()) return std::nullopt;
  const std::string id_text = rest.substr(us + 1);
  for (char c : id_text) {
    if (c < '0' || c > '9') return std::nullopt;
  }
  return std::make_pair(rest.substr(0, us), std::stoi(id_text));
}

void FillTexture(mjModel* m, int tex_id, const apriltag_family_t* family, int id, int quiet_cells,
                 const std::string& tex_name) {
  const int cells = family->total_width + 2 * quiet_cells;
  const int w = m->tex_width[tex_id];
  const int h = m->tex_height[tex_id];
  if (m->tex_type[tex_id] != mjTEXTURE_2D) {
    throw InputError("texture '" + tex_name + "': a tag texture must have type=\"2d\"");
  }
  if (w != h || w < cells) {
    throw InputError("texture '" + tex_name + "': a tag texture must be square and at least " +
                     std::to_string(cells) + " px wide (got " + std::to_string(w) + "x" +
                     std::to_string(h) + ")");
  }
  image_u8_t* tag = apriltag_to_image(const_cast<apriltag_family_t*>(family), id);
  mjtByte* rgb = m->tex_rgb + m->tex_adr[tex_id];
  for (int r = 0; r < h; ++r) {
    const int cell_r = r * cells / h - quiet_cells;
    for (int c = 0; c < w; ++c) {
      const int cell_c = c * cells / w - quiet_cells;
      std::uint8_t value = 255;
      if (cell_r >= 0 && cell_c >= 0 && cell_r < tag->height && cell_c < tag->width) {
        value = tag->buf[cell_r * tag->stride + cell_c];
      }
      mjtByte* px = rgb + 3 * (static_cast<size_t>(r) * w + c);
      px[0] = px[1] = px[2] = value;
    }
  }
  image_u8_destroy(tag);
}

TagInModel DescribeTagGeom(const mjModel* m, int geom_id, const std::string& tex_name,
                           const apriltag_family_t* family, int quiet_cells) {
  const std::string geom_name = sim::ObjectName(m, mjOBJ_GEOM, geom_id);
  const std::string where = "geom '" + geom_name + "' (texture '" + tex_name + "')";
  if (m->geom_type[geom_id] != mjGEOM_MESH) {
    throw InputError(where + ": a tag geom must be a mesh with texture coordinates");
  }
  const int mesh = m->geom_dataid[geom_id];
  const int tc_adr = m->mesh_texcoordadr[mesh];
  if (tc_adr < 0) throw InputError(where + ": the tag mesh has no texcoord");
  const int vadr = m->mesh_vertadr[mesh];
  const int nv = m->mesh_vertnum[mesh];
  // Front-face vertices by their texture coordinate (u, v).
  const double targets[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  Eigen::Vector3d front[4];
  for (int k = 0; k < 4; ++k) {
    int found = -1;
    for (int v = 0; v < nv; ++v) {
      const float* tc = m->mesh_texcoord + 2 * (tc_adr + v);
      if (std::abs(tc[0] - targets[k][0]) < 1e-6 && std::abs(tc[1] - targets[k][1]) < 1e-6) {
        if (found >= 0) {
          throw InputError(where + ": texcoord (" + std::to_string(targets[k][0]) + ", " +
                           std::to_string(targets[k][1]) + ") appears on more than one vertex");
        }
        found = v;
      }
    }
    if (found < 0) throw InputError(where + ": the tag mesh lacks a front-face corner texcoord");
    const float* p = m->mesh_vert + 3 * (vadr + found);
    front[k] = Eigen::Vector3d(p[0], p[1], p[2]);
  }
  const auto at = [&](double u, double v) {
    return ((1 - u) * (1 - v) * front[0] + u * (1 - v) * front[1] + u * v * front[2] +
            (1 - u) * v * front[3])
        .eval();
  };
  const double cells = family->total_width + 2 * quiet_cells;
  const double b = (0.5 * (family->total_width - family->width_at_border) + quiet_cells) / cells;
  TagInModel tag;
  // libapriltag's corner order: tag-frame (x, y) = (-1,+1), (+1,+1), (+1,-1), (-1,-1), x right,
  // y down on the printed tag, i.e. bottom-left, bottom-right, top-right, top-left.
  const double xy[4][2] = {{-1, 1}, {1, 1}, {1, -1}, {-1, -1}};
  for (int k = 0; k < 4; ++k) {
    const double u = b + (1 - 2 * b) * 0.5 * (xy[k][0] + 1);
    const double v = b + (1 - 2 * b) * 0.5 * (xy[k][1] + 1);
    tag.corners_geom[k] = at(u, v);
  }
  tag.size_m = (tag.corners_geom[1] - tag.corners_geom[0]).norm();
  return tag;
}

}  // namespace

std::vector<TagInModel> ApplyTagTextures(mjModel* m, int quiet_cells) {
  std::vector<TagInModel> tags;
  for (int t = 0; t < m->ntex; ++t) {
    const std::string tex_name = sim::ObjectName(m, mjOBJ_TEXTURE, t);
    const auto parsed = ParseTagTextureName(tex_name);
    if (!parsed) continue;
    const auto& [family_name, id] = *parsed;
    FamilyPtr family = MakeFamily(family_name, "texture '" + tex_name + "'");
    if (id < 0 || id >= static_cast<int>(family->ncodes)) {
      throw InputError("texture '" + tex_name + "': tag id " + std::to_string(id) +
                       " is outside family " + family_name + " (ids 0.." +
                       std::to_string(family->ncodes - 1) + ")");
    }
    FillTexture(m, t, family.get(), id, quiet_cells, tex_name);
    for (int g = 0; g < m->ngeom; ++g) {
      const int mat = m->geom_matid[g];
      if (mat < 0 || m->mat_texid[mat] != t) continue;
      TagInModel tag = DescribeTagGeom(m, g, tex_name, family.get(), quiet_cells);
      tag.family = family_name;
      tag.id = id;
      tag.geom_id = g;
      tag.texture_id = t;
      tag.border_cells = family->width_at_border;
      tags.push_back(tag);
    }
  }
  return tags;
}

std::array<Eigen::Vector3d, 4> TagCornersWorld(const mjData* d, const TagInModel& tag) {
  const Mat3 R = RotFromRowMajor(d->geom_xmat + 9 * tag.geom_id);
  const Eigen::Map<const Eigen::Vector3d> t(d->geom_xpos + 3 * tag.geom_id);
  std::array<Eigen::Vector3d, 4> out;
  for (int k = 0; k < 4; ++k) out[k] = R * tag.corners_geom[k] + t;
  return out;
}

}  // namespace flexbench::render
