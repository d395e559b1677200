#pragma once
// Small helpers for the YAML loaders: every error names the file and the line of the node.
#include "robocal/vision/errors.hpp"

#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <string>
#include <vector>

namespace robocal::vision::detail {

struct YamlContext {
  std::string source;  // file name used in messages

  [[noreturn]] void fail(const YAML::Node& node, const std::string& what) const {
    const YAML::Mark mark = node.Mark();
    if (mark.line >= 0)
      throw FileFormatError(source + ":" + std::to_string(mark.line + 1) + ": " + what);
    throw FileFormatError(source + ": " + what);
  }
  [[noreturn]] void fail(const std::string& what) const {
    throw FileFormatError(source + ": " + what);
  }

  YAML::Node require(const YAML::Node& map, const std::string& key) const {
    const YAML::Node n = map[key];
    if (!n) fail(map, "missing required key '" + key + "'");
    return n;
  }

  double to_double(const YAML::Node& n, const std::string& key) const {
    if (!n.IsScalar()) fail(n, "'" + key + "' must be a number");
    try {
      return n.as<double>();
    } catch (const YAML::Exception&) {
      fail(n, "'" + key + "' must be a number (got '" + n.Scalar() + "')");
    }
  }
  int to_int(const YAML::Node& n, const std::string& key) const {
    if (!n.IsScalar()) fail(n, "'" + key + "' must be an integer");
    try {
      return n.as<int>();
    } catch (const YAML::Exception&) {
      fail(n, "'" + key + "' must be an integer (got '" + n.Scalar() + "')");
    }
  }
  std::string to_string(const YAML::Node& n, const std::string& key) const {
    if (!n.IsScalar()) fail(n, "'" + key + "' must be a string");
    return n.Scalar();
  }
  std::vector<double> to_doubles(const YAML::Node& n, const std::string& key) const {
    if (!n.IsSequence()) fail(n, "'" + key + "' must be a list of numbers");
    std::vector<double> out;
    for (const YAML::Node& item : n) out.push_back(to_double(item, key));
    return out;
  }

  void reject_unknown_keys(const YAML::Node& map, const std::vector<std::string>& known) const {
    for (const auto& kv : map) {
      const std::string key = kv.first.Scalar();
      bool ok = false;
      for (const std::string& k : known) ok = ok || k == key;
      if (!ok) fail(kv.first, "unknown key '" + key + "'");
    }
  }
};

// Parses text; syntax errors become FileFormatError with the line.
inline YAML::Node load_yaml_text(const std::string& text, const std::string& source) {
  try {
    return YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw FileFormatError(source + ":" + std::to_string(e.mark.line + 1) +
                          ": YAML syntax error: " + e.msg);
  }
}

std::string read_text_file(const std::filesystem::path& path);
void write_text_file_atomic(const std::filesystem::path& path, const std::string& text);

}  // namespace robocal::vision::detail
