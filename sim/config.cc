#include "sim/config.h"

#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/parser.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <set>
#include <sstream>

namespace flexbench {
namespace {

std::string JoinPath(const std::string& parent, const std::string& key) {
  return parent.empty() ? key : parent + "." + key;
}

std::string LineOf(const YAML::Mark& mark) {
  return mark.line >= 0 ? std::to_string(mark.line + 1) : std::string("?");
}

// Length of the valid UTF-8 sequence at s[i], 0 when it is not one (overlongs, surrogates and
// code points above U+10FFFF are invalid).
size_t Utf8SequenceLength(const std::string& s, size_t i) {
  const auto b = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = b(i);
  if (c < 0x80) return 1;
  size_t n = 0;
  unsigned lo = 0x80, hi = 0xBF;
  if (c >= 0xC2 && c <= 0xDF) {
    n = 2;
  } else if (c >= 0xE0 && c <= 0xEF) {
    n = 3;
    if (c == 0xE0) lo = 0xA0;
    if (c == 0xED) hi = 0x9F;
  } else if (c >= 0xF0 && c <= 0xF4) {
    n = 4;
    if (c == 0xF0) lo = 0x90;
    if (c == 0xF4) hi = 0x8F;
  } else {
    return 0;
  }
  if (i + n > s.size()) return 0;
  if (b(i + 1) < lo || b(i + 1) > hi) return 0;
  for (size_t k = 2; k < n; ++k) {
    if (b(i + k) < 0x80 || b(i + k) > 0xBF) return 0;
  }
  return n;
}

// Text must be UTF-8 (JSON output, messages): the first bad byte is named with its line and,
// when the line starts with a plain key, that key.
void CheckUtf8(const std::string& text, const std::string& name) {
  size_t line = 1, line_start = 0;
  for (size_t i = 0; i < text.size();) {
    if (text[i] == '\n') {
      ++line;
      line_start = i + 1;
      ++i;
      continue;
    }
    const size_t n = Utf8SequenceLength(text, i);
    if (n > 0) {
      i += n;
      continue;
    }
    char hex[8];
    std::snprintf(hex, sizeof(hex), "0x%02X", static_cast<unsigned char>(text[i]));
    std::string key;
    const std::string head = text.substr(line_start, i - line_start);
    const size_t colon = head.find(':');
    if (colon != std::string::npos) {
      const size_t a = head.find_first_not_of(" -\t");
      if (a != std::string::npos && a < colon) key = head.substr(a, colon - a);
    }
    throw InputError(name + ":" + std::to_string(line) + ":" +
                     (key.empty() ? "" : " key '" + CapForMessage(key, 60) + "':") +
                     " not valid UTF-8 (byte " + hex + "); save the file as UTF-8");
  }
}

// Structural checks yaml-cpp does not make: every key a scalar, no key twice in one mapping.
// Counts visited nodes: aliases can make a small file a huge tree.
void CheckStructure(const YAML::Node& node, const std::string& name, const std::string& path,
                    size_t* visited) {
  if (++*visited > kMaxYamlNodes) {
    throw InputError(name + ": more than " + std::to_string(kMaxYamlNodes) +
                     " YAML nodes (aliases expanding?)");
  }
  if (node.IsMap()) {
    std::set<std::string> seen;
    for (const auto& kv : node) {
      if (!kv.first.IsScalar()) {
        throw InputError(name + ":" + LineOf(kv.first.Mark()) + ": a key under '" +
                         (path.empty() ? std::string("(top level)") : CapForMessage(path)) +
                         "' is a list or a mapping; keys are plain names");
      }
      const std::string key = kv.first.Scalar();
      const std::string child = JoinPath(path, key);
      if (!seen.insert(key).second) {
        throw InputError(name + ":" + LineOf(kv.first.Mark()) + ": key '" + CapForMessage(child) +
                         "' given twice");
      }
      CheckStructure(kv.second, name, child, visited);
    }
  } else if (node.IsSequence()) {
    for (size_t i = 0; i < node.size(); ++i) {
      CheckStructure(node[i], name, path + "[" + std::to_string(i) + "]", visited);
    }
  }
}

}  // namespace

std::string CapForMessage(const std::string& value, size_t max_chars) {
  if (value.size() <= max_chars) return value;
  size_t cut = max_chars;
  while (cut > 0 && (static_cast<unsigned char>(value[cut]) & 0xC0) == 0x80) --cut;
  return value.substr(0, cut) + "...";
}

void CheckInputFile(const std::string& path, std::uintmax_t max_bytes) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) {
    throw InputError(
        CapForMessage(path) + ": file not found or not readable" +
        (ec && ec != std::errc::no_such_file_or_directory ? " (" + ec.message() + ")" : ""));
  }
  if (fs::is_directory(st)) throw InputError(CapForMessage(path) + ": is a folder, not a file");
  if (!fs::is_regular_file(st)) {
    throw InputError(CapForMessage(path) + ": not a regular file (a device, pipe or socket)");
  }
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) throw InputError(CapForMessage(path) + ": cannot read: " + ec.message());
  if (size > max_bytes) {
    throw InputError(CapForMessage(path) + ": " + std::to_string(size) + " bytes, more than the " +
                     std::to_string(max_bytes) + " allowed");
  }
  RecordInputFile(path);
}

