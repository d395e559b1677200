#include "wizard/wizard_state.hpp"

#include "cli/cli_common.hpp"
#include "robocal/core/files.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>

namespace robocal::app::wizard {

bool WizardState::is_done(const std::string& step) const {
  return std::find(done.begin(), done.end(), step) != done.end();
}

std::string WizardState::get(const std::string& key, const std::string& fallback) const {
  const auto it = values.find(key);
  return it == values.end() ? fallback : it->second;
}

void WizardState::save() const {
  YAML::Emitter e;
  e << YAML::BeginMap;
  e << YAML::Key << "format" << YAML::Value << "robocal-wizard-1";
  e << YAML::Key << "done" << YAML::Value << YAML::Flow << done;
  e << YAML::Key << "current" << YAML::Value << current;
  e << YAML::Key << "values" << YAML::Value << YAML::BeginMap;
  for (const auto& [k, v] : values) e << YAML::Key << k << YAML::Value << YAML::DoubleQuoted << v;
  e << YAML::EndMap << YAML::EndMap;
  core::write_file_atomic(file(), std::string(e.c_str()) + "\n");
}

WizardState load_state(const std::filesystem::path& folder) {
  WizardState s;
  s.folder = folder;
  const auto path = s.file();
  if (!std::filesystem::exists(path))
    throw InputError(path.string() +
                     ": missing; --resume takes a folder a `robocal wizard` run started");
  try {
    const YAML::Node root = YAML::LoadFile(path.string());
    if (root["format"].as<std::string>("") != "robocal-wizard-1")
      throw InputError(path.string() + ": not a wizard state file (format: robocal-wizard-1)");
    for (const auto& d : root["done"]) s.done.push_back(d.as<std::string>());
    s.current = root["current"].as<std::string>("");
    for (const auto& kv : root["values"])
      s.values[kv.first.as<std::string>()] = kv.second.as<std::string>();
  } catch (const YAML::Exception& e) {
    throw InputError(path.string() + ": " + e.what());
  }
  return s;
}

}  // namespace robocal::app::wizard
