#pragma once
// Line-oriented input files (a simulator's fault script, a perturbation list): '#' starts a
// comment, blank lines are skipped, and each kept line carries its number so every error can say
// "file:line: what is wrong".
#include <filesystem>
#include <string>
#include <vector>

namespace robocal::core {

struct ContentLine {
  int number = 0;    // 1-based line number in the file
  std::string text;  // the line without its comment (not otherwise trimmed)
};

// The lines of `text` that hold something besides a comment and white space.
std::vector<ContentLine> content_lines(const std::string& text);

// The same for a file. Throws InputError("<path>: cannot open file (...)").
std::vector<ContentLine> read_content_lines(const std::filesystem::path& path);

}  // namespace robocal::core
