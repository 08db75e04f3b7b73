// Scenario and declared-model files: YAML with errors that name the file, the line and the
// key, and detection of unknown keys (every key a reader does not consume is an error).
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "estimators/error.h"

namespace flexbench {

// `value` cut to at most `max_chars` bytes (never inside a UTF-8 sequence) with "..." appended
// when cut: user values echoed in messages stay short.
std::string CapForMessage(const std::string& value, size_t max_chars = 200);

// Largest scenario or declared-model file read (bytes); a bigger one is refused as bad input.
inline constexpr std::uintmax_t kMaxConfigFileBytes = 16u << 20;

// Largest YAML tree read from a file or a --set value: nodes (every value, list and mapping;
// counted while parsing, before any tree is built) and nesting depth. A parsed node costs
// hundreds of bytes, so the byte cap alone lets a 15 MiB list build gigabytes.
inline constexpr size_t kMaxYamlNodes = 1000000;
inline constexpr int kMaxYamlDepth = 64;

// Checks that `path` names a regular file of at most `max_bytes`; throws InputError
// "<path>: ..." (the path capped) when it does not exist, is a folder, a device or a pipe, or
// is too big.
// A file it accepts is recorded as an input of this process (RecordedInputFiles).
void CheckInputFile(const std::string& path, std::uintmax_t max_bytes);

// Every file this process has accepted as an input so far (absolute, normal paths): the
// scenario, the models, the declared files, meshes, CSVs. An output folder that holds one of
// them is never replaced. Thread-safe.
std::vector<std::string> RecordedInputFiles();
void RecordInputFile(const std::string& path);

// A file spelled a name its former way (`former` for `current`): read as the current name, with
// one "[flexbench] note:" line on stderr naming `where`, once per place and process (a rig that
// loads one model many times says it once).
void NoteFormerName(const std::string& where, const std::string& former,
                    const std::string& current);

// A command-line override of one scenario key (`--set KEY=VALUE`): `key` a dotted path
// (estimators.ppoe_ekf.iterations), `value` YAML text (3, [1, 2], {a: 1}, text).
struct ConfigOverride {
  std::string key;
  std::string value;
};
// Parses "KEY=VALUE"; throws InputError "--set '<arg>': ..." for a missing '=' or an empty or
// malformed dotted key.
ConfigOverride ParseOverride(const std::string& arg);

class ConfigNode {
 public:
  // Parses a YAML file. Throws InputError "<file>: not found" or "<file>:<line>: YAML syntax
  // error: ...". Also input errors: a file that is not a regular file or is bigger than
  // kMaxConfigFileBytes, text that is not UTF-8, a key that is a list or a map, a key given
  // twice in one mapping, more than one YAML document.
  // `overrides` replace (or add) keys after parsing, with the same checks as the file's own
  // text; errors about an overridden key name "--set <key>" instead of a line. Maps along the
  // path are created when absent, so a misspelt key is reported as unknown by the reader.
  static ConfigNode LoadFile(const std::string& path,
                             const std::vector<ConfigOverride>& overrides = {});
  // Parses YAML text; `name` stands for the file in messages.
  static ConfigNode LoadString(const std::string& text, const std::string& name,
                               const std::vector<ConfigOverride>& overrides = {});

  bool Has(const std::string& key) const;
  // Required child; throws "<file>:<line>: missing key '<path>'".
  ConfigNode Child(const std::string& key) const;
  std::optional<ConfigNode> Optional(const std::string& key) const;

  // Scalar conversions; throw "<file>:<line>: key '<path>': expected <type>".
  double AsDouble() const;
  int AsInt() const;
  bool AsBool() const;
  std::string AsString() const;
  std::vector<double> AsDoubleList() const;
  // The node as one line of YAML (flow style), e.g. for a --set value; consumes the subtree.
  std::string AsYamlText() const;

  double GetDouble(const std::string& key) const { return Child(key).AsDouble(); }
  int GetInt(const std::string& key) const { return Child(key).AsInt(); }
  std::string GetString(const std::string& key) const { return Child(key).AsString(); }
  double GetDouble(const std::string& key, double fallback) const;
  int GetInt(const std::string& key, int fallback) const;
  bool GetBool(const std::string& key, bool fallback) const;
  std::string GetString(const std::string& key, const std::string& fallback) const;

  bool IsMap() const { return node_.IsMap(); }
  bool IsSequence() const { return node_.IsSequence(); }
  bool IsScalar() const { return node_.IsScalar(); }
  // Keys of a map in file order (each one is consumed by the Child call that follows).
  std::vector<std::string> Keys() const;
  // Elements of a sequence.
  std::vector<ConfigNode> Items() const;

  // Throws "<file>:<line>: unknown key '<path>'" for the first key nothing consumed.
  void CheckNoUnknownKeys() const;

  // "<file>:<line>" of this node, and "<file>:<line>: key '<path>'".
  std::string Where() const;
  std::string WhereKey() const;
  [[noreturn]] void Fail(const std::string& message) const;

  const std::string& file() const { return state_->file; }
  const std::string& key_path() const { return path_; }
  // Directory of the file, for resolving relative paths in it.
  std::string Directory() const;
  // `value` relative to the file's directory unless absolute.
  std::string ResolvePath(const std::string& value) const;

 private:
  struct State {
    std::string file;
    std::set<std::string> consumed;
    std::vector<std::string> overridden;  // dotted keys set on the command line
  };
  // "<file>:<line>" of a node at `path`, or "--set <key>" when the key came from an override.
  std::string Location(const YAML::Mark& mark, const std::string& path) const;
  ConfigNode(std::shared_ptr<State> state, YAML::Node node, std::string path)
      : state_(std::move(state)), node_(std::move(node)), path_(std::move(path)) {}
  ConfigNode MakeChild(const YAML::Node& node, const std::string& child_path) const;
  void CheckUnknown(const YAML::Node& node, const std::string& path) const;
  void Consume(const YAML::Node& node, const std::string& path) const;

  std::shared_ptr<State> state_;
  YAML::Node node_;
  std::string path_;
};

}  // namespace flexbench
