// Hand-eye calibration against simulated sets whose truth the test draws: a fixed camera with a
// board on the flange, and a camera on the flange with a fixed board. Corners are projected with
// the true transforms and Gaussian pixel noise; the estimate must lie within its own reported
// covariance of the truth, and bad data must be refused or named.
#include "robocal/vision/hand_eye.hpp"

#include "robocal/core/random_draws.hpp"
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/pose.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <cmath>
#include <random>

namespace rv = robocal::vision;

namespace {

using Iso = Eigen::Isometry3d;

// 99.73 % (3 sigma) quantile of chi-square with 6 degrees of freedom.
constexpr double kChi2Six3Sigma = 20.06;
// Corner noise of the demo's rendered images (px, per axis).
constexpr double kPixelSigma = 0.2;

Iso make_pose(const Eigen::Vector3d& rvec, const Eigen::Vector3d& t) {
  return rv::pose_from_rvec_tvec(rvec, t);
}

// A 6 x 8 grid of corners 30 mm apart, centred on the board origin.
rv::BoardPoints grid_board() {
  rv::BoardPoints board;
  int id = 0;
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 8; ++c)
      board[id++] = Eigen::Vector3d((c - 3.5) * 0.03, (r - 2.5) * 0.03, 0);
  return board;
}

rv::CameraModel test_camera() {
  return rv::make_camera(rv::CameraKind::kPinholeRadtan, 1600, 1200, 1400, 1395, 805, 598,
                         {-0.08, 0.05, 0.0005, -0.0003, 0.0});
}

// Turns `base` by a random rotation of up to `max_angle` about a random axis.
Eigen::Matrix3d random_turn(std::mt19937& rng, double max_angle) {
  std::normal_distribution<double> n(0.0, 1.0);
  std::uniform_real_distribution<double> u(0.3 * max_angle, max_angle);
  const Eigen::Vector3d axis = robocal::core::draw_vector3(n, rng).normalized();
  return Eigen::AngleAxisd(u(rng), axis).toRotationMatrix();
}

struct Scene {
  rv::HandEyeMount mount;
  Iso camera_pose;  // base_T_camera (fixed) or flange_T_camera (on tool)
  Iso target_pose;  // flange_T_target (fixed) or base_T_target (on tool)
  std::vector<rv::HandEyeView> views;
};

// The views' corners as the camera sees them, with noise; views where the board leaves the image
// or faces away are not kept.
void observe(const rv::CameraModel& camera, const rv::BoardPoints& board, std::mt19937& rng,
             Scene& s, const Iso& base_T_flange, double sigma) {
  const Iso M = s.mount == rv::HandEyeMount::kFixedCamera ? base_T_flange : base_T_flange.inverse();
  const Iso camera_T_target = s.camera_pose.inverse() * M * s.target_pose;
  if (camera_T_target.linear()(2, 2) < 0.3) return;  // the board turned away from the camera
  std::normal_distribution<double> noise(0.0, sigma);
  rv::HandEyeView v;
  v.name = "view" + std::to_string(s.views.size());
  v.base_T_flange = base_T_flange;
  for (const auto& [id, P] : board) {
    const auto px = rv::project(camera, camera_T_target * P);
    if (!px || px->x() < 0 || px->y() < 0 || px->x() > camera.width || px->y() > camera.height)
      return;
    v.frame.corners.push_back({id, *px + robocal::core::draw_vector2(noise, rng), 0.0});
  }
  s.views.push_back(v);
}

