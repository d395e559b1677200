#include "cli/cli_common.hpp"

#include "robocal/core/files.hpp"

#include <iostream>

namespace robocal::app {

void write_json(const nlohmann::json& doc, const std::string& path) {
  const std::string text = doc.dump(2) + "\n";
  if (path.empty() || path == "-") {
    std::cout << text << std::flush;
    return;
  }
  core::write_file_atomic(path, text);
}

}  // namespace robocal::app
