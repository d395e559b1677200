// Monte-Carlo checks of the pose measurement's covariance (heavier: label e2e).
#include "robocal/vision/pose_measurement.hpp"

#include "rig_test_scene.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace robocal::vision {
namespace {

using namespace testing;  // the shared stereo scene (rig_test_scene.hpp)

// Monte-Carlo: the predicted covariance must match the actual error spread. The normalised error
// squared e^T C^-1 e is chi-square with 6 dof (mean 6) when the covariance is right.
TEST(PoseMeasurementMC, CovarianceIsConsistentWithTheErrorSpread) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(7);
  const int trials = 100;
  for (int cameras : {1, 2}) {
    const std::vector<RigCamera> used(rig.begin(), rig.begin() + cameras);
    double nees = 0.0;
    double pos_rms = 0.0;
    double predicted = 0.0;
    for (int t = 0; t < trials; ++t) {
      const Eigen::Isometry3d truth = random_target_pose(rng);
      const auto frame = observe(used, truth, board, 0.1, rng);
      const auto m = measure_target_pose(used, board, frame);
      ASSERT_EQ(m.status, PoseStatus::kOk) << m.message;
      const auto e = pose_error(m.world_T_target, truth);
      nees += e.dot(m.covariance.ldlt().solve(e));
      pos_rms += e.tail<3>().squaredNorm();
      predicted += m.covariance.bottomRightCorner<3, 3>().trace();
    }
    nees /= trials;
    pos_rms = std::sqrt(pos_rms / trials);
    predicted = std::sqrt(predicted / trials);
    // Mean of 100 chi2(6) draws: sd 0.35; the band is about +-3.5 sd.
    EXPECT_GT(nees, 4.8) << cameras << " camera(s)";
    EXPECT_LT(nees, 7.2) << cameras << " camera(s)";
    // The position error of the target origin (a board corner) matches its predicted spread.
    EXPECT_NEAR(pos_rms / predicted, 1.0, 0.25) << cameras << " camera(s)";
  }
}

TEST(PoseMeasurementMC, RigUncertaintyEntersTheCovariance) {
  auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(17);
  const Eigen::Isometry3d truth = random_target_pose(rng);
  // Monte-Carlo: perturb the right camera's extrinsics by its stated covariance; the measured
  // pose must then scatter as the total covariance says.
  Eigen::Matrix<double, 6, 6> ext = Eigen::Matrix<double, 6, 6>::Zero();
  ext.diagonal() << 4e-10, 4e-10, 4e-10, 1e-9, 1e-9, 1e-9;  // 20 urad, 32 um
  std::normal_distribution<double> n01(0.0, 1.0);
  double nees_total = 0.0, nees_noise_only = 0.0;
  const int trials = 60;
  for (int t = 0; t < trials; ++t) {
    const auto frame = observe(rig, truth, board, 0.1, rng);  // observed by the TRUE rig
    auto believed = rig;
    Eigen::Matrix<double, 6, 1> d;
    for (int i = 0; i < 6; ++i) d[i] = std::sqrt(ext(i, i)) * n01(rng);
    believed[1].camera_T_world.linear() =
        Eigen::AngleAxisd(d.head<3>().norm(), d.head<3>().normalized()).toRotationMatrix() *
        rig[1].camera_T_world.linear();
    believed[1].camera_T_world.translation() += d.tail<3>();
    believed[1].extrinsic_covariance = ext;
    const auto m = measure_target_pose(believed, board, frame);
    ASSERT_EQ(m.status, PoseStatus::kOk);
    const auto e = pose_error(m.world_T_target, truth);
    nees_total += e.dot(m.covariance.ldlt().solve(e));
    nees_noise_only += e.dot(m.covariance_corner_noise.ldlt().solve(e));
  }
  nees_total /= trials;
  nees_noise_only /= trials;
  EXPECT_GT(nees_total, 4.0);
  EXPECT_LT(nees_total, 8.0);
  EXPECT_GT(nees_noise_only, 12.0);  // ignoring the rig uncertainty would be overconfident
}

// No false rejection over many pairs of noisy frames of a still target (false-alarm rate 1e-4
// per pair), and a 100 um motion always caught.
TEST(PoseMeasurementMC, SettledFrameTestOverManyPoses) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(21);
  int false_rejections = 0, detected = 0;
  const int trials = 50;
  for (int t = 0; t < trials; ++t) {
    const Eigen::Isometry3d truth = random_target_pose(rng);
    const auto still = measure_settled_pose(
        rig, board, {observe(rig, truth, board, 0.1, rng), observe(rig, truth, board, 0.1, rng)});
    if (still.status == PoseStatus::kMoving) ++false_rejections;
    Eigen::Isometry3d moved = truth;
    moved.translation() += Eigen::Vector3d(0, 100e-6, 0);
    const auto moving = measure_settled_pose(
        rig, board, {observe(rig, truth, board, 0.1, rng), observe(rig, moved, board, 0.1, rng)});
    if (moving.status == PoseStatus::kMoving) ++detected;
  }
  EXPECT_EQ(false_rejections, 0);
  EXPECT_EQ(detected, trials);
}

// Corners that scatter 2.5x the sigma they report (the pose views' small tags, against a sigma
// from the calibration views): the settled-frame test weighs each frame by its own fit's
// residuals, so a still target is not called moving, and a motion of 2.5x the 100 um above is
// still always caught.
TEST(PoseMeasurementMC, SettledFrameTestWithCornersNoisierThanTheirSigma) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(23);
  auto noisy = [&](const Eigen::Isometry3d& pose) {
    std::vector<CameraFrame> frame;
    frame.reserve(rig.size());
    for (const RigCamera& cam : rig)
      frame.push_back(
          simulate_frame(cam.model, cam.camera_T_world * pose, board, 0.25, rng, 2.0, 0.1));
    return frame;
  };
  int false_rejections = 0, detected = 0;
  const int trials = 50;
  for (int t = 0; t < trials; ++t) {
    const Eigen::Isometry3d truth = random_target_pose(rng);
    const auto still = measure_settled_pose(rig, board, {noisy(truth), noisy(truth)});
    if (still.status == PoseStatus::kMoving) ++false_rejections;
    Eigen::Isometry3d moved = truth;
    moved.translation() += Eigen::Vector3d(0, 250e-6, 0);
    const auto moving = measure_settled_pose(rig, board, {noisy(truth), noisy(moved)});
    if (moving.status == PoseStatus::kMoving) ++detected;
  }
  EXPECT_EQ(false_rejections, 0);
  EXPECT_EQ(detected, trials);
}

}  // namespace
}  // namespace robocal::vision
