#include "cli/cli_common.hpp"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>

namespace robocal::app {

void write_json(const nlohmann::json& doc, const std::string& path) {
  const std::string text = doc.dump(2) + "\n";
  if (path.empty() || path == "-") {
    std::cout << text << std::flush;
    return;
  }
  const std::filesystem::path target(path);
  std::filesystem::path tmp = target;
  tmp += ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw InputError("cannot write " + tmp.string());
    out << text;
    if (!out.flush()) throw InputError("write failed for " + tmp.string());
  }
  std::filesystem::rename(tmp, target);
}

}  // namespace robocal::app
