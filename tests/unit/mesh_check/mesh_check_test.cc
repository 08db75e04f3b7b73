// The mesh guard in front of MuJoCo 2.2.2 (sim/mesh_check.h): face indices outside the vertex
// list corrupt memory inside mj_loadXML, so they must be refused before MuJoCo sees them, as
// one line naming the file and the mesh, while valid meshes (inline, OBJ with relative and
// v/vt indices, MSH) still load.
#include "sim/mesh_check.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "estimators/error.h"
#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;

// A tetrahedron with outward faces; MuJoCo checks the orientation.
const char* kVertices = "0 0 0  1 0 0  0 1 0  0 0 1";
const char* kFaces = "0 2 1  0 1 3  0 3 2  1 2 3";

std::string Model(const std::string& mesh_attributes, const std::string& prefix = "") {
  return "<mujoco>\n" + prefix + "  <asset>\n    <mesh name=\"m\" " + mesh_attributes +
         "/>\n  </asset>\n  <worldbody><body name=\"b\"><joint name=\"j\"/>"
         "<geom type=\"mesh\" mesh=\"m\"/></body></worldbody>\n</mujoco>\n";
}

std::string Inline(const std::string& vertex, const std::string& face) {
  return Model("vertex=\"" + vertex + "\" face=\"" + face + "\"");
}

std::string Msh(const std::vector<float>& v, const std::vector<std::int32_t>& f,
                std::int32_t nvertex_in_header = -1) {
  std::int32_t header[4] = {
      nvertex_in_header >= 0 ? nvertex_in_header : static_cast<std::int32_t>(v.size() / 3), 0, 0,
      static_cast<std::int32_t>(f.size() / 3)};
  std::string out(reinterpret_cast<const char*>(header), sizeof(header));
  out.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(float));
  out.append(reinterpret_cast<const char*>(f.data()), f.size() * sizeof(std::int32_t));
  return out;
}

TEST(MeshCheck, ValidMeshesLoad) {
  TempDir tmp;
  // Inline, and a commented-out broken mesh that MuJoCo never reads.
  EXPECT_NO_THROW(sim::LoadModelFromString(
      Model(std::string("vertex=\"") + kVertices + "\" face=\"" + kFaces + "\"",
            "  <!-- <mesh name=\"old\" vertex=\"0 0 0\" face=\"0 1 2\"/> -->\n"),
      (tmp.path() / "inline.xml").string()));
  // OBJ: 1-based, negative (relative) and v/vt indices; found through <compiler meshdir>.
  WriteFile(tmp.path() / "meshes/t.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf -4 -1 -2\nf 2/1 3/1 4/1\n");
  WriteFile(tmp.path() / "obj.xml", Model("file=\"t.obj\"", "  <compiler meshdir=\"meshes\"/>\n"));
  EXPECT_NO_THROW(sim::LoadModel((tmp.path() / "obj.xml").string()));
  WriteFile(tmp.path() / "t.msh",
            Msh({0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1}, {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3}));
  WriteFile(tmp.path() / "msh.xml", Model("file=\"t.msh\""));
  EXPECT_NO_THROW(sim::LoadModel((tmp.path() / "msh.xml").string()));
}

