#include "sim/params.h"

#include "estimators/error.h"

namespace flexbench::sim {

ComponentParams::ComponentParams(std::optional<ConfigNode> node, std::string where)
    : node_(std::move(node)), where_(std::move(where)) {
  if (node_ && !node_->IsMap()) node_->Fail("expected a mapping of parameters");
}

ComponentParams ComponentParams::FromYaml(const std::string& yaml, const std::string& where) {
  const std::string text = yaml.empty() ? std::string("{}") : yaml;
  return ComponentParams(ConfigNode::LoadString(text, where), where);
}

bool ComponentParams::Has(const std::string& key) const { return node_ && node_->Has(key); }

std::optional<ConfigNode> ComponentParams::Optional(const std::string& key) const {
  if (!node_) return std::nullopt;
  return node_->Optional(key);
}

ConfigNode ComponentParams::Require(const std::string& key) const {
  if (!node_ || !node_->Has(key)) Fail("missing parameter '" + key + "'");
  return node_->Child(key);
}

double ComponentParams::GetDouble(const std::string& key, double fallback) const {
  const auto c = Optional(key);
  return c ? c->AsDouble() : fallback;
}

double ComponentParams::RequireDouble(const std::string& key) const {
  return Require(key).AsDouble();
}

double ComponentParams::GetPositive(const std::string& key, double fallback,
                                    bool allow_zero) const {
  const auto c = Optional(key);
  if (!c) return fallback;
  const double v = c->AsDouble();
  if (allow_zero ? v < 0.0 : v <= 0.0) c->Fail(allow_zero ? "must be >= 0" : "must be > 0");
  return v;
}

int ComponentParams::GetInt(const std::string& key, int fallback) const {
  const auto c = Optional(key);
  return c ? c->AsInt() : fallback;
}

std::string ComponentParams::GetString(const std::string& key, const std::string& fallback) const {
  const auto c = Optional(key);
  return c ? c->AsString() : fallback;
}

std::string ComponentParams::RequireString(const std::string& key) const {
  return Require(key).AsString();
}

Vec3 ComponentParams::GetVec3(const std::string& key, const Vec3& fallback) const {
  const auto c = Optional(key);
  if (!c) return fallback;
  const std::vector<double> v = c->AsDoubleList();
  if (v.size() != 3) c->Fail("expected a list of 3 numbers");
  return Vec3(v[0], v[1], v[2]);
}

std::vector<std::string> ComponentParams::GetStringList(
    const std::string& key, const std::vector<std::string>& fallback) const {
  const auto c = Optional(key);
  if (!c) return fallback;
  std::vector<std::string> out;
  if (c->IsScalar()) {
    out.push_back(c->AsString());
    return out;
  }
  for (const ConfigNode& item : c->Items()) out.push_back(item.AsString());
  return out;
}

void ComponentParams::Fail(const std::string& message) const {
  throw InputError(where_ + ": " + message);
}

void ComponentParams::FailKey(const std::string& key, const std::string& message) const {
  if (const auto c = Optional(key)) c->Fail(message);
  Fail(message);
}

}  // namespace flexbench::sim
