#pragma once
// The YAML loaders read through core's helpers (file:line errors, core/yaml.hpp) and core's files.
#include "robocal/core/files.hpp"
#include "robocal/core/yaml.hpp"
#include "robocal/vision/errors.hpp"

#include <filesystem>
#include <string>

namespace robocal::vision::detail {

using core::load_yaml_text;
using core::read_text_file;
using core::YamlContext;

inline void write_text_file_atomic(const std::filesystem::path& path, const std::string& text) {
  core::write_file_atomic(path, text);
}

}  // namespace robocal::vision::detail
