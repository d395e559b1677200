#include "cli/command_registry.hpp"
#include "run_robocal.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
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

// A target whose paper no printer takes (cols/rows typed with an extra zero) is drawn, but the
// command says so; a normal board gets no warning.
TEST(TargetCommand, WarnsWhenTheDrawingCannotBePrinted) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "robocal_target_warn";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "huge.yaml") << "type: chessboard\ncols: 700\nrows: 500\nsquare_size: 0.02\n";
  testing::internal::CaptureStderr();
  testing::internal::CaptureStdout();
  EXPECT_EQ(run({"target", (dir / "huge.yaml").string(), "--svg", (dir / "huge.svg").string()}), 0);
  testing::internal::GetCapturedStdout();
  const std::string warned = testing::internal::GetCapturedStderr();
  EXPECT_NE(warned.find("larger than A0"), std::string::npos) << warned;
  EXPECT_NE(warned.find("huge.yaml"), std::string::npos) << warned;
  EXPECT_NE(warned.find("MB"), std::string::npos) << warned;  // the drawing's size is said too

  testing::internal::CaptureStderr();
  testing::internal::CaptureStdout();
  EXPECT_EQ(run({"target", std::string(ROBOCAL_TESTDATA_DIR) + "/vision/apriltag_4x3.yaml"}), 0);
  testing::internal::GetCapturedStdout();
  const std::string quiet = testing::internal::GetCapturedStderr();
  EXPECT_EQ(quiet.find("warning"), std::string::npos) << quiet;
}

}  // namespace