namespace {
std::mutex& InputFilesMutex() {
  static std::mutex m;
  return m;
}
std::set<std::string>& InputFiles() {
  static std::set<std::string> files;
  return files;
}
}  // namespace

void RecordInputFile(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::path p = fs::weakly_canonical(fs::absolute(path, ec), ec);
  if (ec) p = fs::absolute(path, ec).lexically_normal();
  const std::lock_guard<std::mutex> lock(InputFilesMutex());
  InputFiles().insert(p.string());
}

std::vector<std::string> RecordedInputFiles() {
  const std::lock_guard<std::mutex> lock(InputFilesMutex());
  return {InputFiles().begin(), InputFiles().end()};
}

void NoteFormerName(const std::string& where, const std::string& former,
                    const std::string& current) {
  const std::string line = "[flexbench] note: " + CapForMessage(where) + ": '" + former +
                           "' is the former name of '" + current + "'; read as '" + current + "'\n";
  static std::mutex mutex;
  static std::set<std::string> noted;
  const std::lock_guard<std::mutex> lock(mutex);
  if (noted.insert(line).second) std::fputs(line.c_str(), stderr);
}

ConfigOverride ParseOverride(const std::string& arg) {
  const size_t eq = arg.find('=');
  const std::string shown = "--set '" + CapForMessage(arg) + "'";
  if (eq == std::string::npos) throw InputError(shown + ": expected KEY=VALUE");
  // The file's cap holds for one override too (the shell's argument limit bounds a --set, but
  // not a Python caller's string): the parser's time and memory grow with the text.
  if (arg.size() > kMaxConfigFileBytes) {
    throw InputError("--set " + CapForMessage(arg.substr(0, eq), 60) + ": " +
                     std::to_string(arg.size()) + " bytes, more than the " +
                     std::to_string(kMaxConfigFileBytes) + " an override may hold");
  }
  ConfigOverride o{arg.substr(0, eq), arg.substr(eq + 1)};
  if (o.key.empty() || o.key.front() == '.' || o.key.back() == '.' ||
      o.key.find("..") != std::string::npos ||
      o.key.find_first_of(" \t[]{}:#") != std::string::npos) {
    throw InputError(shown + ": KEY must be a dotted path of names (a.b.c)");
  }
  return o;
}

