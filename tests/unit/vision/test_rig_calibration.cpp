// Rig calibration against exact synthetic projections with known truth: 1, 2 and 4 cameras,
// chained extrinsics, intrinsics refinement, covariance, OpenCV comparison and bad input.
#include "robocal/vision/rig_calibration.hpp"

#include "rig_test_scene.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace robocal::vision {
namespace {

using namespace testing;  // the shared stereo scene (rig_test_scene.hpp)

std::vector<std::vector<CameraFrame>> calibration_views(const std::vector<RigCamera>& rig,
                                                        const BoardPoints& board, int n,
                                                        double sigma, std::mt19937_64& rng) {
  std::vector<std::vector<CameraFrame>> views;
  for (int i = 0; i < n; ++i)
    views.push_back(observe(rig, random_target_pose(rng, 1.1, 40.0), board, sigma, rng));
  return views;
}

// The true relative pose of camera c with respect to camera 0.
Eigen::Isometry3d relative(const std::vector<RigCamera>& rig, size_t c) {
  return rig[c].camera_T_world * rig[0].camera_T_world.inverse();
}

TEST(RigCalibration, ExactStereoViewsRecoverTheExtrinsics) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(1);
  const auto views = calibration_views(rig, board, 12, 0.0, rng);
  const auto res = calibrate_rig(rig, board, views);
  ASSERT_TRUE(res.ok) << res.message;
  ASSERT_EQ(res.cameras.size(), 2u);
  EXPECT_TRUE(res.cameras[0].camera_T_rig.isApprox(Eigen::Isometry3d::Identity()));
  EXPECT_LT(pose_error(res.cameras[1].camera_T_rig, relative(rig, 1)).norm(), 1e-9);
  EXPECT_NEAR(res.cameras[1].baseline_m, 0.5, 1e-9);
  EXPECT_LT(res.rms_px, 1e-6);
  for (size_t v = 0; v < views.size(); ++v) {
    ASSERT_TRUE(res.rig_T_board[v].has_value());
    EXPECT_LT(res.view_rms_px[v][0], 1e-6);
  }
}

TEST(RigCalibration, NoisyStereoBaselineWithinItsSigmaAndAgreesWithOpenCv) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(2);
  const auto views = calibration_views(rig, board, 20, 0.1, rng);
  const auto res = calibrate_rig(rig, board, views);
  ASSERT_TRUE(res.ok) << res.message;
  const auto& right = res.cameras[1];
  EXPECT_GT(right.baseline_sigma_m, 0.0);
  EXPECT_LT(std::abs(right.baseline_m - 0.5), 4.0 * right.baseline_sigma_m);
  const auto e = pose_error(right.camera_T_rig, relative(rig, 1));
  EXPECT_LT(e.dot(right.extrinsic_covariance.ldlt().solve(e)), 30.0);  // chi2(6) p ~ 4e-5
  EXPECT_NEAR(res.variance_factor, 1.0, 0.1);
  EXPECT_NEAR(res.rms_px, 0.1, 0.01);
  // cv::stereoCalibrate on the same detections lands on the same baseline (its own solver,
  // float inputs): within 3 sigma of ours.
  const auto cv = opencv_stereo_calibrate(rig, board, views, 0, 1);
  ASSERT_TRUE(cv.ok) << cv.message;
  EXPECT_EQ(cv.views, 20);
  EXPECT_LT(std::abs(cv.baseline_m - right.baseline_m), 3.0 * right.baseline_sigma_m);
  EXPECT_LT(pose_error(cv.b_T_a, right.camera_T_rig).tail<3>().norm(), 1e-4);
}

