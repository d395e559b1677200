// Pose measurement against exact synthetic projections with known truth: mono and stereo
// recovery, covariance consistency (NEES), planar-PnP ambiguity, settled-frame test, bad input.
#include "robocal/vision/pose_measurement.hpp"

#include "rig_test_scene.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>

namespace robocal::vision {
namespace {

using namespace testing;  // the shared stereo scene (rig_test_scene.hpp)

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

// Moves `count` corners of camera 0 by 5 px in varying directions; returns their ids.
std::vector<int> inject_outliers(std::vector<CameraFrame>& frame, int count) {
  std::vector<int> ids;
  auto& corners = frame[0].corners;
  for (int k = 0; k < count; ++k) {
    auto& c = corners[static_cast<size_t>(7 + 31 * k) % corners.size()];
    const double a = 1.3 + 2.1 * k;
    c.pixel += 5.0 * Eigen::Vector2d(std::cos(a), std::sin(a));
    ids.push_back(c.id);
  }
  return ids;
}

TEST(PoseMeasurement, GrossCornerOutliersAreRejectedAndThePoseKeepsItsAccuracy) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(23);
  double clean_sq[2] = {0, 0}, bad_sq[2] = {0, 0};  // stereo, mono
  for (int t = 0; t < 6; ++t) {
    const Eigen::Isometry3d truth = random_target_pose(rng);
    const auto frame = observe(rig, truth, board, 0.1, rng);
    auto bad = frame;
    std::vector<int> moved = inject_outliers(bad, 3);
    std::sort(moved.begin(), moved.end());
    for (int mono = 0; mono < 2; ++mono) {
      const std::vector<RigCamera> r = mono ? std::vector<RigCamera>{rig[0]} : rig;
      const auto f_clean = mono ? std::vector<CameraFrame>{frame[0]} : frame;
      const auto f_bad = mono ? std::vector<CameraFrame>{bad[0]} : bad;
      const auto clean = measure_target_pose(r, board, f_clean);
      const auto m = measure_target_pose(r, board, f_bad);
      ASSERT_EQ(clean.status, PoseStatus::kOk) << clean.message;
      ASSERT_EQ(m.status, PoseStatus::kOk) << m.message;
      EXPECT_EQ(clean.outliers, 0);
      ASSERT_EQ(m.outliers, 3) << m.message;
      EXPECT_EQ(m.cameras[0].outliers, 3);
      std::vector<int> flagged;
      for (const auto& rc : m.rejected) {
        EXPECT_EQ(rc.camera, 0);
        EXPECT_GT(rc.residual_px.norm(), 4.0);
        flagged.push_back(rc.id);
      }
      std::sort(flagged.begin(), flagged.end());
      EXPECT_EQ(flagged, moved);
      EXPECT_NE(m.message.find("outliers"), std::string::npos) << m.message;
      EXPECT_EQ(m.corners, clean.corners - 3);
      clean_sq[mono] += pose_error(clean.world_T_target, truth).tail<3>().squaredNorm();
      bad_sq[mono] += pose_error(m.world_T_target, truth).tail<3>().squaredNorm();
    }
  }
  for (int mono = 0; mono < 2; ++mono)
    EXPECT_LE(std::sqrt(bad_sq[mono]), 1.2 * std::sqrt(clean_sq[mono])) << "mono " << mono;
}

TEST(PoseMeasurement, NoFalseOutlierRejectionsOnCleanCorners) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(29);
  int rejected = 0;
  for (int t = 0; t < 20; ++t) {
    // The given sigma is right (0.1) or optimistic by 2x (0.2 px noise): neither rejects.
    const double noise = t % 2 == 0 ? 0.1 : 0.2;
    const auto m =
        measure_target_pose(rig, board, observe(rig, random_target_pose(rng), board, noise, rng));
    ASSERT_EQ(m.status, PoseStatus::kOk) << m.message;
    rejected += m.outliers;
  }
  EXPECT_EQ(rejected, 0);
}

