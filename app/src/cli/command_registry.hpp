#pragma once
// Every `robocal` sub-command is listed in exactly one place: command_registry.cpp.
#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

namespace robocal::app {

// Process exit codes, documented in `robocal --help` and the README.
enum ExitCode : int {
  kExitOk = 0,
  kExitFailure = 1,   // the command ran but its result is not acceptable (e.g. refused calibration)
  kExitUsage = 2,     // bad command line
  kExitBadInput = 3,  // an input file is missing or malformed
  kExitInternal = 4,  // a bug: please report it
  kExitInterrupted = 130,  // Ctrl-C (SIGINT); 143 for SIGTERM (128 + the signal)
};

// A sub-command adds itself to the parent app and stores the action to run when it is selected.
// The action returns an exit code.
using CommandAction = std::function<int()>;

struct CommandSpec {
  std::string name;
  std::string summary;
  // Adds options to `cmd` and returns the action that runs with the parsed values.
  std::function<CommandAction(CLI::App& cmd)> install;
};

// All sub-commands, in the order `robocal --help` lists them.
const std::vector<CommandSpec>& all_commands();

// Builds the full CLI, parses argv and runs the selected command. Returns the exit code.
int run_cli(int argc, const char* const* argv);

}  // namespace robocal::app
