#include "cli/command_registry.hpp"
#include "run_robocal.hpp"

#include <gtest/gtest.h>

#include <set>
#include <string>
#include <vector>

namespace {

constexpr auto& run = robocal::test::run_robocal;

TEST(CommandRegistry, NamesAreUniqueAndDocumented) {
  std::set<std::string> seen;
  for (const auto& spec : robocal::app::all_commands()) {
    EXPECT_TRUE(seen.insert(spec.name).second) << "duplicate command " << spec.name;
    EXPECT_FALSE(spec.summary.empty()) << spec.name << " has no summary";
  }
  EXPECT_FALSE(seen.empty());
}

TEST(CommandRegistry, EveryCommandHasItsOwnHelp) {
  for (const auto& spec : robocal::app::all_commands()) {
    testing::internal::CaptureStdout();
    const int code = run({spec.name, "--help"});
    const std::string out = testing::internal::GetCapturedStdout();
    EXPECT_EQ(code, 0) << spec.name;
    EXPECT_NE(out.find(spec.name), std::string::npos) << spec.name << " help:\n" << out;
  }
}

TEST(CommandRegistry, UsageErrorsReturnExitCode2) {
  testing::internal::CaptureStderr();
  EXPECT_EQ(run({"no-such-command"}), robocal::app::kExitUsage);
  EXPECT_EQ(run({}), robocal::app::kExitUsage);
  EXPECT_EQ(run({"version", "--no-such-flag"}), robocal::app::kExitUsage);
  testing::internal::GetCapturedStderr();
}

TEST(CommandRegistry, VersionJsonIsMachineReadable) {
  testing::internal::CaptureStdout();
  EXPECT_EQ(run({"version", "--json"}), 0);
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_NE(out.find("\"robocal\""), std::string::npos) << out;
}

}  // namespace