TEST(RigCalibration, FourCamerasChainedThroughSharedViews) {
  // Four cameras in a row 1.5 m wide, each aimed at its own part of a row of board poses;
  // camera 3 never shares a view with the reference camera 0 and is reached through 1 and 2.
  std::vector<RigCamera> rig(4);
  const double xs[4] = {-0.75, -0.25, 0.25, 0.75};
  for (size_t i = 0; i < 4; ++i) {
    rig[i].name = "cam" + std::to_string(i);
    rig[i].model = testing::bench_camera();
    rig[i].camera_T_world =
        camera_T_board_look_at(Eigen::Vector3d(xs[i], 0, 0), Eigen::Vector3d(xs[i] * 0.6, 0, 1.1),
                               Eigen::Vector3d(0, -1, 0));
  }
  const auto board = bench_board();
  std::mt19937_64 rng(4);
  std::vector<std::vector<CameraFrame>> views;
  for (int i = 0; i < 40; ++i) {
    const double x = -0.45 + 0.9 * (i % 10) / 9.0;
    Eigen::Isometry3d pose = random_target_pose(rng, 1.1, 30.0);
    pose.translation().x() += x;
    auto frame = observe(rig, pose, board, 0.05, rng);
    // Enforce the chain: camera 3 never shares a view with the reference camera 0.
    if (!frame[0].corners.empty()) frame[3] = CameraFrame{};
    views.push_back(frame);
  }
  const auto res = calibrate_rig(rig, board, views);
  ASSERT_TRUE(res.ok) << res.message;
  for (size_t c = 1; c < 4; ++c) {
    const auto e = pose_error(res.cameras[c].camera_T_rig, relative(rig, c));
    EXPECT_LT(e.dot(res.cameras[c].extrinsic_covariance.ldlt().solve(e)), 30.0) << c;
    EXPECT_NEAR(res.cameras[c].baseline_m, std::abs(xs[c] - xs[0]),
                4.0 * res.cameras[c].baseline_sigma_m + 1e-9);
  }
}

TEST(RigCalibration, SingleCameraGivesBoardPosesOnly) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(5);
  const std::vector<RigCamera> mono = {rig[0]};
  std::vector<std::vector<CameraFrame>> views;
  std::vector<Eigen::Isometry3d> truth;
  for (int i = 0; i < 5; ++i) {
    truth.push_back(random_target_pose(rng));
    views.push_back(observe(mono, truth.back(), board, 0.0, rng));
  }
  const auto res = calibrate_rig(mono, board, views);
  ASSERT_TRUE(res.ok) << res.message;
  for (size_t v = 0; v < views.size(); ++v)
    EXPECT_LT(pose_error(*res.rig_T_board[v], rig[0].camera_T_world * truth[v]).norm(), 1e-9);
}

TEST(RigCalibration, RefinesIntrinsicsFromAPerturbedStart) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(6);
  const auto views = calibration_views(rig, board, 25, 0.05, rng);
  auto start = rig;
  start[1].model.params[0] *= 1.01;
  start[1].model.params[2] += 5.0;
  start[1].model.params[4] = 0.0;
  RigCalibrationOptions options;
  options.refine_intrinsics = true;
  const auto res = calibrate_rig(start, board, views, options);
  ASSERT_TRUE(res.ok) << res.message;
  const auto& cam = res.cameras[1];
  ASSERT_EQ(cam.intrinsic_sigma.size(), rig[1].model.params.size());
  for (size_t i = 0; i < 5; ++i)
    EXPECT_LT(std::abs(cam.model.params[i] - rig[1].model.params[i]), 5.0 * cam.intrinsic_sigma[i])
        << "parameter " << i;
  EXPECT_LT(std::abs(cam.baseline_m - 0.5), 4.0 * cam.baseline_sigma_m);
}

