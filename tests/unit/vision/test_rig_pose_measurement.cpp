// Pose measurement against exact synthetic projections with known truth: mono and stereo
// recovery, covariance consistency (NEES), planar-PnP ambiguity, settled-frame test, bad input.
#include "robocal/vision/pose_measurement.hpp"

#include "rig_test_scene.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace robocal::vision {
namespace {

using testing::bench_board;
using testing::observe;
using testing::pose_error;
using testing::random_target_pose;
using testing::stereo_rig;

TEST(PoseMeasurement, ExactObservationsRecoverThePoseMonoAndStereo) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(1);
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::Isometry3d truth = random_target_pose(rng);
    const auto frame = observe(rig, truth, board, 0.0, rng);
    const auto stereo = measure_target_pose(rig, board, frame);
    ASSERT_EQ(stereo.status, PoseStatus::kOk) << stereo.message;
    EXPECT_LT(pose_error(stereo.world_T_target, truth).head<3>().norm(), 1e-9);
    EXPECT_LT(pose_error(stereo.world_T_target, truth).tail<3>().norm(), 1e-9);
    EXPECT_TRUE(stereo.usable()) << stereo.message;
    EXPECT_EQ(stereo.corners, static_cast<int>(frame[0].corners.size() + frame[1].corners.size()));
    for (int c = 0; c < 2; ++c) {
      const std::vector<RigCamera> mono_rig = {rig[static_cast<size_t>(c)]};
      const auto mono = measure_target_pose(mono_rig, board, {frame[static_cast<size_t>(c)]});
      ASSERT_EQ(mono.status, PoseStatus::kOk) << mono.message;
      EXPECT_LT(pose_error(mono.world_T_target, truth).norm(), 1e-8);
    }
  }
}

TEST(PoseMeasurement, StereoCovarianceIsSmallerThanMono) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(3);
  const Eigen::Isometry3d truth = random_target_pose(rng);
  const auto frame = observe(rig, truth, board, 0.1, rng);
  const auto stereo = measure_target_pose(rig, board, frame);
  const auto mono = measure_target_pose({rig[0]}, board, {frame[0]});
  ASSERT_EQ(stereo.status, PoseStatus::kOk);
  ASSERT_EQ(mono.status, PoseStatus::kOk);
  // Depth is the weak direction of a single camera; the second one pins it down.
  const double stereo_var = stereo.covariance.bottomRightCorner<3, 3>().trace();
  const double mono_var = mono.covariance.bottomRightCorner<3, 3>().trace();
  EXPECT_LT(stereo_var, 0.5 * mono_var);
}

// A 60 mm target (2 x 2 tags) 1.5 m away, tilted 11 deg: one camera cannot tell the two
// planar-PnP branches apart; the second camera can. A 100 mm target at the same place is
// unambiguous even for one camera (the flag is not always on).
struct AmbiguityCount {
  int mono_ambiguous = 0, stereo_ambiguous = 0, stereo_wrong = 0, mono_wrong_unflagged = 0;
};
AmbiguityCount count_ambiguous(double size, int trials) {
  const auto rig = stereo_rig();
  const BoardPoints board = apriltag_grid_points(2, 2, size / 2.3, 0.3 * size / 2.3);
  std::mt19937_64 rng(11);
  AmbiguityCount n;
  for (int t = 0; t < trials; ++t) {
    Eigen::Isometry3d truth = Eigen::Isometry3d::Identity();
    truth.linear() =
        Eigen::AngleAxisd(0.2, Eigen::Vector3d(1, 0.3, 0).normalized()).toRotationMatrix();
    truth.translation() =
        Eigen::Vector3d(0.0, 0.0, 1.5) - truth.linear() * Eigen::Vector3d(size / 2, size / 2, 0);
    const auto frame = observe(rig, truth, board, 0.2, rng);
    const auto mono = measure_target_pose({rig[0]}, board, {frame[0]});
    const auto stereo = measure_target_pose(rig, board, frame);
    EXPECT_EQ(mono.status, PoseStatus::kOk) << mono.message;
    EXPECT_EQ(stereo.status, PoseStatus::kOk) << stereo.message;
    n.mono_ambiguous += mono.ambiguous ? 1 : 0;
    n.stereo_ambiguous += stereo.ambiguous ? 1 : 0;
    if (mono.ambiguous) {
      EXPECT_NE(mono.message.find("ambiguous"), std::string::npos);
    }
    // The right branch: the error lies within the predicted covariance; the mirrored branch
    // would be tens of sigma off.
    const auto e = pose_error(stereo.world_T_target, truth);
    if (e.dot(stereo.covariance.ldlt().solve(e)) > 30.0) ++n.stereo_wrong;
    const auto em = pose_error(mono.world_T_target, truth);
    if (!mono.ambiguous && em.dot(mono.covariance.ldlt().solve(em)) > 30.0)
      ++n.mono_wrong_unflagged;
  }
  return n;
}

TEST(PoseMeasurement, SmallTargetIsAmbiguousInOneCameraAndResolvedByTwo) {
  const AmbiguityCount small = count_ambiguous(0.06, 20);
  EXPECT_EQ(small.mono_ambiguous, 20);
  EXPECT_EQ(small.stereo_ambiguous, 0);
  EXPECT_EQ(small.stereo_wrong, 0);
  const AmbiguityCount large = count_ambiguous(0.10, 20);
  EXPECT_EQ(large.mono_ambiguous, 0);
  EXPECT_EQ(large.mono_wrong_unflagged, 0);
  EXPECT_EQ(large.stereo_wrong, 0);
}

