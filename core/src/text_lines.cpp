#include "robocal/core/text_lines.hpp"

#include "robocal/core/files.hpp"

#include <sstream>

namespace robocal::core {

std::vector<ContentLine> content_lines(const std::string& text) {
  std::vector<ContentLine> lines;
  std::istringstream in(text);
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const std::size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    lines.push_back({number, line});
  }
  return lines;
}

std::vector<ContentLine> read_content_lines(const std::filesystem::path& path) {
  return content_lines(read_text_file(path));
}

}  // namespace robocal::core