namespace {

std::vector<std::string> SplitKey(const std::string& key) {
  std::vector<std::string> parts;
  size_t start = 0;
  for (size_t dot; (dot = key.find('.', start)) != std::string::npos; start = dot + 1) {
    parts.push_back(key.substr(start, dot - start));
  }
  parts.push_back(key.substr(start));
  return parts;
}

YAML::Node LoadOneDocument(const std::string& text, const std::string& name);

// Sets `o` in `root`: the value parsed and checked like file text, the maps on its path created
// when absent. yaml-cpp's Node::operator= writes through to the node, so the walk rebinds with
// reset().
void ApplyOverride(YAML::Node root, const ConfigOverride& o, const std::string& file) {
  const std::string where = "--set " + CapForMessage(o.key);
  for (size_t i = 0; i < o.value.size();) {
    const size_t n = Utf8SequenceLength(o.value, i);
    if (n == 0) {
      char hex[8];
      std::snprintf(hex, sizeof(hex), "0x%02X", static_cast<unsigned char>(o.value[i]));
      throw InputError(where + ": the value is not valid UTF-8 (byte " + hex + ")");
    }
    i += n;
  }
  YAML::Node value;
  try {
    value = LoadOneDocument(o.value, where);
  } catch (const YAML::Exception& e) {
    throw InputError(where + ": YAML syntax error in the value: " + CapForMessage(e.msg));
  }
  // An empty value is YAML's null, which would delete the key and let the run go on with its
  // default: never what a --set means.
  if (value.IsNull()) {
    throw InputError(where + ": no value ('" + CapForMessage(o.key) +
                     "=' or null would remove the key; give a value)");
  }
  size_t visited = 0;
  CheckStructure(value, where, o.key, &visited);
  const std::vector<std::string> parts = SplitKey(o.key);
  YAML::Node cur;
  cur.reset(root);
  std::string path;
  for (size_t i = 0; i + 1 < parts.size(); ++i) {
    path += (i ? "." : "") + parts[i];
    YAML::Node next = cur[parts[i]];
    if (!next.IsDefined() || next.IsNull()) {
      cur[parts[i]] = YAML::Node(YAML::NodeType::Map);
      next.reset(cur[parts[i]]);
    } else if (!next.IsMap()) {
      throw InputError(where + ": '" + CapForMessage(path) + "' in " + file +
                       " is not a mapping, so it has no key '" + CapForMessage(parts[i + 1]) + "'");
    }
    cur.reset(next);
  }
  cur[parts.back()] = value;
}

}  // namespace

namespace {

// Where each document of a YAML stream starts, and the size of the tree YAML::Load would build:
// nodes are counted and nesting measured while the events stream by, so a file under the byte
// cap that would build a tree of gigabytes (a list of millions of short items) or recurse
// deeply is refused before any tree exists.
class DocumentStarts : public YAML::EventHandler {
 public:
  explicit DocumentStarts(std::string name) : name_(std::move(name)) {}
  std::vector<YAML::Mark> starts;
  void OnDocumentStart(const YAML::Mark& mark) override { starts.push_back(mark); }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark& mark, YAML::anchor_t) override { Node(mark); }
  void OnAlias(const YAML::Mark& mark, YAML::anchor_t) override { Node(mark); }
  void OnScalar(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                const std::string&) override {
    Node(mark);
  }
  void OnSequenceStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {
    Open(mark);
  }
  void OnSequenceEnd() override { --depth_; }
  void OnMapStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {
    Open(mark);
  }
  void OnMapEnd() override { --depth_; }

 private:
  void Node(const YAML::Mark& mark) {
    if (++nodes_ > kMaxYamlNodes) {
      throw InputError(name_ + ":" + LineOf(mark) + ": more than " + std::to_string(kMaxYamlNodes) +
                       " YAML nodes (values, lists, mappings)");
    }
  }
  void Open(const YAML::Mark& mark) {
    Node(mark);
    if (++depth_ > kMaxYamlDepth) {
      throw InputError(name_ + ":" + LineOf(mark) + ": lists and mappings nested more than " +
                       std::to_string(kMaxYamlDepth) + " deep");
    }
  }
  std::string name_;
  size_t nodes_ = 0;
  int depth_ = 0;
};

// The one document of `text`, or an InputError. Never YAML::LoadAll: yaml-cpp 0.7 loops forever
// on some malformed streams (a file holding only ',' allocates until memory runs out; found by
// tests/fuzz, yaml-cpp issue 1040), handing out the same broken document again and again without
// moving on. Here at most two documents are parsed, and a second one starting where the first
// did is that loop: a syntax error at that place.
YAML::Node LoadOneDocument(const std::string& text, const std::string& name) {
  DocumentStarts events(name);
  {
    std::istringstream in(text);
    YAML::Parser parser(in);
    while (events.starts.size() < 2 && parser.HandleNextDocument(events)) {
    }
  }
  if (events.starts.size() > 1) {
    const YAML::Mark& first = events.starts[0];
    const YAML::Mark& second = events.starts[1];
    if (second.pos == first.pos) {
      throw InputError(name + ":" + LineOf(second) +
                       ": YAML syntax error: a token where no value can start");
    }
    throw InputError(name + ":" + LineOf(second) +
                     ": a second YAML document ('---'); a file holds one");
  }
  return YAML::Load(text);
}

}  // namespace

