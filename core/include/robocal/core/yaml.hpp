#pragma once
// Reading YAML with errors that name the file and the line of the offending node
// ("robot.yaml:12: 'length' must be a number (got 'abc')"). Every loader of the project's YAML
// files (cameras, targets, sessions, robots, measurements) reads through this.
#include "robocal/core/input_error.hpp"

#include <yaml-cpp/yaml.h>

#include <string>
#include <vector>

namespace robocal::core {

// Parses text; a syntax error becomes InputError("<source>:<line>: not valid YAML (<why>)").
YAML::Node load_yaml_text(const std::string& text, const std::string& source);

// "<source>:<line>" of a node, or "<source>" when the node has no position.
std::string yaml_where(const std::string& source, const YAML::Node& node);

struct YamlContext {
  std::string source;  // file name used in messages

  [[noreturn]] void fail(const YAML::Node& node, const std::string& what) const {
    throw InputError(yaml_where(source, node) + ": " + what);
  }
  [[noreturn]] void fail(const std::string& what) const { throw InputError(source + ": " + what); }

  YAML::Node require(const YAML::Node& map, const std::string& key) const {
    const YAML::Node n = map[key];
    if (!n) fail(map, "missing required key '" + key + "'");
    return n;
  }
  // A mapping under `key` ("'key' must be a mapping" at the node, or at `map` when missing).
  YAML::Node require_map(const YAML::Node& map, const std::string& key) const {
    const YAML::Node n = map[key];
    if (!n || !n.IsMap()) fail(n ? n : map, "'" + key + "' must be a mapping");
    return n;
  }

  double to_double(const YAML::Node& n, const std::string& key) const;
  int to_int(const YAML::Node& n, const std::string& key) const;
  std::string to_string(const YAML::Node& n, const std::string& key) const;
  std::vector<double> to_doubles(const YAML::Node& n, const std::string& key) const;
  // A key of `map` not in `known` fails at its line, naming it and the allowed keys: a
  // misspelled optional key would otherwise be ignored in silence.
  void reject_unknown_keys(const YAML::Node& map, const std::vector<std::string>& known) const;

  // A required value of `map`, converted to T ("missing required key", "has a value of the
  // wrong type").
  template <typename T>
  T required(const YAML::Node& map, const std::string& key) const {
    return convert<T>(require(map, key), key);
  }
  template <typename T>
  T optional(const YAML::Node& map, const std::string& key, const T& fallback) const {
    const YAML::Node n = map[key];
    return n ? convert<T>(n, key) : fallback;
  }

 private:
  template <typename T>
  T convert(const YAML::Node& n, const std::string& key) const {
    try {
      return n.as<T>();
    } catch (const YAML::Exception&) {
      fail(n, "'" + key + "' has a value of the wrong type");
    }
  }
};

}  // namespace robocal::core
