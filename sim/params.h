// Parameters of one effect or one sensor in a scenario file. The block may be absent
// (`payload:` with no value); errors then name the entry that lacks the key.
//
// Not estimators::Params: that one is a plain map of numbers, so the estimators read their
// parameters without YAML (estimators/ sees no file formats); this one keeps the YAML node,
// since effects and sensors take maps of joint names, lists and strings, and their errors name
// the file line.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "sim/config.h"

namespace flexbench::sim {

class ComponentParams {
 public:
  // `node` is the parameter map (nullopt when the entry has no value); `where` names the entry
  // in messages, e.g. "rover.yaml:12: effect 'payload'".
  ComponentParams(std::optional<ConfigNode> node, std::string where);
  // Parameters given as text (tests, programmatic set-ups): `yaml` is a flow or block map.
  static ComponentParams FromYaml(const std::string& yaml, const std::string& where);

  bool Has(const std::string& key) const;
  std::optional<ConfigNode> Optional(const std::string& key) const;
  ConfigNode Require(const std::string& key) const;

  double GetDouble(const std::string& key, double fallback) const;
  double RequireDouble(const std::string& key) const;
  // A number that must be > 0 (or >= 0 with allow_zero).
  double GetPositive(const std::string& key, double fallback, bool allow_zero = false) const;
  int GetInt(const std::string& key, int fallback) const;
  std::string GetString(const std::string& key, const std::string& fallback) const;
  std::string RequireString(const std::string& key) const;
  Vec3 GetVec3(const std::string& key, const Vec3& fallback) const;
  std::vector<std::string> GetStringList(const std::string& key,
                                         const std::vector<std::string>& fallback) const;

  [[noreturn]] void Fail(const std::string& message) const;
  // Fails naming `key` (its file line when present).
  [[noreturn]] void FailKey(const std::string& key, const std::string& message) const;
  const std::string& where() const { return where_; }
  const std::optional<ConfigNode>& node() const { return node_; }

 private:
  std::optional<ConfigNode> node_;
  std::string where_;
};

}  // namespace flexbench::sim
