#pragma once
// Small helpers shared by the sub-commands: the error type for bad input, JSON output.
#include "robocal/core/input_error.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace CLI {
class App;
}  // namespace CLI

namespace robocal::app {

// Problems with the user's input (missing file, malformed value): the project's one input-error
// type. The message must say what is wrong and where; run_cli turns it into exit code 3.
using core::InputError;

// A mistake on the command line that the parser's own checks cannot see: a value outside its
// choices or of the wrong form, options that conflict, an option that does not apply to the way
// the command was called. run_cli turns it into exit code 2 (a bad command line), whichever
// command throws it. The message names the option. Not an InputError: no file is at fault.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Refuses those of `options` that `cmd` was given (UsageError naming them): none of them has an
// effect on the command as called, `how` (e.g. "with a SESSION folder"). Ignoring an option in
// silence would hide a mistake: a user who gave it expects it to change the result.
void refuse_options(const CLI::App& cmd, const std::vector<std::string>& options,
                    const std::string& how);

// A folder or file the operating system refused (a symbolic link loop, no permission, a file
// where a folder should be, a full disk) in the operator's words: the path, the cause, and what
// to look at. The library's own text ("filesystem error: status: Too many levels of symbolic
// links [p]") names neither the likely mistake nor what to do.
std::string filesystem_problem(const std::filesystem::filesystem_error& e);
// The same for a check that reported `ec` on `path` (an std::error_code overload's failure).
std::string filesystem_problem(const std::filesystem::path& path, const std::error_code& ec);

// Writes `doc` as indented JSON to `path`, or to stdout when path is "-" or empty. Files are
// written to a temporary name and renamed, so a reader never sees half a file.
void write_json(const nlohmann::json& doc, const std::string& path);

}  // namespace robocal::app