ConfigNode ConfigNode::LoadFile(const std::string& path,
                                const std::vector<ConfigOverride>& overrides) {
  CheckInputFile(path, kMaxConfigFileBytes);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(CapForMessage(path) + ": file not found or not readable");
  std::stringstream buffer;
  buffer << in.rdbuf();
  if (!in.good() && !in.eof()) throw InputError(CapForMessage(path) + ": read error");
  return LoadString(buffer.str(), path, overrides);
}

ConfigNode ConfigNode::LoadString(const std::string& text, const std::string& name_in,
                                  const std::vector<ConfigOverride>& overrides) {
  const std::string name = CapForMessage(name_in);
  auto state = std::make_shared<State>();
  state->file = name;
  CheckUtf8(text, name);
  YAML::Node doc;
  try {
    doc = LoadOneDocument(text, name);
  } catch (const YAML::Exception& e) {
    throw InputError(name + ":" + LineOf(e.mark) + ": YAML syntax error: " + CapForMessage(e.msg));
  }
  if (!doc.IsMap()) throw InputError(name + ": expected a YAML mapping at the top level");
  size_t visited = 0;
  CheckStructure(doc, name, "", &visited);
  for (const ConfigOverride& o : overrides) {
    ApplyOverride(doc, o, name);
    state->overridden.push_back(o.key);
  }
  return ConfigNode(state, doc, "");
}

std::string ConfigNode::Location(const YAML::Mark& mark, const std::string& path) const {
  for (const std::string& key : state_->overridden) {
    if (path == key || (path.size() > key.size() && path.compare(0, key.size(), key) == 0 &&
                        (path[key.size()] == '.' || path[key.size()] == '['))) {
      return "--set " + CapForMessage(key);
    }
  }
  // A map the override created on its way to the key has no line: name the override.
  if (mark.is_null()) {
    for (const std::string& key : state_->overridden) {
      if (key.size() > path.size() && key.compare(0, path.size(), path) == 0 &&
          key[path.size()] == '.') {
        return "--set " + CapForMessage(key);
      }
    }
  }
  return state_->file + ":" + LineOf(mark);
}

ConfigNode ConfigNode::MakeChild(const YAML::Node& node, const std::string& child_path) const {
  state_->consumed.insert(child_path);
  return ConfigNode(state_, node, child_path);
}

bool ConfigNode::Has(const std::string& key) const {
  return node_.IsMap() && node_[key].IsDefined() && !node_[key].IsNull();
}

ConfigNode ConfigNode::Child(const std::string& key) const {
  if (!node_.IsMap()) Fail("expected a mapping with key '" + JoinPath(path_, key) + "'");
  const YAML::Node child = node_[key];
  if (!child.IsDefined() || child.IsNull()) {
    throw InputError(Where() + ": missing key '" + CapForMessage(JoinPath(path_, key)) + "'");
  }
  return MakeChild(child, JoinPath(path_, key));
}

std::optional<ConfigNode> ConfigNode::Optional(const std::string& key) const {
  if (!Has(key)) {
    if (node_.IsMap() && node_[key].IsDefined()) state_->consumed.insert(JoinPath(path_, key));
    return std::nullopt;
  }
  return Child(key);
}

double ConfigNode::AsDouble() const {
  if (!node_.IsScalar()) Fail("expected a number");
  double v = 0.0;
  try {
    v = node_.as<double>();
  } catch (const YAML::Exception&) {
    Fail("expected a number, got '" + CapForMessage(node_.Scalar()) + "'");
  }
  if (!std::isfinite(v))
    Fail("expected a finite number, got '" + CapForMessage(node_.Scalar()) + "'");
  return v;
}

int ConfigNode::AsInt() const {
  if (!node_.IsScalar()) Fail("expected an integer");
  try {
    return node_.as<int>();
  } catch (const YAML::Exception&) {
    Fail("expected an integer, got '" + CapForMessage(node_.Scalar()) + "'");
  }
}

