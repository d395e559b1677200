#include "robocal/core/yaml.hpp"

namespace robocal::core {

YAML::Node load_yaml_text(const std::string& text, const std::string& source) {
  try {
    return YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw InputError(source + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML (" + e.msg +
                     ")");
  }
}

std::string yaml_where(const std::string& source, const YAML::Node& node) {
  const YAML::Mark mark = node.Mark();
  return mark.is_null() || mark.line < 0 ? source : source + ":" + std::to_string(mark.line + 1);
}

double YamlContext::to_double(const YAML::Node& n, const std::string& key) const {
  if (!n.IsScalar()) fail(n, "'" + key + "' must be a number");
  try {
    return n.as<double>();
  } catch (const YAML::Exception&) {
    fail(n, "'" + key + "' must be a number (got '" + n.Scalar() + "')");
  }
}

int YamlContext::to_int(const YAML::Node& n, const std::string& key) const {
  if (!n.IsScalar()) fail(n, "'" + key + "' must be an integer");
  try {
    return n.as<int>();
  } catch (const YAML::Exception&) {
    fail(n, "'" + key + "' must be an integer (got '" + n.Scalar() + "')");
  }
}

std::string YamlContext::to_string(const YAML::Node& n, const std::string& key) const {
  if (!n.IsScalar()) fail(n, "'" + key + "' must be a string");
  return n.Scalar();
}

std::vector<double> YamlContext::to_doubles(const YAML::Node& n, const std::string& key) const {
  if (!n.IsSequence()) fail(n, "'" + key + "' must be a list of numbers");
  std::vector<double> out;
  for (const YAML::Node& item : n) out.push_back(to_double(item, key));
  return out;
}

void YamlContext::reject_unknown_keys(const YAML::Node& map,
                                      const std::vector<std::string>& known) const {
  for (const auto& kv : map) {
    const std::string key = kv.first.Scalar();
    bool ok = false;
    for (const std::string& k : known) ok = ok || k == key;
    if (ok) continue;
    std::string allowed;
    for (const std::string& k : known) allowed += (allowed.empty() ? "" : ", ") + k;
    std::string message = "unknown key '";
    message.append(key).append("' (allowed: ").append(allowed).append(")");
    fail(kv.first, message);
  }
}

}  // namespace robocal::core
