#include "sim/config.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace flexbench {
namespace {

std::string JoinPath(const std::string& parent, const std::string& key) {
  return parent.empty() ? key : parent + "." + key;
}

std::string LineOf(const YAML::Mark& mark) {
  return mark.line >= 0 ? std::to_string(mark.line + 1) : std::string("?");
}

}  // namespace

ConfigNode ConfigNode::LoadFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": file not found or not readable");
  std::stringstream buffer;
  buffer << in.rdbuf();
  return LoadString(buffer.str(), path);
}

ConfigNode ConfigNode::LoadString(const std::string& text, const std::string& name) {
  auto state = std::make_shared<State>();
  state->file = name;
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw InputError(name + ":" + LineOf(e.mark) + ": YAML syntax error: " + e.msg);
  }
  if (!root.IsMap()) {
    throw InputError(name + ": expected a YAML mapping at the top level");
  }
  return ConfigNode(state, root, "");
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
    throw InputError(Where() + ": missing key '" + JoinPath(path_, key) + "'");
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
    Fail("expected a number, got '" + node_.Scalar() + "'");
  }
  if (!std::isfinite(v)) Fail("expected a finite number, got '" + node_.Scalar() + "'");
  return v;
}

int ConfigNode::AsInt() const {
  if (!node_.IsScalar()) Fail("expected an integer");
  try {
    return node_.as<int>();
  } catch (const YAML::Exception&) {
    Fail("expected an integer, got '" + node_.Scalar() + "'");
  }
}

bool ConfigNode::AsBool() const {
  if (!node_.IsScalar()) Fail("expected true or false");
  try {
    return node_.as<bool>();
  } catch (const YAML::Exception&) {
    Fail("expected true or false, got '" + node_.Scalar() + "'");
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
        throw InputError(state_->file + ":" + LineOf(kv.first.Mark()) + ": unknown key '" +
                         child + "'");
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

std::string ConfigNode::Where() const { return state_->file + ":" + LineOf(node_.Mark()); }

std::string ConfigNode::WhereKey() const {
  return path_.empty() ? Where() : Where() + ": key '" + path_ + "'";
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
