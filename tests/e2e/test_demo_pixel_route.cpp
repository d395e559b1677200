// End to end: `robocal demo --route both` identifies the simulated Delta from the same rendered
// detections twice, from measured 6-D poses and directly from the corner pixels
// (camera-in-the-loop, camera 1's pose estimated), and reports both against the hidden truth.
#include "cli/command_registry.hpp"
#include "run_robocal.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace {

using robocal::test::run_robocal;

TEST(DemoEndToEnd, PixelRouteCalibratesFromTheSameDetections) {
  const auto dir = std::filesystem::temp_directory_path() / "robocal_e2e_demo_pixels";
  std::filesystem::remove_all(dir);
  ASSERT_EQ(run_robocal({"demo", "--quick", "--poses", "24", "--held-out", "200", "--seed", "3",
                         "--route", "both", "--out", dir.string()}),
            0);
  std::ifstream in(dir / "results" / "demo.json");
  ASSERT_TRUE(in) << "no results/demo.json";
  const auto report = nlohmann::json::parse(in);
  const auto& pixel_route = report["identify"]["pixel_route"];
  EXPECT_EQ(pixel_route["result"]["status"], "converged");
  // Corner noise of rendered images: the fit reproduces the pixels to a fraction of a pixel.
  EXPECT_LT(pixel_route["reprojection_rms_px"].get<double>(), 1.25 * 0.0186);
  EXPECT_TRUE(std::filesystem::exists(dir / "results" / "calibrated_robot_pixels.yaml"));
  const double nominal = report["validate"]["nominal"]["rms_m"];
  const double pixels = report["validate"]["calibrated_pixels"]["rms_m"];
  EXPECT_LT(pixels, nominal / 5.0);
  // 1.25x the largest of seeds 1-3 in this configuration (`robocal demo --quick --poses 24
  // --held-out 200 --seed S`, the truth with unmodelled error): 50.2 / 34.7 / 57.6 µm;
  // reprojection 0.0184 / 0.0183 / 0.0186 px.
  EXPECT_LT(pixels, 1.25 * 57.6e-6) << "pixel-route calibrated error against truth";
  std::filesystem::remove_all(dir);
}

}  // namespace
