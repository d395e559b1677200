#pragma once
// Small helpers shared by the sub-commands: error type for bad input, JSON output.
#include <nlohmann/json.hpp>

#include <stdexcept>
#include <string>

namespace robocal::app {

// Thrown by commands for problems with the user's input (missing file, malformed value). The
// message must say what is wrong and where; run_cli turns it into exit code 3.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Writes `doc` as indented JSON to `path`, or to stdout when path is "-" or empty. Files are
// written to a temporary name and renamed, so a reader never sees half a file.
void write_json(const nlohmann::json& doc, const std::string& path);

}  // namespace robocal::app