TEST(RigCalibration, CamerasSharingNoViewsAreNamed) {
  auto rig = stereo_rig();
  rig.push_back(rig[1]);
  rig[2].name = "far_right";
  const auto board = bench_board();
  std::mt19937_64 rng(7);
  auto views = calibration_views(rig, board, 6, 0.05, rng);
  // Camera 2 sees the board only in views where neither 0 nor 1 does.
  for (auto& v : views) v[2] = CameraFrame{};
  for (int i = 0; i < 3; ++i) {
    auto v = observe(rig, random_target_pose(rng), board, 0.05, rng);
    v[0] = CameraFrame{};
    v[1] = CameraFrame{};
    views.push_back(v);
  }
  const auto res = calibrate_rig(rig, board, views);
  EXPECT_FALSE(res.ok);
  EXPECT_NE(res.message.find("camera 2 'far_right'"), std::string::npos) << res.message;
  EXPECT_NE(res.message.find("shares no views"), std::string::npos) << res.message;
  EXPECT_NE(res.message.find("camera 0 'left'"), std::string::npos) << res.message;

  // A camera that never sees the board at all.
  for (auto& v : views) v[2] = CameraFrame{};
  const auto res2 = calibrate_rig(rig, board, views);
  EXPECT_FALSE(res2.ok);
  EXPECT_NE(res2.message.find("camera 2 'far_right' sees the board"), std::string::npos)
      << res2.message;
  // Frame count mismatch.
  views[0].pop_back();
  EXPECT_THROW(calibrate_rig(rig, board, views), std::invalid_argument);
}

TEST(RigCalibration, ViewsSeenByNoCameraAreSkipped) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(8);
  auto views = calibration_views(rig, board, 8, 0.05, rng);
  views[3] = {CameraFrame{}, CameraFrame{}};
  const auto res = calibrate_rig(rig, board, views);
  ASSERT_TRUE(res.ok) << res.message;
  EXPECT_FALSE(res.rig_T_board[3].has_value());
  EXPECT_TRUE(std::isnan(res.view_rms_px[3][0]));
  EXPECT_NE(res.message.find("1 views seen by no camera"), std::string::npos) << res.message;
}

TEST(RigCalibration, GrossCornerOutliersAreRejectedPerCameraAndView) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(41);
  const auto views = calibration_views(rig, board, 12, 0.1, rng);
  auto bad = views;
  // 3 corners moved by 5 px in view 2 (right camera) and 2 in view 5 (left camera).
  for (int k = 0; k < 3; ++k)
    bad[2][1].corners[static_cast<size_t>(10 + 17 * k)].pixel += Eigen::Vector2d(5.0, -2.0 + k);
  for (int k = 0; k < 2; ++k)
    bad[5][0].corners[static_cast<size_t>(3 + 40 * k)].pixel += Eigen::Vector2d(-3.0, 4.0);
  const auto clean = calibrate_rig(rig, board, views);
  const auto res = calibrate_rig(rig, board, bad);
  ASSERT_TRUE(clean.ok) << clean.message;
  ASSERT_TRUE(res.ok) << res.message;
  EXPECT_TRUE(clean.rejected.empty());
  ASSERT_EQ(res.rejected.size(), 5u) << res.message;
  EXPECT_EQ(res.view_outliers[2][1], 3);
  EXPECT_EQ(res.view_outliers[5][0], 2);
  EXPECT_EQ(res.cameras[0].outliers, 2);
  EXPECT_EQ(res.cameras[1].outliers, 3);
  for (const auto& rc : res.rejected) EXPECT_GT(rc.residual_px.norm(), 4.0);
  EXPECT_NE(res.message.find("outliers"), std::string::npos) << res.message;
  // The extrinsics keep their accuracy: error within 1.2x of the clean calibration's (plus a
  // tenth of its sigma, as both are random).
  const double clean_err = std::abs(clean.cameras[1].baseline_m - 0.5);
  const double bad_err = std::abs(res.cameras[1].baseline_m - 0.5);
  EXPECT_LE(bad_err, 1.2 * clean_err + 0.1 * clean.cameras[1].baseline_sigma_m);
  const double clean_rot =
      pose_error(clean.cameras[1].camera_T_rig, relative(rig, 1)).head<3>().norm();
  const double bad_rot = pose_error(res.cameras[1].camera_T_rig, relative(rig, 1)).head<3>().norm();
  EXPECT_LE(bad_rot, 1.2 * clean_rot + 1e-6);
}

}  // namespace
}  // namespace robocal::vision
