#include "cli/cli_common.hpp"

#include "robocal/core/files.hpp"

#include <fmt/format.h>
#include <CLI/CLI.hpp>

#include <cerrno>
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

std::string filesystem_problem(const std::filesystem::filesystem_error& e) {
  std::string where = e.path1().string();
  if (!e.path2().empty()) where += " -> " + e.path2().string();
  return filesystem_problem(where, e.code());
}

std::string filesystem_problem(const std::filesystem::path& path, const std::error_code& ec) {
  const std::string where = path.string();
  std::string hint;
  switch (ec.value()) {
    case ELOOP:
      hint =
          "a symbolic link loop: a link that leads, through others, back to itself or to a folder "
          "that holds it; remove or fix the link";
      break;
    case EACCES:
    case EPERM:
      hint =
          "permission denied: this user may not read (or write) it; check its permissions "
          "with `ls -ld` and its owner";
      break;
    case ENOTDIR:
      hint = "a file stands where a folder is expected";
      break;
    case ENOSPC:
      hint = "the disk is full";
      break;
    default:
      hint = ec.message();
  }
  return fmt::format("{}: {}", where.empty() ? std::string("(no path)") : where, hint);
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