// Corner noise correlated within each tag (as the four corners of a refined AprilTag share
// its fitted edges): with the joint covariance given as CornerGroups the predicted covariance
// matches the actual error (NEES ~ 1); treating the corners as independent with the same
// per-corner sigma does not.
TEST(PoseMeasurement, CorrelatedCornerGroupsGiveAConsistentCovariance) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(31);
  std::normal_distribution<double> gauss(0.0, 1.0);
  // A fixed 8x8 covariance with strong positive correlation between corners.
  Eigen::Matrix<double, 8, 8> a = Eigen::Matrix<double, 8, 8>::Identity();
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 8; ++j) a(i, j) += (i % 2 == j % 2) ? 0.8 : 0.0;
  const Eigen::Matrix<double, 8, 8> cov = 0.05 * 0.05 * a * a.transpose() / 4.0;
  const Eigen::Matrix<double, 8, 8> l = cov.llt().matrixL();
  const double iid_sigma = std::sqrt(cov.diagonal().mean());
  double nees_grouped = 0.0, nees_iid = 0.0;
  const int poses = 30;
  for (int t = 0; t < poses; ++t) {
    const Eigen::Isometry3d truth = random_target_pose(rng);
    auto frame = observe(rig, truth, board, 0.0, rng);
    for (auto& f : frame) {
      std::map<int, size_t> index;
      for (size_t i = 0; i < f.corners.size(); ++i) index[f.corners[i].id] = i;
      for (int tag = 0; tag < 36; ++tag) {
        CornerGroup g;
        Eigen::Matrix<double, 8, 1> z;
        for (int k = 0; k < 8; ++k) z(k) = gauss(rng);
        const Eigen::Matrix<double, 8, 1> e = l * z;
        for (int k = 0; k < 4; ++k) {
          const auto it = index.find(tag * 4 + k);
          ASSERT_NE(it, index.end());
          f.corners[it->second].pixel += e.segment<2>(2 * k);
          g.corner_ids.push_back(tag * 4 + k);
        }
        g.covariance = cov;
        f.corner_groups.push_back(g);
      }
    }
    PoseMeasurementOptions opt;
    opt.default_sigma_px = iid_sigma;
    const auto grouped = measure_target_pose(rig, board, frame, opt);
    for (auto& f : frame) f.corner_groups.clear();
    const auto iid = measure_target_pose(rig, board, frame, opt);
    ASSERT_EQ(grouped.status, PoseStatus::kOk) << grouped.message;
    ASSERT_EQ(iid.status, PoseStatus::kOk) << iid.message;
    EXPECT_EQ(grouped.outliers, 0);
    const auto e1 = pose_error(grouped.world_T_target, truth);
    const auto e2 = pose_error(iid.world_T_target, truth);
    nees_grouped += e1.dot(grouped.covariance.ldlt().solve(e1)) / 6.0 / poses;
    nees_iid += e2.dot(iid.covariance.ldlt().solve(e2)) / 6.0 / poses;
  }
  EXPECT_GT(nees_grouped, 0.7);
  EXPECT_LT(nees_grouped, 1.4);
  EXPECT_GT(nees_iid, 2.0);  // independent-corner covariance far too small
}

TEST(PoseMeasurement, DiagonalCornerGroupsEqualIndependentCorners) {
  const auto rig = stereo_rig();
  const auto board = bench_board();
  std::mt19937_64 rng(37);
  const Eigen::Isometry3d truth = random_target_pose(rng);
  auto frame = observe(rig, truth, board, 0.1, rng);
  const auto plain = measure_target_pose(rig, board, frame);
  for (auto& f : frame) {
    CornerGroup g;
    for (size_t i = 0; i < 8 && i < f.corners.size(); ++i) g.corner_ids.push_back(f.corners[i].id);
    g.covariance = Eigen::MatrixXd::Identity(16, 16) * 0.01;  // = the default sigma 0.1
    f.corner_groups.push_back(g);
  }
  const auto grouped = measure_target_pose(rig, board, frame);
  ASSERT_EQ(grouped.status, PoseStatus::kOk);
  EXPECT_LT(pose_error(grouped.world_T_target, plain.world_T_target).norm(), 1e-10);
  EXPECT_LT((grouped.covariance - plain.covariance).norm(), 1e-9 * plain.covariance.norm());
  EXPECT_NEAR(grouped.chi2, plain.chi2, 1e-8 * plain.chi2);
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
