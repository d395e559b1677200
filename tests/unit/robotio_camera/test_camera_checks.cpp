// Live checks on rendered frames whose defects are known from the render settings.
#include "robocal/robotio/camera_checks.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/renderer.hpp"
#include "robocal/vision/target_io.hpp"

#include <gtest/gtest.h>

#include <string>

namespace robocal::robotio {
namespace {

struct Scene {
  vision::CameraModel camera =
      vision::load_camera_file(std::string(ROBOCAL_TESTDATA_DIR) + "/vision/camera_640x480.yaml");
  vision::TargetBoard board =
      vision::load_target_file(std::string(ROBOCAL_TESTDATA_DIR) + "/vision/apriltag_4x3.yaml");
  vision::CameraRays rays = vision::precompute_rays(camera);

  // The board `distance` m in front of the camera, shifted sideways by `shift_x` m.
  cv::Mat render(const vision::RenderOptions& options, double distance = 0.45,
                 double shift_x = 0.0) const {
    const Eigen::Vector3d centre(0.08, 0.06, 0.0);
    vision::RenderTarget target{
        board, vision::camera_T_board_look_at(centre + Eigen::Vector3d(-shift_x, 0.0, -distance),
                                              centre + Eigen::Vector3d(-shift_x, 0.0, 0.0),
                                              Eigen::Vector3d(0.0, -1.0, 0.0))};
    return vision::render(rays, {target}, options).image;
  }
};

vision::RenderOptions good_options() {
  vision::RenderOptions options;
  options.blur_sigma = 0.5;
  options.read_noise = 1.0;
  return options;
}

const LiveCheck& check(const LiveCheckReport& report, const std::string& name) {
  for (const LiveCheck& c : report.checks) {
    if (c.name == name) {
      return c;
    }
  }
  throw std::runtime_error("no check " + name);
}

TEST(LiveChecks, AGoodFramePassesEveryCheck) {
  const Scene scene;
  vision::AprilTagDetector detector;
  const LiveCheckReport report =
      check_live_frame(scene.render(good_options()), scene.board, detector);
  EXPECT_TRUE(report.ok());
  EXPECT_EQ(report.corners, 48);
  EXPECT_EQ(report.board_corners, 48);
  EXPECT_LT(report.edge_spread_px, 1.0);
  EXPECT_EQ(report.clipped_fraction, 0.0);
  double total = 0.0;
  for (double bin : report.histogram) {
    total += bin;
  }
  EXPECT_NEAR(total, 1.0, 1e-9);
  for (const LiveCheck& c : report.checks) {
    EXPECT_TRUE(c.advice.empty()) << c.name;
  }
}

TEST(LiveChecks, DefocusFailsSharpnessWithAdvice) {
  const Scene scene;
  vision::AprilTagDetector detector;
  vision::RenderOptions options = good_options();
  options.blur_sigma = 2.5;  // a defocused lens: edge spread ~2.5 px
  const LiveCheckReport report = check_live_frame(scene.render(options), scene.board, detector);
  const LiveCheck& sharpness = check(report, "sharpness");
  EXPECT_FALSE(sharpness.ok) << sharpness.summary;
  EXPECT_GT(sharpness.value, 1.5);
  EXPECT_NE(sharpness.advice.find("focus"), std::string::npos);
  EXPECT_TRUE(check(report, "target").ok);
}

TEST(LiveChecks, OverAndUnderExposureFailTheExposureCheck) {
  const Scene scene;
  vision::AprilTagDetector detector;
  vision::RenderOptions bright = good_options();
  bright.white_level = 320.0;  // the paper saturates the sensor
  bright.background_level = 120.0;
  const LiveCheckReport over = check_live_frame(scene.render(bright), scene.board, detector);
  EXPECT_FALSE(check(over, "exposure").ok);
  EXPECT_GT(over.clipped_fraction, 0.05);
  EXPECT_NE(check(over, "exposure").advice.find("Overexposed"), std::string::npos);

  vision::RenderOptions dark = good_options();
  dark.black_level = 3.0;
  dark.white_level = 40.0;
  dark.background_level = 10.0;
  const LiveCheckReport under = check_live_frame(scene.render(dark), scene.board, detector);
  EXPECT_FALSE(check(under, "exposure").ok);
  EXPECT_LT(under.bright_level, 0.35);
  EXPECT_NE(check(under, "exposure").advice.find("Underexposed"), std::string::npos);
}

TEST(LiveChecks, TargetOutOfViewOrPartlyOutside) {
  const Scene scene;
  vision::AprilTagDetector detector;
  const LiveCheckReport absent =
      check_live_frame(scene.render(good_options(), 0.45, 1.0), scene.board, detector);
  EXPECT_FALSE(check(absent, "target").ok);
  EXPECT_FALSE(check(absent, "target").advice.empty());
  EXPECT_EQ(absent.corners, 0);

  // Shifted so part of the board leaves the image: found, but corners missing.
  const LiveCheckReport partial =
      check_live_frame(scene.render(good_options(), 0.45, 0.21), scene.board, detector);
  EXPECT_TRUE(check(partial, "target").ok) << check(partial, "target").summary;
  EXPECT_FALSE(check(partial, "corners").ok) << check(partial, "corners").summary;
  EXPECT_LT(partial.corners, 48);
  EXPECT_GT(partial.corners, 0);
}

}  // namespace
}  // namespace robocal::robotio
