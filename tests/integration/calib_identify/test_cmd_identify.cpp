// `robocal identify` driven in-process as a user would: simulate a measurements file, identify,
// read the calibrated robot file back; bad measurement files give exit code 3 with the reason.
#include "cli/command_registry.hpp"
#include "robocal/calib/robot_file.hpp"
#include "run_robocal.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

namespace {

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto pos = text.find(from);
  if (pos != std::string::npos) text.replace(pos, from.size(), to);
  return text;
}

using robocal::test::read_text;
using robocal::test::run_robocal;

struct IdentifyCli : robocal::test::ScratchDirTest {
  IdentifyCli() : ScratchDirTest("robocal_identify_cli_") {}
  std::string robot = std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml";
};

TEST_F(IdentifyCli, SimulateIdentifyAndWriteCalibratedRobot) {
  ASSERT_EQ(run_robocal({"identify", "--robot", robot, "--simulate", file("m.yaml"), "--poses",
                         "40", "--json", file("sim.json")}),
            0);
  ASSERT_EQ(run_robocal({"identify", "--robot", robot, "--measurements", file("m.yaml"), "--json",
                         file("r.json"), "--out-robot", file("cal.yaml"), "--holdout-every", "4"}),
            0);
  const auto doc = nlohmann::json::parse(read_text(file("r.json")));
  EXPECT_EQ(doc["status"], "converged");
  const double before = doc["heldout_validation"]["before"]["position_rms_m"];
  const double after = doc["heldout_validation"]["after"]["position_rms_m"];
  EXPECT_LT(after, before / 10.0);
  // The calibrated file loads and carries the estimated values.
  const auto cal = robocal::calib::load_robot_file(file("cal.yaml"));
  for (const auto& p : doc["parameters"]) {
    if (!p["estimated"].get<bool>()) continue;
    const int i = cal.parameter_index(p["name"]);
    ASSERT_GE(i, 0);
    EXPECT_NEAR(cal.parameters[static_cast<std::size_t>(i)].value, p["value"].get<double>(), 1e-15);
  }
  EXPECT_NE(read_text(file("cal.yaml")).find("# Calibrated by robocal"), std::string::npos);
}

TEST_F(IdentifyCli, BadMeasurementFilesAreRefusedWithTheReason) {
  ASSERT_EQ(run_robocal({"identify", "--robot", robot, "--simulate", file("m.yaml"), "--poses",
                         "30", "--json", file("sim.json")}),
            0);
  const std::string good = read_text(file("m.yaml"));
  // Duplicate pose id.
  std::ofstream(file("dup.yaml")) << replaced(good, "id: p0003", "id: p0002");
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_robocal({"identify", "--robot", robot, "--measurements", file("dup.yaml"), "--json",
                         file("r.json")}),
            3);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("p0002"), std::string::npos) << err;
  EXPECT_NE(err.find("more than once"), std::string::npos) << err;
  // Metre values declared as millimetres: off by 1000.
  std::ofstream(file("mm.yaml")) << replaced(good, "units:\n  length: m", "units:\n  length: mm");
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_robocal({"identify", "--robot", robot, "--measurements", file("mm.yaml"), "--json",
                         file("r.json")}),
            3);
  const std::string err2 = testing::internal::GetCapturedStderr();
  EXPECT_NE(err2.find("1000"), std::string::npos) << err2;
  // Missing file.
  EXPECT_EQ(run_robocal({"identify", "--robot", robot, "--measurements", file("none.yaml")}), 3);
}

}  // namespace

namespace {

// Options out of range are usage errors (exit 2) that name the option, before anything runs:
// no runaway sampling, no NaN from a zero scale, no file written.
TEST(CommandLineRanges, OutOfRangeOptionsAreUsageErrors) {
  const std::string robot = std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml";
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"identify", "--robot", robot, "--simulate", "never.yaml", "--poses", "-1"}, "--poses"},
      {{"identify", "--robot", robot, "--measurements", "m.yaml", "--robust-scale", "0"},
       "--robust-scale"},
      {{"identify", "--robot", robot, "--measurements", "m.yaml", "--kfold", "-3"}, "--kfold"},
      {{"identify", "--robot", robot, "--simulate", "never.yaml", "--point-sigma", "-1e-5"},
       "--point-sigma"},
      {{"rig", "--sigma-px", "0"}, "--sigma-px"},
      {{"measure", "--sigma-px", "-1"}, "--sigma-px"},
      {{"intrinsics", "--threads", "0"}, "--threads"},
  };
  for (const auto& [args, option] : cases) {
    testing::internal::CaptureStderr();
    EXPECT_EQ(robocal::test::run_robocal(args), 2) << args[0] << " " << option;
    const std::string err = testing::internal::GetCapturedStderr();
    EXPECT_NE(err.find(option), std::string::npos) << err;
  }
  EXPECT_FALSE(std::filesystem::exists("never.yaml"));
}

}  // namespace