// A fixed camera 1.1 m from the flange's working area, a board 12 cm off the flange.
Scene fixed_camera_scene(unsigned seed, int views, double sigma = kPixelSigma) {
  std::mt19937 rng(seed);
  Scene s;
  s.mount = rv::HandEyeMount::kFixedCamera;
  // Camera above and in front of the robot, looking down at the working area around (0.5, 0, 0.3).
  s.camera_pose =
      rv::camera_T_board_look_at(Eigen::Vector3d(0.5, -0.9, 1.1), Eigen::Vector3d(0.5, 0.0, 0.3),
                                 Eigen::Vector3d(0, 0, 1))
          .inverse();
  s.target_pose = make_pose(Eigen::Vector3d(0.1, -0.2, 0.05), Eigen::Vector3d(0.02, -0.01, 0.12));
  // The flange's nominal orientation turns the board's face towards the camera.
  const Iso camera_T_target_nominal = make_pose(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, 0, 1));
  const Iso base_T_flange_nominal =
      s.camera_pose * camera_T_target_nominal * s.target_pose.inverse();
  std::uniform_real_distribution<double> shift(-0.15, 0.15);
  const rv::BoardPoints board = grid_board();
  const rv::CameraModel camera = test_camera();
  for (int tries = 0; static_cast<int>(s.views.size()) < views && tries < 1000; ++tries) {
    Iso pose = base_T_flange_nominal;
    pose.linear() = random_turn(rng, 0.5) * pose.linear();
    pose.translation() += robocal::core::draw_vector3(shift, rng);
    observe(camera, board, rng, s, pose, sigma);
  }
  return s;
}

// A camera 8 cm off the flange looking along its z, a board on the table in front of the robot.
Scene camera_on_tool_scene(unsigned seed, int views, double sigma = kPixelSigma) {
  std::mt19937 rng(seed);
  Scene s;
  s.mount = rv::HandEyeMount::kCameraOnTool;
  s.camera_pose = make_pose(Eigen::Vector3d(0.02, -0.03, 1.6), Eigen::Vector3d(0.08, 0.01, 0.05));
  s.target_pose = make_pose(Eigen::Vector3d(0.05, 0.03, 0.4), Eigen::Vector3d(0.6, 0.1, 0.0));
  const Iso camera_T_target_nominal =
      make_pose(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, 0, 0.6));
  // base_T_flange such that flange_T_base = camera_pose · camera_T_target · target_pose⁻¹.
  const Iso base_T_flange_nominal =
      (s.camera_pose * camera_T_target_nominal * s.target_pose.inverse()).inverse();
  std::uniform_real_distribution<double> shift(-0.12, 0.12);
  const rv::BoardPoints board = grid_board();
  const rv::CameraModel camera = test_camera();
  for (int tries = 0; static_cast<int>(s.views.size()) < views && tries < 1000; ++tries) {
    // Turn the camera about the board's centre so it stays in view.
    const Eigen::Matrix3d turn = random_turn(rng, 0.45);
    const Eigen::Vector3d centre = s.target_pose.translation();
    Iso pose = base_T_flange_nominal;
    pose.linear() = turn * pose.linear();
    pose.translation() =
        centre + turn * (pose.translation() - centre) + robocal::core::draw_vector3(shift, rng);
    observe(camera, board, rng, s, pose, sigma);
  }
  return s;
}

Eigen::Matrix<double, 6, 1> error_of(const Iso& estimate, const Iso& truth) {
  Eigen::Matrix<double, 6, 1> d;
  d.head<3>() = estimate.translation() - truth.translation();
  const Eigen::AngleAxisd turn(estimate.linear() * truth.linear().transpose());
  d.tail<3>() = turn.angle() * turn.axis();
  return d;
}

double mahalanobis(const Eigen::Matrix<double, 6, 1>& d, const Eigen::Matrix<double, 6, 6>& cov) {
  return d.dot(cov.ldlt().solve(d));
}

void expect_truth_within_covariance(const Scene& s, const rv::HandEyeResult& r) {
  ASSERT_EQ(r.status, rv::HandEyeStatus::kOk) << r.reason;
  const auto dc = error_of(r.camera_pose, s.camera_pose);
  const auto dt = error_of(r.target_pose, s.target_pose);
  EXPECT_LT(mahalanobis(dc, r.camera_pose_covariance), kChi2Six3Sigma)
      << "camera error " << dc.transpose();
  EXPECT_LT(mahalanobis(dt, r.target_pose_covariance), kChi2Six3Sigma)
      << "target error " << dt.transpose();
  EXPECT_LT(dc.head<3>().norm(), 0.2e-3);
  EXPECT_LT(dt.head<3>().norm(), 0.2e-3);
  // The residual estimates the simulated noise (per axis).
  EXPECT_NEAR(r.residual_sigma_px, kPixelSigma, 0.25 * kPixelSigma);
}

}  // namespace

