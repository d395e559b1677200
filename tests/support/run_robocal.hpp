#pragma once
// Runs the `robocal` command line in-process (as main() does) for CLI-level tests.
#include "cli/command_registry.hpp"

#include <string>
#include <vector>

namespace robocal::test {

// run_robocal({"demo", "--quick"}) == `robocal demo --quick`; returns the exit code.
inline int run_robocal(std::vector<std::string> args) {
  args.insert(args.begin(), "robocal");
  std::vector<const char*> argv;
  argv.reserve(args.size());
  for (const auto& a : args) argv.push_back(a.c_str());
  return robocal::app::run_cli(static_cast<int>(argv.size()), argv.data());
}

}  // namespace robocal::test
