#include "sim/mesh_check.h"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <set>
#include <utility>
#include <vector>

#include "estimators/error.h"
#include "sim/config.h"
#include "sim/mujoco_model.h"

namespace fs = std::filesystem;

namespace flexbench::sim {
namespace {

// Includes nested deeper than this are refused.
constexpr int kMaxIncludeDepth = 16;

struct Element {
  std::string name;
  std::vector<std::pair<std::string, std::string>> attributes;  // in file order
  int line = 0;

  // The first attribute called `key` (tinyxml2, under MuJoCo, returns the first of duplicates).
  const std::string* Find(const std::string& key) const {
    for (const auto& [k, v] : attributes) {
      if (k == key) return &v;
    }
    return nullptr;
  }
};

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

// The start tags of `xml` in order. Comments, CDATA, processing instructions, declarations
// and end tags are skipped; attribute values are read quote to quote, so a '>' or '<' inside
// one does not end the tag. At the first malformed tag the scan stops: MuJoCo's parser
// rejects such a file before compiling any mesh.
std::vector<Element> StartTags(const std::string& xml) {
  std::vector<Element> out;
  const size_t n = xml.size();
  size_t i = 0;
  int line = 1;
  size_t line_pos = 0;  // offset up to which `line` counts newlines
  auto line_at = [&](size_t pos) {
    for (; line_pos < pos && line_pos < n; ++line_pos) line += xml[line_pos] == '\n';
    return line;
  };
  auto skip_past = [&](size_t from, const char* end) {
    const size_t e = xml.find(end, from);
    return e == std::string::npos ? n : e + std::strlen(end);
  };
  while ((i = xml.find('<', i)) != std::string::npos) {
    if (xml.compare(i, 4, "<!--") == 0) {
      i = skip_past(i + 4, "-->");
    } else if (xml.compare(i, 9, "<![CDATA[") == 0) {
      i = skip_past(i + 9, "]]>");
    } else if (xml.compare(i, 2, "<?") == 0) {
      i = skip_past(i + 2, "?>");
    } else if (xml.compare(i, 2, "<!") == 0 || xml.compare(i, 2, "</") == 0) {
      i = skip_past(i + 2, ">");
    } else {
      Element e;
      e.line = line_at(i);
      size_t p = i + 1;
      while (p < n && !IsSpace(xml[p]) && xml[p] != '/' && xml[p] != '>') e.name += xml[p++];
      for (;;) {
        while (p < n && IsSpace(xml[p])) ++p;
        if (p >= n) return out;
        if (xml[p] == '>' || xml[p] == '/') break;
        std::string key;
        while (p < n && !IsSpace(xml[p]) && xml[p] != '=' && xml[p] != '>' && xml[p] != '/') {
          key += xml[p++];
        }
        while (p < n && IsSpace(xml[p])) ++p;
        if (p >= n || xml[p] != '=') return out;
        ++p;
        while (p < n && IsSpace(xml[p])) ++p;
        if (p >= n || (xml[p] != '"' && xml[p] != '\'')) return out;
        const char quote = xml[p++];
        const size_t end = xml.find(quote, p);
        if (end == std::string::npos) return out;
        e.attributes.emplace_back(std::move(key), xml.substr(p, end - p));
        p = end + 1;
      }
      out.push_back(std::move(e));
      i = p;
    }
  }
  return out;
}

std::vector<std::string> Tokens(const std::string& text) {
  std::vector<std::string> out;
  size_t i = 0;
  while (i < text.size()) {
    while (i < text.size() && IsSpace(text[i])) ++i;
    const size_t start = i;
    while (i < text.size() && !IsSpace(text[i])) ++i;
    if (i > start) out.push_back(text.substr(start, i - start));
  }
  return out;
}

// A whole token as an integer (decimal, optional sign), or false.
bool ParseInteger(const std::string& token, long long* value) {
  errno = 0;
  char* end = nullptr;
  *value = std::strtoll(token.c_str(), &end, 10);
  return errno == 0 && end != token.c_str() && *end == '\0';
}

// A whole token as a finite number, or false.
bool ParseFinite(const std::string& token) {
  char* end = nullptr;
  const double v = std::strtod(token.c_str(), &end);
  return end != token.c_str() && *end == '\0' && std::isfinite(v);
}

std::string Quoted(const std::string& s) { return "'" + CapForMessage(s, 40) + "'"; }

// `file` when it exists: a regular file of at most kMaxModelFileBytes (recorded as an input of
// the run), else an InputError "<what>: <file>: ...". MuJoCo would block on a FIFO or a
// terminal and read a device such as /dev/zero until memory runs out. A missing file is left to
// MuJoCo, which names it. Returns whether the file exists.
bool CheckReferencedFile(const fs::path& file, const std::string& what) {
  std::error_code ec;
  const fs::file_status st = fs::status(file, ec);
  if (ec || !fs::exists(st)) return false;
  try {
    CheckInputFile(file.string(), kMaxModelFileBytes);
  } catch (const InputError& e) {
    throw InputError(what + ": " + e.what());
  }
  return true;
}

// The bytes of `file`, checked by CheckReferencedFile first ("" when it does not exist).
std::string ReadCapped(const fs::path& file, const std::string& what) {
  if (!CheckReferencedFile(file, what)) return {};
  std::ifstream in(file, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

bool IsRegularFile(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Inline vertex/face lists of one <mesh>.
void CheckInlineMesh(const Element& mesh, const std::string& what) {
  const std::string* vertex = mesh.Find("vertex");
  const std::string* face = mesh.Find("face");
  long long nvertex = 0;
  if (vertex) {
    const std::vector<std::string> v = Tokens(*vertex);
    for (const std::string& t : v) {
      if (!ParseFinite(t)) {
        throw InputError(what + ": vertex value " + Quoted(t) + " is not a finite number");
      }
    }
    if (v.size() % 3 != 0) {
      throw InputError(what + ": vertex has " + std::to_string(v.size()) +
                       " numbers, not a multiple of 3");
    }
    nvertex = static_cast<long long>(v.size() / 3);
  }
  if (!face) return;
  // Faces index the inline vertices; without them (a mesh file's vertices) the indices cannot
  // be checked here, so the combination is refused rather than handed to MuJoCo unchecked.
  if (!vertex) throw InputError(what + ": face given without vertex");
  const std::vector<std::string> f = Tokens(*face);
  if (f.size() % 3 != 0) {
    throw InputError(what + ": face has " + std::to_string(f.size()) +
                     " indices, not a multiple of 3");
  }
  for (const std::string& t : f) {
    long long index = 0;
    if (!ParseInteger(t, &index)) {
      throw InputError(what + ": face value " + Quoted(t) + " is not an integer");
    }
    if (index < 0 || index >= nvertex) {
      throw InputError(what + ": face index " + std::to_string(index) + " is outside its " +
                       std::to_string(nvertex) + " vertices (0.." + std::to_string(nvertex - 1) +
                       ")");
    }
  }
}

void CheckObj(const fs::path& file, const std::string& what) {
  const std::string text = ReadCapped(file, what);
  const std::string shown = what + " (" + CapForMessage(file.string()) + ")";
  // Pass 1: the total number of vertices (a positive index counts from the file's first one).
  // Pass 2: every face's vertex index; a negative one counts back from the vertices read so far.
  long long total = 0;
  for (int pass = 0; pass < 2; ++pass) {
    long long seen = 0;
    int line_no = 0;
    size_t pos = 0;
    while (pos < text.size()) {
      size_t eol = text.find('\n', pos);
      if (eol == std::string::npos) eol = text.size();
      ++line_no;
      size_t p = pos;
      while (p < eol && (text[p] == ' ' || text[p] == '\t')) ++p;
      const bool vertex_line =
          p + 1 < eol && text[p] == 'v' && (text[p + 1] == ' ' || text[p + 1] == '\t');
      const bool face_line =
          p + 1 < eol && text[p] == 'f' && (text[p + 1] == ' ' || text[p + 1] == '\t');
      if (vertex_line) ++seen;
      if (face_line && pass == 1) {
        std::string rest = text.substr(p + 1, eol - p - 1);
        if (!rest.empty() && rest.back() == '\r') rest.pop_back();
        for (const std::string& t : Tokens(rest)) {
          long long index = 0;
          if (!ParseInteger(t.substr(0, t.find('/')), &index)) {
            throw InputError(shown + ", line " + std::to_string(line_no) + ": face vertex " +
                             Quoted(t) + " is not an index");
          }
          const long long zero_based = index > 0 ? index - 1 : seen + index;
          const long long bound = index > 0 ? total : seen;
          if (index == 0 || zero_based < 0 || zero_based >= bound) {
            throw InputError(shown + ", line " + std::to_string(line_no) + ": face index " +
                             std::to_string(index) + " is outside its " + std::to_string(bound) +
                             " vertices");
          }
        }
      }
      pos = eol + 1;
    }
    total = seen;
  }
}

void CheckMsh(const fs::path& file, const std::string& what) {
  const std::string bytes = ReadCapped(file, what);
  const std::string shown = what + " (" + CapForMessage(file.string()) + ")";
  std::int32_t header[4];
  if (bytes.size() < sizeof(header)) throw InputError(shown + ": shorter than its 16-byte header");
  std::memcpy(header, bytes.data(), sizeof(header));
  const long long nvertex = header[0], nnormal = header[1], ntexcoord = header[2],
                  nface = header[3];
  if (nvertex < 0 || nnormal < 0 || ntexcoord < 0 || nface < 0) {
    throw InputError(shown + ": negative count in its header");
  }
  const long long faces_at = 16 + 12 * nvertex + 12 * nnormal + 8 * ntexcoord;
  const long long expected = faces_at + 12 * nface;
  if (expected != static_cast<long long>(bytes.size())) {
    throw InputError(shown + ": " + std::to_string(bytes.size()) + " bytes, but its header (" +
                     std::to_string(nvertex) + " vertices, " + std::to_string(nnormal) +
                     " normals, " + std::to_string(ntexcoord) + " texture coordinates, " +
                     std::to_string(nface) + " faces) needs " + std::to_string(expected));
  }
  for (long long k = 0; k < 3 * nface; ++k) {
    std::int32_t index = 0;
    std::memcpy(&index, bytes.data() + faces_at + 4 * k, sizeof(index));
    if (index < 0 || index >= nvertex) {
      throw InputError(shown + ": face index " + std::to_string(index) + " is outside its " +
                       std::to_string(nvertex) + " vertices");
    }
  }
}

struct Scanned {
  std::string file;  // as named in messages
  fs::path dir;      // its folder
  Element element;
};

std::string Where(const std::string& file, int line) {
  return CapForMessage(file) + ":" + std::to_string(line);
}

void Collect(const std::string& xml, const std::string& file, const fs::path& main_dir, int depth,
             std::set<fs::path>* visited, std::vector<Scanned>* out) {
  const fs::path dir = fs::path(file).parent_path();
  for (Element& e : StartTags(xml)) {
    if (e.name == "include") {
      // Deeper nesting is no model anyone writes; unchecked, a file at that depth could be a
      // pipe MuJoCo would block on.
      if (depth >= kMaxIncludeDepth) {
        throw InputError(Where(file, e.line) + ": <include> nested more than " +
                         std::to_string(kMaxIncludeDepth) + " files deep");
      }
      if (const std::string* name = e.Find("file")) {
        // MuJoCo resolves an include against the main file's folder; the including file's
        // folder is checked too, so a guess on either side does not skip a file.
        const std::string what = Where(file, e.line) + ": include " + Quoted(*name);
        for (const fs::path& base : {main_dir, dir}) {
          const fs::path p = base / *name;
          if (!CheckReferencedFile(p, what)) continue;
          std::error_code ec;
          const fs::path key = fs::weakly_canonical(p, ec);
          if (!visited->insert(ec ? p : key).second) continue;
          Collect(ReadCapped(p, what), p.string(), main_dir, depth + 1, visited, out);
        }
      }
    }
    out->push_back({file, dir, std::move(e)});
  }
}

// Attributes naming a file MuJoCo opens: `file` (include, mesh, skin, hfield, texture), a cube
// texture's `fileright` ... `fileback`, a URDF mesh's `filename`.
bool IsFileAttribute(const std::string& key) { return key.compare(0, 4, "file") == 0; }

// Largest coordinate accepted in a position (m): far beyond any robot or scene, small enough
// that products of positions (inertias, distances squared) stay finite.
constexpr double kMaxPosition = 1e6;

// `pos` and `fromto` of any element (a URDF's <origin xyz>): every number finite and within
// kMaxPosition. Values that are not numbers are left to MuJoCo's parser.
void CheckPositions(const Scanned& s) {
  const Element& e = s.element;
  for (const auto& [key, value] : e.attributes) {
    if (key != "pos" && key != "fromto" && !(key == "xyz" && e.name == "origin")) continue;
    for (const std::string& t : Tokens(value)) {
      char* end = nullptr;
      const double v = std::strtod(t.c_str(), &end);
      if (end == t.c_str() || *end != '\0') continue;
      if (!std::isfinite(v) || std::abs(v) > kMaxPosition) {
        throw InputError(Where(s.file, e.line) + ": <" + CapForMessage(e.name, 40) + "> " + key +
                         ": " + Quoted(t) + " is out of range (|value| <= 1e6 m)");
      }
    }
  }
}

}  // namespace

void CheckMeshFile(const fs::path& file, const std::string& what) {
  const std::string ext = Lower(file.extension().string());
  if (ext == ".obj") CheckObj(file, what);
  if (ext == ".msh") CheckMsh(file, what);
}

void CheckMjcfMeshes(const std::string& xml, const std::string& path) {
  const fs::path main_dir = fs::path(path).parent_path();
  std::set<fs::path> visited;
  std::vector<Scanned> elements;
  Collect(xml, path, main_dir, 0, &visited, &elements);
  // Asset files are found through <compiler meshdir/texturedir/assetdir> (and, with strippath,
  // by their bare name); every folder MuJoCo might use is tried, and each existing candidate
  // is checked.
  std::vector<fs::path> asset_dirs;
  for (const Scanned& s : elements) {
    if (s.element.name != "compiler") continue;
    for (const char* key : {"meshdir", "texturedir", "assetdir"}) {
      if (const std::string* d = s.element.Find(key)) {
        asset_dirs.push_back(fs::path(*d).is_absolute() ? fs::path(*d) : main_dir / *d);
      }
    }
  }
  const auto candidates = [&](const Scanned& s, const std::string& value) {
    const fs::path v(value);
    std::vector<fs::path> out = {main_dir / v, s.dir / v, main_dir / v.filename()};
    for (const fs::path& d : asset_dirs) {
      out.push_back(d / v);
      out.push_back(d / v.filename());
    }
    std::set<fs::path> seen;
    std::vector<fs::path> unique;
    for (const fs::path& c : out) {
      if (seen.insert(c.lexically_normal()).second) unique.push_back(c);
    }
    return unique;
  };
  int index = 0;
  for (const Scanned& s : elements) {
    const Element& e = s.element;
    CheckPositions(s);
    for (const auto& [key, value] : e.attributes) {
      if (!IsFileAttribute(key) || value.empty()) continue;
      const std::string what = Where(s.file, e.line) + ": <" + CapForMessage(e.name, 40) + "> " +
                               key + " " + Quoted(value);
      for (const fs::path& c : candidates(s, value)) CheckReferencedFile(c, what);
    }
    if (e.name != "mesh") continue;
    const std::string* name = e.Find("name");
    const std::string* file = e.Find("file");
    std::string what = Where(s.file, e.line) + ": mesh ";
    what += name ? Quoted(*name) : file ? "from " + Quoted(*file) : "#" + std::to_string(index);
    ++index;
    CheckInlineMesh(e, what);
    if (!file) continue;
    for (const fs::path& c : candidates(s, *file)) {
      if (IsRegularFile(c)) CheckMeshFile(c, what);
    }
  }
}

}  // namespace flexbench::sim