TEST(HandEye, ClosedFormSolvesExactMotions) {
  std::mt19937 rng(4);
  const Iso X = make_pose(Eigen::Vector3d(0.3, -0.2, 0.9), Eigen::Vector3d(0.1, 0.05, -0.2));
  std::vector<Iso> A;
  std::vector<Iso> B;
  for (int k = 0; k < 6; ++k) {
    Iso a = Iso::Identity();
    a.linear() = random_turn(rng, 1.0);
    a.translation() = Eigen::Vector3d(0.1 * k, -0.05, 0.2);
    A.push_back(a);
    B.push_back(X.inverse() * a * X);  // A X = X B
  }
  const auto est = rv::solve_ax_xb(A, B);
  ASSERT_TRUE(est.has_value());
  EXPECT_LT(error_of(*est, X).norm(), 1e-9);
  // Turns about one axis only leave a rotation about it open.
  std::vector<Iso> A1;
  std::vector<Iso> B1;
  for (int k = 1; k < 5; ++k) {
    Iso a = Iso::Identity();
    a.linear() = Eigen::AngleAxisd(0.2 * k, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    A1.push_back(a);
    B1.push_back(X.inverse() * a * X);
  }
  EXPECT_FALSE(rv::solve_ax_xb(A1, B1).has_value());
}

// Seeds 1-3, both mountings: both transforms within 3 sigma (chi-square, 6 dof) of the truth
// under their reported covariance, and within 0.2 mm.
TEST(HandEye, FixedCameraRecoversBothTransformsWithinTheirCovariance) {
  for (unsigned seed = 1; seed <= 3; ++seed) {
    SCOPED_TRACE(seed);
    const Scene s = fixed_camera_scene(seed, 15);
    ASSERT_EQ(s.views.size(), 15u);
    rv::HandEyeOptions o;
    o.mount = s.mount;
    const auto r = rv::calibrate_hand_eye(test_camera(), grid_board(), s.views, o);
    expect_truth_within_covariance(s, r);
  }
}

TEST(HandEye, CameraOnToolRecoversBothTransformsWithinTheirCovariance) {
  for (unsigned seed = 1; seed <= 3; ++seed) {
    SCOPED_TRACE(seed);
    const Scene s = camera_on_tool_scene(seed, 15);
    ASSERT_EQ(s.views.size(), 15u);
    rv::HandEyeOptions o;
    o.mount = s.mount;
    const auto r = rv::calibrate_hand_eye(test_camera(), grid_board(), s.views, o);
    expect_truth_within_covariance(s, r);
  }
}

TEST(HandEye, IntrinsicsEstimatedTogether) {
  const Scene s = fixed_camera_scene(5, 20);
  rv::CameraModel start = test_camera();
  start.params[0] *= 1.02;  // 2 % off in focal length
  start.params[1] *= 1.02;
  start.params[2] += 6.0;
  rv::HandEyeOptions o;
  o.mount = s.mount;
  o.estimate_intrinsics = true;
  const auto r = rv::calibrate_hand_eye(start, grid_board(), s.views, o);
  ASSERT_EQ(r.status, rv::HandEyeStatus::kOk) << r.reason;
  ASSERT_EQ(r.intrinsics_stddev.size(), r.camera.params.size());
  for (int k = 0; k < 4; ++k)
    EXPECT_LT(std::abs(r.camera.params[k] - test_camera().params[k]), 4.0 * r.intrinsics_stddev[k])
        << "parameter " << k;
  EXPECT_LT(error_of(r.camera_pose, s.camera_pose).head<3>().norm(), 1e-3);
}

TEST(HandEye, MillimetresAreRefused) {
  Scene s = fixed_camera_scene(1, 10);
  for (auto& v : s.views) v.base_T_flange.translation() *= 1000.0;
  const auto r = rv::calibrate_hand_eye(test_camera(), grid_board(), s.views, {});
  EXPECT_EQ(r.status, rv::HandEyeStatus::kRefused);
  EXPECT_NE(r.reason.find("millimetres"), std::string::npos) << r.reason;
}

TEST(HandEye, QuaternionsWrittenWFirstAreNamed) {
  Scene s = fixed_camera_scene(2, 10);
  for (auto& v : s.views) {
    // The file holds (w, x, y, z) under the keys (qx, qy, qz, qw): read as x y z w.
    const Eigen::Quaterniond q(v.base_T_flange.linear());
    const Eigen::Quaterniond misread(q.z(), q.w(), q.x(), q.y());
    v.base_T_flange.linear() = misread.normalized().toRotationMatrix();
  }
  const auto r = rv::calibrate_hand_eye(test_camera(), grid_board(), s.views, {});
  EXPECT_EQ(r.status, rv::HandEyeStatus::kRefused);
  EXPECT_NE(r.reason.find("w x y z"), std::string::npos) << r.reason;
}

TEST(HandEye, TheOtherMountingIsNamed) {
  const Scene s = camera_on_tool_scene(3, 10);
  rv::HandEyeOptions o;
  o.mount = rv::HandEyeMount::kFixedCamera;
  const auto r = rv::calibrate_hand_eye(test_camera(), grid_board(), s.views, o);
  EXPECT_EQ(r.status, rv::HandEyeStatus::kRefused);
  EXPECT_NE(r.reason.find("camera_on_tool"), std::string::npos) << r.reason;
}

TEST(HandEye, UnseenAndForeignViewsAreNamedAndExcluded) {
  Scene s = fixed_camera_scene(6, 14);
  s.views[3].frame.corners.clear();  // the board was not seen
  // View 7 carries the flange pose of view 8 (a pose file of another image).
  s.views[7].base_T_flange = s.views[8].base_T_flange;
  rv::HandEyeOptions o;
  o.mount = s.mount;
  // The consistency check sees the foreign pose among 13 good ones as one outlying pair set;
  // the median is unaffected.
  const auto r = rv::calibrate_hand_eye(test_camera(), grid_board(), s.views, o);
  ASSERT_EQ(r.status, rv::HandEyeStatus::kOk) << r.reason;
  EXPECT_FALSE(r.views[3].used);
  EXPECT_NE(r.views[3].rejection.find("not seen"), std::string::npos);
  EXPECT_FALSE(r.views[7].used);
  EXPECT_NE(r.views[7].rejection.find("outlier"), std::string::npos) << r.views[7].rejection;
  int used = 0;
  for (const auto& v : r.views) used += v.used ? 1 : 0;
  EXPECT_EQ(used, 12);
  EXPECT_LT(error_of(r.camera_pose, s.camera_pose).head<3>().norm(), 0.2e-3);
}

TEST(HandEye, TooFewOrUnturnedViewsAreRefusedWithWhatToAdd) {
  const Scene s = fixed_camera_scene(7, 10);
  const std::vector<rv::HandEyeView> two(s.views.begin(), s.views.begin() + 2);
  const auto r = rv::calibrate_hand_eye(test_camera(), grid_board(), two, {});
  EXPECT_EQ(r.status, rv::HandEyeStatus::kRefused);
  EXPECT_NE(r.reason.find("only 2 views"), std::string::npos) << r.reason;

  // Views that only slide (no rotation): nothing separates the two unknowns.
  Scene slide = s;
  for (std::size_t i = 1; i < slide.views.size(); ++i) {
    slide.views[i] = s.views[0];
    slide.views[i].base_T_flange.translation() += Eigen::Vector3d(0.01 * i, 0.0, 0.0);
  }
  const auto r2 = rv::calibrate_hand_eye(test_camera(), grid_board(), slide.views, {});
  EXPECT_EQ(r2.status, rv::HandEyeStatus::kRefused);
  EXPECT_NE(r2.reason.find("turned about two different axes"), std::string::npos) << r2.reason;
}
