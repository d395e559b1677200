#include "cli/cli_common.hpp"

#include "robocal/core/files.hpp"

#include <fmt/format.h>
#include <CLI/CLI.hpp>

#include <iostream>

namespace robocal::app {

void refuse_options(const CLI::App& cmd, const std::vector<std::string>& options,
                    const std::string& how) {
  std::vector<std::string> given;
  for (const std::string& option : options)
    if (cmd.count(option) > 0) given.push_back(option);
  if (given.empty()) return;
  throw UsageError(fmt::format("{} {} not apply {}", fmt::join(given, ", "),
                               given.size() == 1 ? "does" : "do", how));
}

void write_json(const nlohmann::json& doc, const std::string& path) {
  const std::string text = doc.dump(2) + "\n";
  if (path.empty() || path == "-") {
    std::cout << text << std::flush;
    return;
  }
  core::write_file_atomic(path, text);
}

}  // namespace robocal::app
