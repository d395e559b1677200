// `robocal export` in-process: firmware settings from a robot file and from a session's
// calibrated robot, URDF to a file, and bad input (a session without identification results, a
// robot the format cannot describe, an unknown format): the reason, the exit code, nothing written.
#include "cli/command_registry.hpp"
#include "run_robocal.hpp"
#include "session/session.hpp"

#include "robocal/core/files.hpp"

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <cmath>
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

// A session folder as identify leaves it: the session's robot file, and the calibrated robot
// whose base frame is camera 0's and whose tool frame carries the end-effector board's mount.
fs::path calibrated_session(const std::string& name, const std::string& calibrated_text,
                            bool mounted) {
  const fs::path session = scratch(name);
  fs::create_directories(session / "results");
  robocal::app::Session s;
  s.source = "recorded";
  s.robot_name = "linear_delta";
  s.actuators = 3;
  s.measured_frame = "tool";
  s.cameras = {{"cam0", 640, 480}};
  if (mounted) s.target_mount = {{"tool.x", -0.145}, {"tool.y", -0.145}, {"tool.z", -0.01}};
  robocal::core::write_file_atomic(session / "session.yaml", robocal::app::session_to_yaml(s));
  robocal::core::write_file_atomic(session / "robot.yaml",
                                   robocal::core::read_text_file(robot("linear_delta.yaml")));
  robocal::core::write_file_atomic(session / "results" / "calibrated_robot.yaml", calibrated_text);
  return session;
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

TEST(ExportCli, ASessionExportsItsCalibratedRobot) {
  // A calibrated printer whose tower A rod came out 0.5 mm long: Klipper keeps a rod per tower
  // (exact), Marlin has one for all (a residual it prints).
  const std::string text = replaced(robocal::core::read_text_file(robot("linear_delta.yaml")),
                                    "{name: rod_a, a: carriage_a, b: eff_joint_a, length: 0.27}",
                                    "{name: rod_a, a: carriage_a, b: eff_joint_a, length: 0.2705}");
  const fs::path session = calibrated_session("session", text, false);
  const fs::path cfg = session / "printer.cfg";
  const CliRun klipper = run({"export", session.string(), "--format", "klipper", "--out",
                              cfg.string(), "--json", (session / "k.json").string()});
  ASSERT_EQ(klipper.code, 0) << klipper.err;
  const std::string written = robocal::core::read_text_file(cfg);
  EXPECT_NE(written.find("arm_length: 270.500000"), std::string::npos) << written;
  // It says what it keeps and who carries the rest.
  EXPECT_NE(written.find("what these settings keep"), std::string::npos) << written;
  EXPECT_NE(written.find("robocal compensate " + session.string()), std::string::npos) << written;
  const CliRun marlin = run({"export", session.string(), "--format", "marlin", "--json", "-"});
  ASSERT_EQ(marlin.code, 0) << marlin.err;
  const auto j = nlohmann::json::parse(marlin.out);
  EXPECT_GT(j.at("residual_rms_m").get<double>(), 10e-6);
  // The drawing's single rod against a calibrated 0.5 mm longer one is worse than the fit.
  EXPECT_GT(j.at("nominal_rms_m").get<double>(), j.at("residual_rms_m").get<double>());
  EXPECT_NE(j.at("text").get<std::string>().find("M665 L"), std::string::npos);
}

TEST(ExportCli, TheToolIsTheRobotsOwnAndTheBaseFrameTheRobotsNotTheCameras) {
  // As identification writes it: the base placed in camera 0's frame (1.25 m away, turned), the
  // tool frame's values replaced by the board's mount 145 mm off the nozzle.
  std::string text = robocal::core::read_text_file(robot("linear_delta.yaml"));
  text = replaced(text, "  - name: base\n    convention: xyz_rpy\n    joint: fixed\n",
                  "  - name: base\n    convention: xyz_rpy\n    joint: fixed\n    params: {x: "
                  "0.1, y: -0.2, z: 1.25, roll: 3.1, pitch: 0.02, yaw: 0.5}\n");
  text = replaced(
      text, "{name: tool, parent: effector, convention: xyz_rpy, joint: fixed, params: {z: 0}}",
      "{name: tool, parent: effector, convention: xyz_rpy, joint: fixed, params: {x: "
      "-0.145, y: -0.145, z: -0.01}}");
  const fs::path session = calibrated_session("frames", text, true);
  const CliRun r = run({"export", session.string(), "--format", "klipper", "--json", "-"});
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  // The firmware frame sits on the nozzle's towers, not 145 mm away at the board: the nominal
  // geometry in its own frames fits exactly, with the frame on the base.
  EXPECT_LT(j.at("residual_max_m").get<double>(), 1e-9);
  EXPECT_LT(std::abs(j.at("firmware_frame").at("x_m").get<double>()), 1e-9);
  EXPECT_LT(std::abs(j.at("firmware_frame").at("y_m").get<double>()), 1e-9);
  EXPECT_NEAR(j.at("settings").at("delta_radius").get<double>(), 140.0, 1e-6);
  EXPECT_EQ(j.at("frames").at("measured_frame").at("frame"), "board");
  const auto& board = j.at("frames").at("measured_frame").at("pose").at("translation_m");
  EXPECT_NEAR(board[0].get<double>(), -0.145, 1e-12);
  EXPECT_NEAR(board[2].get<double>(), -0.01, 1e-12);
  // The camera: the inverse of the base's placement in camera 0's frame.
  const auto& cam = j.at("frames").at("camera0").at("pose").at("translation_m");
  const Eigen::Isometry3d camera_T_base =
      Eigen::Translation3d(0.1, -0.2, 1.25) *
      (Eigen::AngleAxisd(3.1, Eigen::Vector3d::UnitX()) *
       Eigen::AngleAxisd(0.02, Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()));  // the file's rotation_order xyz
  const Eigen::Vector3d expected = camera_T_base.inverse().translation();
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(cam[k].get<double>(), expected[k], 1e-9) << k;
  EXPECT_NE(j.at("text").get<std::string>().find("nozzle: the robot file's tool frame 'tool'"),
            std::string::npos);
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
