// A guard in front of MuJoCo 2.2.2's mesh compiler. Given a mesh whose face indices fall
// outside its vertex list (negative, or >= the number of vertices), mj_loadXML reads and
// writes out of bounds and frees a pointer it never allocated (valgrind, ASan; in the normal
// build it aborts with "free(): invalid next size" or, by luck, returns its "vertex index out
// of range" error). Found by the mjcf fuzz target; the input is in
// tests/fuzz/regressions/mjcf/. The same happens for OBJ and MSH mesh files. These checks run
// before MuJoCo sees the model and turn such meshes into an InputError: one line naming the
// file, the mesh and the line.
#pragma once

#include <filesystem>
#include <string>

namespace flexbench::sim {

// Checks MJCF text `xml` (read from `path`, which names it in errors and resolves relative
// files) before MuJoCo opens anything it names:
//   - every file an element names (`file` of include, mesh, skin, hfield, texture; a cube
//     texture's `fileright` ... `fileback`; a URDF mesh's `filename`), at each place MuJoCo may
//     look for it (the main file's folder, the including file's, <compiler meshdir / texturedir
//     / assetdir>, the bare name): one that exists must be a regular file of at most
//     kMaxModelFileBytes (CheckInputFile; it is recorded as an input of the run). MuJoCo blocks
//     forever on a FIFO or /dev/stdin and reads /dev/zero until memory runs out. Files that do
//     not exist are left to MuJoCo, which reports them;
//   - <include> files are scanned the same way, at most 16 deep;
//   - every <mesh>: inline `vertex` / `face` lists (numbers only, a multiple of 3 each, every
//     face index in [0, number of vertices)) and mesh files ending in .obj or .msh (see
//     CheckMeshFile);
//   - `pos` and `fromto` of every element (a URDF's <origin xyz>): finite, |value| <= 1e6 m
//     (larger ones compile, then every result is NaN).
// The scan is a small XML tokenizer (comments, CDATA, quoted attribute values holding '>' are
// skipped correctly); malformed XML is left to MuJoCo's parser.
void CheckMjcfMeshes(const std::string& xml, const std::string& path);

// Checks the face indices of one mesh file (.obj: `f` lines against the `v` lines, 1-based or
// negative relative indices; .msh: MuJoCo's binary layout, size against its header, indices
// against its vertex count). Other formats (STL holds no indices) pass. `what` names the mesh
// in the error ("<model>: mesh 'x'").
void CheckMeshFile(const std::filesystem::path& file, const std::string& what);

}  // namespace flexbench::sim