bool ConfigNode::AsBool() const {
  if (!node_.IsScalar()) Fail("expected true or false");
  try {
    return node_.as<bool>();
  } catch (const YAML::Exception&) {
    Fail("expected true or false, got '" + CapForMessage(node_.Scalar()) + "'");
  }
}

std::string ConfigNode::AsString() const {
  if (!node_.IsScalar()) Fail("expected a string");
  return node_.Scalar();
}

std::vector<double> ConfigNode::AsDoubleList() const {
  if (!node_.IsSequence()) Fail("expected a list of numbers");
  std::vector<double> out;
  for (const ConfigNode& item : Items()) out.push_back(item.AsDouble());
  return out;
}

std::string ConfigNode::AsYamlText() const {
  Consume(node_, path_);
  YAML::Emitter e;
  e.SetMapFormat(YAML::Flow);
  e.SetSeqFormat(YAML::Flow);
  e << node_;
  return e.c_str();
}

void ConfigNode::Consume(const YAML::Node& node, const std::string& path) const {
  state_->consumed.insert(path);
  if (node.IsMap()) {
    for (const auto& kv : node) Consume(kv.second, JoinPath(path, kv.first.as<std::string>()));
  } else if (node.IsSequence()) {
    for (size_t i = 0; i < node.size(); ++i) Consume(node[i], path + "[" + std::to_string(i) + "]");
  }
}

double ConfigNode::GetDouble(const std::string& key, double fallback) const {
  const auto c = Optional(key);
  return c ? c->AsDouble() : fallback;
}
int ConfigNode::GetInt(const std::string& key, int fallback) const {
  const auto c = Optional(key);
  return c ? c->AsInt() : fallback;
}
bool ConfigNode::GetBool(const std::string& key, bool fallback) const {
  const auto c = Optional(key);
  return c ? c->AsBool() : fallback;
}
std::string ConfigNode::GetString(const std::string& key, const std::string& fallback) const {
  const auto c = Optional(key);
  return c ? c->AsString() : fallback;
}

std::vector<std::string> ConfigNode::Keys() const {
  if (!node_.IsMap()) Fail("expected a mapping");
  std::vector<std::string> keys;
  for (const auto& kv : node_) keys.push_back(kv.first.as<std::string>());
  return keys;
}

std::vector<ConfigNode> ConfigNode::Items() const {
  if (!node_.IsSequence()) Fail("expected a list");
  std::vector<ConfigNode> items;
  for (size_t i = 0; i < node_.size(); ++i) {
    items.push_back(MakeChild(node_[i], path_ + "[" + std::to_string(i) + "]"));
  }
  return items;
}

void ConfigNode::CheckNoUnknownKeys() const { CheckUnknown(node_, path_); }

void ConfigNode::CheckUnknown(const YAML::Node& node, const std::string& path) const {
  if (node.IsMap()) {
    for (const auto& kv : node) {
      const std::string key = kv.first.as<std::string>();
      const std::string child = JoinPath(path, key);
      if (!state_->consumed.count(child)) {
        throw InputError(Location(kv.first.Mark(), child) + ": unknown key '" +
                         CapForMessage(child) + "'");
      }
      CheckUnknown(kv.second, child);
    }
  } else if (node.IsSequence()) {
    for (size_t i = 0; i < node.size(); ++i) {
      const std::string child = path + "[" + std::to_string(i) + "]";
      if (state_->consumed.count(child)) CheckUnknown(node[i], child);
    }
  }
}

std::string ConfigNode::Where() const { return Location(node_.Mark(), path_); }

std::string ConfigNode::WhereKey() const {
  return path_.empty() ? Where() : Where() + ": key '" + CapForMessage(path_) + "'";
}

void ConfigNode::Fail(const std::string& message) const {
  throw InputError(WhereKey() + ": " + message);
}

std::string ConfigNode::Directory() const {
  return std::filesystem::path(state_->file).parent_path().string();
}

std::string ConfigNode::ResolvePath(const std::string& value) const {
  const std::filesystem::path p(value);
  if (p.is_absolute()) return p.string();
  return (std::filesystem::path(Directory()) / p).lexically_normal().string();
}

}  // namespace flexbench
