#pragma once
// Small helpers shared by the sub-commands: the error type for bad input, JSON output.
#include "robocal/core/input_error.hpp"

#include <nlohmann/json.hpp>

#include <string>

namespace robocal::app {

// Problems with the user's input (missing file, malformed value): the project's one input-error
// type. The message must say what is wrong and where; run_cli turns it into exit code 3.
using core::InputError;

// Writes `doc` as indented JSON to `path`, or to stdout when path is "-" or empty. Files are
// written to a temporary name and renamed, so a reader never sees half a file.
void write_json(const nlohmann::json& doc, const std::string& path);

}  // namespace robocal::app
