#pragma once
// Runs the `robocal` command line in-process (as main() does) for CLI-level tests.
#include "cli/command_registry.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace robocal::test {

// run_robocal({"demo", "--quick"}) == `robocal demo --quick`; returns the exit code.
inline int run_robocal(const std::vector<std::string>& args) {
  std::vector<const char*> argv;
  argv.reserve(args.size() + 1);
  argv.push_back("robocal");
  for (const auto& a : args) argv.push_back(a.c_str());
  return robocal::app::run_cli(static_cast<int>(argv.size()), argv.data());
}

// What a command printed, with its exit code.
struct CliRun {
  int code = 0;
  std::string out, err;
};

// run_robocal with stdout and stderr captured (gtest's capture: not nested in another capture).
inline CliRun run_robocal_captured(const std::vector<std::string>& args) {
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  const int code = run_robocal(args);
  return {code, testing::internal::GetCapturedStdout(), testing::internal::GetCapturedStderr()};
}

}  // namespace robocal::test
