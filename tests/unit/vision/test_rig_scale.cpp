// Scale check against a scale bar: a rig calibrated with a board printed at 99.5 % is caught,
// named and corrected; a correct rig passes.
#include "robocal/vision/rig_calibration.hpp"
#include "robocal/vision/scale_check.hpp"

#include "rig_test_scene.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace robocal::vision {
namespace {

using namespace testing;  // the shared stereo scene (rig_test_scene.hpp)

constexpr double kBarLength = 0.5;

// Two 30 mm tags (ids 100 and 101) whose centres are kBarLength apart, on one rigid bar.
BoardPoints scale_bar_points() {
  BoardPoints pts;
  for (const auto& [id, p] : apriltag_grid_points(1, 1, 0.03, 0.0, 100))
    pts[id] = p + Eigen::Vector3d(-0.015, -0.015, 0);
  for (const auto& [id, p] : apriltag_grid_points(1, 1, 0.03, 0.0, 101))
    pts[id] = p + Eigen::Vector3d(kBarLength - 0.015, -0.015, 0);
  return pts;
}

ScaleBar bar_spec() {
  ScaleBar bar;
  bar.name = "bar-500";
  bar.corners_a = {400, 401, 402, 403};
  bar.corners_b = {404, 405, 406, 407};
  bar.certified_length_m = kBarLength;
  bar.certified_sigma_m = 2e-6;
  return bar;
}

std::vector<std::vector<CameraFrame>> bar_frames(const std::vector<RigCamera>& rig, int n,
                                                 std::mt19937_64& rng) {
  const BoardPoints bar = scale_bar_points();
  std::vector<std::vector<CameraFrame>> frames;
  for (int i = 0; i < n; ++i) {
    Eigen::Isometry3d pose = random_target_pose(rng, 1.15, 30.0, 0.0);
    pose.translation() -= pose.linear() * Eigen::Vector3d(0.5 * kBarLength, 0, 0);
    frames.push_back(observe(rig, pose, bar, 0.1, rng));
  }
  return frames;
}

TEST(ScaleCheck, TrueRigPasses) {
  const auto rig = stereo_rig();
  std::mt19937_64 rng(1);
  const auto check = check_scale(rig, bar_spec(), bar_frames(rig, 10, rng));
  ASSERT_TRUE(check.ok) << check.message;
  EXPECT_FALSE(check.scale_error) << check.verdict;
  EXPECT_LT(std::abs(check.measured_length_m - kBarLength), 4.0 * check.measured_sigma_m);
  EXPECT_NE(check.verdict.find("scale ok"), std::string::npos);
  EXPECT_EQ(check.frames.size(), 10u);
}

TEST(ScaleCheck, BoardPrintedAt99_5PercentIsDetectedNamedAndCorrected) {
  const auto rig = stereo_rig();
  const BoardPoints nominal = bench_board();
  const BoardPoints printed = scaled_board(nominal, 0.995);  // what is really on the paper
  std::mt19937_64 rng(2);
  std::vector<std::vector<CameraFrame>> views;
  for (int i = 0; i < 20; ++i)
    views.push_back(observe(rig, random_target_pose(rng, 1.1, 40.0), printed, 0.1, rng));
  // Calibrated believing the nominal size: the residuals cannot show the error...
  const auto calib = calibrate_rig(rig, nominal, views);
  ASSERT_TRUE(calib.ok) << calib.message;
  EXPECT_NEAR(calib.rms_px, 0.1, 0.01);
  // ...but every length is 1/0.995 too long.
  EXPECT_NEAR(calib.cameras[1].baseline_m, 0.5 / 0.995, 4.0 * calib.cameras[1].baseline_sigma_m);

  ScaleCheckOptions options;
  options.calibration_board_name = "board 'cal-6x6-200mm'";
  const auto bar_obs = bar_frames(rig, 10, rng);  // the true rig sees the bar
  const auto check = check_scale(calib.rig(), bar_spec(), bar_obs, options);
  ASSERT_TRUE(check.ok) << check.message;
  EXPECT_TRUE(check.scale_error);
  EXPECT_NEAR(check.scale_factor, 0.995, 4.0 * check.scale_factor_sigma);
  EXPECT_LT(check.scale_factor_sigma, 2e-4);
  EXPECT_NE(check.verdict.find("cal-6x6-200mm"), std::string::npos) << check.verdict;
  EXPECT_NE(check.verdict.find("99.50 %"), std::string::npos) << check.verdict;
}

TEST(ScaleCheck, FramesWhereTheBarIsNotTriangulableAreReported) {
  const auto rig = stereo_rig();
  std::mt19937_64 rng(3);
  auto frames = bar_frames(rig, 3, rng);
  frames[1][1] = CameraFrame{};  // right camera missed the bar in frame 1
  const auto check = check_scale(rig, bar_spec(), frames);
  ASSERT_TRUE(check.ok);
  EXPECT_FALSE(check.frames[1].ok);
  EXPECT_NE(check.frames[1].message.find("fewer than 2 cameras"), std::string::npos);
  EXPECT_NE(check.message.find("1 of 3 frames"), std::string::npos) << check.message;
  // A single camera can never triangulate.
  const auto mono = check_scale({rig[0]}, bar_spec(), {{frames[0][0]}});
  EXPECT_FALSE(mono.ok);
  EXPECT_NE(mono.message.find("two cameras"), std::string::npos) << mono.message;
  ScaleBar bad = bar_spec();
  bad.certified_length_m = 0.0;
  EXPECT_THROW(check_scale(rig, bad, frames), std::invalid_argument);
}

}  // namespace
}  // namespace robocal::vision