TEST(MeshCheck, InlineMeshesOutOfRangeOrRaggedAreOneLineNamingFileAndMesh) {
  const std::pair<std::string, std::string> cases[] = {
      {Inline(kVertices, "0 2 1  0 1 -1  0 3 2"), "face index -1 is outside its 4 vertices"},
      {Inline(kVertices, "0 2 1  0 1 4  0 3 2"), "face index 4 is outside its 4 vertices"},
      {Inline(kVertices, "0 2 1  0 1 99999999999"), "face index 99999999999 is outside"},
      {Inline(kVertices, "0 2 1  0 1"), "face has 5 indices, not a multiple of 3"},
      {Inline("0 0 0  1 0 0  0 1", kFaces), "vertex has 8 numbers, not a multiple of 3"},
      {Inline(kVertices, "0 2 1  0 1 3.5"), "face value '3.5' is not an integer"},
      {Inline(kVertices, "0 2 1  0 1 &#51;"), "face value '&#51;' is not an integer"},
      {Inline("0 0 0  1 0 0  0 1 0  0 0 nan", kFaces), "vertex value 'nan' is not a finite"},
      {Model("face=\"0 1 2\""), "face given without vertex"},
  };
  for (const auto& [xml, expected] : cases) {
    const std::string e = ErrorOf([&] { sim::LoadModelFromString(xml, "/x/bad.xml"); });
    EXPECT_NE(e.find("/x/bad.xml:3: mesh 'm': " + expected), std::string::npos)
        << xml << "\n-> " << e;
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  }
  // A quoted '>' does not end the tag early, so the face list is still seen.
  const std::string quoted =
      "<mujoco><asset><mesh name=\"a>b\" vertex='0 0 0' face='0 0 1'/>"
      "</asset></mujoco>";
  EXPECT_NE(
      ErrorOf([&] { sim::CheckMjcfMeshes(quoted, "q.xml"); }).find("mesh 'a>b': face index 1"),
      std::string::npos);
}

TEST(MeshCheck, MeshFilesAndIncludesAreCheckedToo) {
  TempDir tmp;
  WriteFile(tmp.path() / "far.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 9\n");
  WriteFile(tmp.path() / "zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
  WriteFile(tmp.path() / "back.obj", "v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n");
  WriteFile(tmp.path() / "far.msh", Msh({0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1}, {0, 2, 1, 0, 1, 7}));
  WriteFile(tmp.path() / "short.msh", Msh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, 5));
  const std::pair<std::string, std::string> cases[] = {
      {"far.obj", "line 6: face index 9 is outside its 4 vertices"},
      {"zero.obj", "line 4: face index 0 is outside its 3 vertices"},
      {"back.obj", "line 3: face index -3 is outside its 2 vertices"},
      {"far.msh", "face index 7 is outside its 4 vertices"},
      {"short.msh", "bytes, but its header (5 vertices, 0 normals"},
  };
  for (const auto& [file, expected] : cases) {
    const fs::path model = tmp.path() / (file + ".xml");
    WriteFile(model, Model("file=\"" + file + "\""));
    const std::string e = ErrorOf([&] { sim::LoadModel(model.string()); });
    EXPECT_NE(e.find(model.string() + ":3: mesh 'm' ("), std::string::npos) << e;
    EXPECT_NE(e.find(expected), std::string::npos) << file << " -> " << e;
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  }
  // A broken mesh in an included file names the included file.
  WriteFile(tmp.path() / "assets.xml",
            "<mujoco>\n  <asset>\n\n    <mesh name=\"inc\" vertex=\"0 0 0\" face=\"0 0 1\"/>\n"
            "  </asset>\n</mujoco>\n");
  WriteFile(tmp.path() / "main.xml", "<mujoco>\n  <include file=\"assets.xml\"/>\n</mujoco>\n");
  const std::string e = ErrorOf([&] { sim::LoadModel((tmp.path() / "main.xml").string()); });
  EXPECT_NE(e.find((tmp.path() / "assets.xml").string() + ":4: mesh 'inc': face index 1"),
            std::string::npos)
      << e;
}

// The fuzzer's reproducer through the CLI: exit 2 and one line naming the file and the mesh
// (before the guard: "free(): invalid next size", exit 134, or valgrind/ASan reports).
TEST(MeshCheck, FuzzReproducerIsExit2AndOneLine) {
  const std::string file =
      SourceDir() + "/tests/fuzz/regressions/mjcf/mesh_face_index_out_of_range.xml";
  const CommandResult r = RunCommand(BinDir() + "/flexbench inspect " + file + " </dev/null");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(r.err, "flexbench: error: " + file +
                       ":3: mesh 'm': face index -2 is outside its 5 vertices (0..4)\n");
  EXPECT_EQ(r.out, "");
}

}  // namespace
}  // namespace flexbench::testing
