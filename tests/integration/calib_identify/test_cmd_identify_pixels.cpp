// `robocal identify` on pixel observations (camera-in-the-loop), driven in-process: simulate a
// measurements file with two cameras, identify robot and camera 1's pose, validate on held-out
// pixels; a pixel naming an unknown camera is refused with file and line.
#include "cli/command_registry.hpp"
#include "robocal/calib/robot_file.hpp"
#include "run_robocal.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>

namespace {

using robocal::test::read_text;
using robocal::test::run_robocal;

struct IdentifyPixelsCli : robocal::test::ScratchDirTest {
  IdentifyPixelsCli() : ScratchDirTest("robocal_identify_pixels_") {}
  std::string robot = std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml";
};

TEST_F(IdentifyPixelsCli, SimulatedPixelsCalibrateRobotAndCamera) {
  ASSERT_EQ(run_robocal({"identify", "--robot", robot, "--simulate", file("m.yaml"), "--kind",
                         "pixel", "--poses", "40", "--json", file("sim.json")}),
            0);
  const auto sim = nlohmann::json::parse(read_text(file("sim.json")));
  ASSERT_GE(sim["poses"].get<int>(), 30);
  ASSERT_EQ(run_robocal({"identify", "--robot", robot, "--measurements", file("m.yaml"), "--json",
                         file("r.json"), "--out-robot", file("cal.yaml"), "--holdout-every", "4"}),
            0);
  const auto doc = nlohmann::json::parse(read_text(file("r.json")));
  EXPECT_EQ(doc["status"], "converged");
  // Held-out reprojection: from many pixels off to the noise level (0.1 px per axis).
  const double before = doc["heldout_pixels"]["before"]["rms_px"];
  const double after = doc["heldout_pixels"]["after"]["rms_px"];
  EXPECT_GT(before, 5.0);
  EXPECT_LT(after, 0.25);
  // Camera 1 found (it was stated ~4 mm off); camera 0 is the gauge.
  ASSERT_EQ(doc["cameras"].size(), 2u);
  EXPECT_TRUE(doc["cameras"][0]["gauge"].get<bool>());
  double error = 0;
  for (int i = 0; i < 3; ++i)
    error += std::pow(doc["cameras"][1]["position_m"][i].get<double>() -
                          sim["cameras"][1]["true_position"][i].get<double>(),
                      2);
  EXPECT_LT(std::sqrt(error), 0.5e-3);
  // The calibrated robot file holds the robot's parameters only and loads.
  const auto cal = robocal::calib::load_robot_file(file("cal.yaml"));
  int checked = 0;
  for (const auto& p : doc["parameters"]) {
    if (!p["estimated"].get<bool>()) continue;
    const int i = cal.parameter_index(p["name"]);
    if (p["name"].get<std::string>().rfind("camera", 0) == 0) {
      EXPECT_LT(i, 0);
      continue;
    }
    ASSERT_GE(i, 0) << p["name"];
    EXPECT_NEAR(cal.parameters[static_cast<std::size_t>(i)].value, p["value"].get<double>(), 1e-15);
    ++checked;
  }
  EXPECT_GT(checked, 5);
}

TEST_F(IdentifyPixelsCli, UnknownCameraIsRefusedWithFileAndLine) {
  ASSERT_EQ(run_robocal({"identify", "--robot", robot, "--simulate", file("m.yaml"), "--kind",
                         "pixel", "--poses", "12", "--json", file("sim.json")}),
            0);
  std::string text = read_text(file("m.yaml"));
  const auto pos = text.find("camera: camera1,");
  ASSERT_NE(pos, std::string::npos);
  text.replace(pos, 16, "camera: camera7,");
  std::ofstream(file("bad.yaml")) << text;
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_robocal({"identify", "--robot", robot, "--measurements", file("bad.yaml"), "--json",
                         file("r.json")}),
            3);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("bad.yaml:"), std::string::npos) << err;
  EXPECT_NE(err.find("unknown camera 'camera7'"), std::string::npos) << err;
}

}  // namespace