TEST(PoseMeasurement, FewCornersAndBlurAreFlagged) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(5);
  const Eigen::Isometry3d truth = random_target_pose(rng);
  auto frame = observe(rig, truth, board, 0.1, rng);
  frame[0].corners.resize(6);
  frame[1].corners.resize(4);
  const auto few = measure_target_pose(rig, board, frame);
  ASSERT_EQ(few.status, PoseStatus::kOk) << few.message;
  EXPECT_TRUE(few.few_corners);
  EXPECT_FALSE(few.usable());
  EXPECT_NE(few.message.find("few corners"), std::string::npos) << few.message;

  auto blurred = observe(rig, truth, board, 0.1, rng);
  blurred[1].blur_px = 3.0;
  blurred[0].blur_px = 0.8;
  const auto b = measure_target_pose(rig, board, blurred);
  ASSERT_EQ(b.status, PoseStatus::kOk);
  EXPECT_TRUE(b.blurred);
  EXPECT_FALSE(b.cameras[0].blurred);
  EXPECT_TRUE(b.cameras[1].blurred);
}

TEST(PoseMeasurement, MovingTargetIsRejectedAndAStillOneIsNot) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(9);
  int false_rejections = 0;
  int detected = 0;
  const int trials = 8;  // 50 more in test_vision_rig_mc
  for (int t = 0; t < trials; ++t) {
    const Eigen::Isometry3d truth = random_target_pose(rng);
    // Still: two independent noisy frames of the same pose.
    const auto still = measure_settled_pose(
        rig, board, {observe(rig, truth, board, 0.1, rng), observe(rig, truth, board, 0.1, rng)});
    ASSERT_NE(still.status, PoseStatus::kFailed) << still.message;
    if (still.moving || still.status == PoseStatus::kMoving) ++false_rejections;
    EXPECT_EQ(still.frames_used, 2);
    // Moving: 100 um along x between the frames (a settling robot), 0.2 px in the images, i.e.
    // two corner sigmas, but many times the sigma of the pose.
    Eigen::Isometry3d moved = truth;
    moved.translation() += Eigen::Vector3d(100e-6, 0, 0);
    const auto moving = measure_settled_pose(
        rig, board, {observe(rig, truth, board, 0.1, rng), observe(rig, moved, board, 0.1, rng)});
    if (moving.status == PoseStatus::kMoving) {
      ++detected;
      EXPECT_TRUE(moving.moving);
      EXPECT_FALSE(moving.usable());
      EXPECT_NE(moving.message.find("moved"), std::string::npos);
    }
  }
  EXPECT_EQ(false_rejections, 0);
  EXPECT_EQ(detected, trials);
}

TEST(PoseMeasurement, SettledFramesAveraging) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(13);
  const Eigen::Isometry3d truth = random_target_pose(rng);
  const auto one = measure_target_pose(rig, board, observe(rig, truth, board, 0.1, rng));
  const auto four = measure_settled_pose(
      rig, board,
      {observe(rig, truth, board, 0.1, rng), observe(rig, truth, board, 0.1, rng),
       observe(rig, truth, board, 0.1, rng), observe(rig, truth, board, 0.1, rng)});
  ASSERT_EQ(four.status, PoseStatus::kOk) << four.message;
  EXPECT_EQ(four.frames_used, 4);
  // Four frames: a quarter of the variance.
  EXPECT_NEAR(four.covariance.trace() / one.covariance.trace(), 0.25, 0.03);
}

TEST(PoseMeasurement, BadInputGivesAStatusNotACrash) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(19);
  const Eigen::Isometry3d truth = random_target_pose(rng);
  // Seen by no camera.
  const auto none = measure_target_pose(rig, board, {CameraFrame{}, CameraFrame{}});
  EXPECT_EQ(none.status, PoseStatus::kNotSeen);
  EXPECT_FALSE(none.message.empty());
  // Three corners in each camera: no camera can start IPPE.
  auto frame = observe(rig, truth, board, 0.1, rng);
  frame[0].corners.resize(3);
  frame[1].corners.resize(3);
  const auto few = measure_target_pose(rig, board, frame);
  EXPECT_EQ(few.status, PoseStatus::kTooFewCorners);
  // Unknown ids and NaN pixels are ignored.
  auto odd = observe(rig, truth, board, 0.1, rng);
  odd[0].corners.push_back({99999, Eigen::Vector2d(10, 10), 0.1});
  odd[1].corners.push_back({0, Eigen::Vector2d(NAN, 3), 0.1});
  const auto ok = measure_target_pose(rig, board, odd);
  EXPECT_EQ(ok.status, PoseStatus::kOk);
  EXPECT_LT(pose_error(ok.world_T_target, truth).tail<3>().norm(), 1e-4);
  // Frame count not matching the rig.
  EXPECT_THROW(measure_target_pose(rig, board, {CameraFrame{}}), std::invalid_argument);
}

TEST(Chi2, SurvivalMatchesKnownValues) {
  // Closed form for 6 dof: Q = exp(-x/2) (1 + x/2 + x^2/8).
  for (double x : {0.5, 3.0, 12.6, 22.46, 40.0}) {
    const double q = std::exp(-x / 2) * (1 + x / 2 + x * x / 8);
    EXPECT_NEAR(chi2_survival(x, 6), q, 1e-12 + 1e-10 * q);
  }
  EXPECT_NEAR(chi2_survival(3.841458820694124, 1), 0.05, 1e-9);
  EXPECT_NEAR(chi2_quantile_upper(1e-3, 6), 22.457744484825323, 1e-6);
}

}  // namespace
}  // namespace robocal::vision
