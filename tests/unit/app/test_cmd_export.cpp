// `robocal export` in-process: firmware settings from a robot file and from a session's
// calibrated robot, URDF to a file, and bad input (a session without identification results, a
// robot the format cannot describe, an unknown format): the reason, the exit code, nothing written.
#include "cli/command_registry.hpp"
#include "run_robocal.hpp"

#include "robocal/core/files.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace {
namespace fs = std::filesystem;

using robocal::test::CliRun;
constexpr auto& run = robocal::test::run_robocal_captured;

std::string robot(const std::string& file) {
  return std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + file;
}

fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("robocal_export_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

TEST(ExportCli, KlipperFromARobotFileAsJson) {
  const CliRun r =
      run({"export", robot("linear_delta.yaml"), "--format", "klipper", "--json", "-"});
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("robot"), "linear_delta");
  EXPECT_NEAR(j.at("settings").at("delta_radius").get<double>(), 140.0, 1e-6);
  EXPECT_NEAR(j.at("settings").at("arm_length_b").get<double>(), 270.0, 1e-6);
  EXPECT_LT(j.at("residual_max_m").get<double>(), 1e-9);
  EXPECT_NE(j.at("text").get<std::string>().find("[printer]\nkinematics: delta"),
            std::string::npos);
}

TEST(ExportCli, ASessionExportsItsCalibratedRobot) {
  const fs::path session = scratch("session");
  fs::create_directories(session / "results");
  // A calibrated printer whose tower A rod came out 0.5 mm long: Klipper keeps a rod per tower
  // (exact), Marlin has one for all (a residual it prints).
  std::string text = robocal::core::read_text_file(robot("linear_delta.yaml"));
  const std::string rod = "{name: rod_a, a: carriage_a, b: eff_joint_a, length: 0.27}";
  ASSERT_NE(text.find(rod), std::string::npos);
  text.replace(text.find(rod), rod.size(),
               "{name: rod_a, a: carriage_a, b: eff_joint_a, length: 0.2705}");
  robocal::core::write_file_atomic(session / "results" / "calibrated_robot.yaml", text);
  const fs::path cfg = session / "printer.cfg";
  const CliRun klipper = run({"export", session.string(), "--format", "klipper", "--out",
                              cfg.string(), "--json", (session / "k.json").string()});
  ASSERT_EQ(klipper.code, 0) << klipper.err;
  const std::string written = robocal::core::read_text_file(cfg);
  EXPECT_NE(written.find("arm_length: 270.500000"), std::string::npos) << written;
  const CliRun marlin = run({"export", session.string(), "--format", "marlin", "--json", "-"});
  ASSERT_EQ(marlin.code, 0) << marlin.err;
  const auto j = nlohmann::json::parse(marlin.out);
  EXPECT_GT(j.at("residual_rms_m").get<double>(), 10e-6);
  EXPECT_NE(j.at("text").get<std::string>().find("M665 L"), std::string::npos);
}

TEST(ExportCli, BadInputSaysWhyAndWritesNothing) {
  const fs::path dir = scratch("bad");
  const fs::path out = dir / "keep.cfg";
  robocal::core::write_file_atomic(out, "the user's file\n");
  const auto untouched = [&] { return robocal::core::read_text_file(out) == "the user's file\n"; };

  const fs::path session = dir / "session";  // recorded, never identified
  fs::create_directories(session / "poses");
  CliRun r = run({"export", session.string(), "--format", "klipper", "--out", out.string()});
  EXPECT_EQ(r.code, 3);
  EXPECT_NE(r.err.find("no identification results"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("robocal identify"), std::string::npos) << r.err;
  EXPECT_TRUE(untouched());

  r = run({"export", robot("rotary_delta.yaml"), "--format", "klipper", "--out", out.string()});
  EXPECT_EQ(r.code, 3);
  EXPECT_NE(r.err.find("rotary arms"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("three linear towers"), std::string::npos) << r.err;
  EXPECT_TRUE(untouched());

  r = run({"export", robot("gantry_tau.yaml"), "--format", "rrf", "--out", out.string()});
  EXPECT_EQ(r.code, 3);
  EXPECT_NE(r.err.find("not a vertical tower"), std::string::npos) << r.err;
  EXPECT_TRUE(untouched());

  r = run({"export", robot("linear_delta.yaml"), "--format", "urdf", "--out", out.string()});
  EXPECT_EQ(r.code, 3);
  EXPECT_NE(r.err.find("closed loops"), std::string::npos) << r.err;
  EXPECT_TRUE(untouched());

  r = run({"export", robot("ur5.yaml"), "--format", "step", "--out", out.string()});
  EXPECT_EQ(r.code, 2);
  EXPECT_TRUE(untouched());

  r = run({"export", (dir / "missing.yaml").string(), "--format", "urdf"});
  EXPECT_EQ(r.code, 3);
  EXPECT_NE(r.err.find("missing.yaml"), std::string::npos) << r.err;
}

TEST(ExportCli, UrdfToAFile) {
  const fs::path out = scratch("urdf") / "ur5.urdf";
  const CliRun r = run({"export", robot("ur5.yaml"), "--format", "urdf", "--out", out.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(robocal::core::read_text_file(out).find("<robot name=\"ur5\">"), std::string::npos);
}

}  // namespace
