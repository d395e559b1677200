// Pose helpers and the models inside a real Ceres cost function.
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/pose.hpp"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <gtest/gtest.h>

namespace rv = robocal::vision;

TEST(Pose, RvecRoundTripAndOpenCVMeaning) {
  const Eigen::Vector3d rvec(0.3, -1.1, 2.0), t(0.1, 0.2, 0.3);
  const Eigen::Isometry3d pose = rv::pose_from_rvec_tvec(rvec, t);
  EXPECT_LT((rv::rvec_of(pose) - rvec).norm(), 1e-14);
  // Same rotation as Ceres' (and OpenCV's) angle-axis convention.
  const double p[3] = {0.4, -0.2, 1.0};
  double q[3];
  ceres::AngleAxisRotatePoint(rvec.data(), p, q);
  const Eigen::Vector3d mine = pose * Eigen::Vector3d(p[0], p[1], p[2]);
  EXPECT_LT((mine - Eigen::Vector3d(q[0], q[1], q[2]) - t).norm(), 1e-14);
  EXPECT_NEAR(rv::rotation_angle_between(pose, rv::pose_from_rvec_tvec(Eigen::Vector3d::Zero(), t)),
              rvec.norm(), 1e-12);
  EXPECT_NEAR(rv::translation_between(pose, pose), 0.0, 1e-15);
}

TEST(Pose, LookAtCentresTheTargetWithUpUp) {
  const auto cam =
      rv::make_camera(rv::CameraKind::kPinholeRadtan, 640, 480, 500, 500, 319.5, 239.5);
  const Eigen::Vector3d eye(0.1, 0.05, -0.6), target(0.12, 0.08, 0.0);
  const Eigen::Vector3d up(0, -1, 0);  // the board's -y (top of the print)
  const Eigen::Isometry3d camera_T_board = rv::camera_T_board_look_at(eye, target, up);
  const auto c = rv::project(cam, camera_T_board * target);
  ASSERT_TRUE(c.has_value());
  EXPECT_LT((*c - Eigen::Vector2d(319.5, 239.5)).norm(), 1e-9);
  const auto above = rv::project(cam, camera_T_board * (target + 0.01 * up));
  ASSERT_TRUE(above.has_value());
  EXPECT_LT(above->y(), c->y() - 1.0);  // "up" on the board is up in the image
  EXPECT_LT((camera_T_board.inverse().translation() - eye).norm(), 1e-14);
}

namespace {
// Reprojection residual of a board point, templated for Ceres' automatic differentiation.
template <class Model>
struct Reprojection {
  Eigen::Vector3d point;
  Eigen::Vector2d observed;
  template <class T>
  bool operator()(const T* params, const T* rvec_t, T* residual) const {
    const T p[3] = {T(point.x()), T(point.y()), T(point.z())};
    T pc[3];
    ceres::AngleAxisRotatePoint(rvec_t, p, pc);
    for (int i = 0; i < 3; ++i) pc[i] += rvec_t[3 + i];
    T px[2];
    if (!Model::project(params, pc, px)) return false;
    residual[0] = px[0] - T(observed.x());
    residual[1] = px[1] - T(observed.y());
    return true;
  }
};
}  // namespace

TEST(CameraModel, UsableInCeresAutoDiff) {
  // Recover a board pose from exact projections through a fisheye model.
  const auto cam = rv::make_camera(rv::CameraKind::kFisheyeKB4, 800, 600, 380, 379, 399.2, 301.1,
                                   {0.02, -0.01, 0.003, -0.0005});
  const Eigen::Vector3d rvec(0.2, -0.3, 0.1), t(-0.05, 0.02, 0.4);
  const Eigen::Isometry3d truth = rv::pose_from_rvec_tvec(rvec, t);
  double pose[6] = {0, 0, 0, 0, 0, 0.5};
  std::vector<double> params = cam.params;
  ceres::Problem problem;
  for (int j = 0; j < 5; ++j)
    for (int i = 0; i < 6; ++i) {
      const Eigen::Vector3d p(0.02 * i, 0.02 * j, 0.0);
      const auto px = rv::project(cam, truth * p);
      ASSERT_TRUE(px.has_value());
      using F = Reprojection<rv::FisheyeKB4>;
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<F, 2, rv::FisheyeKB4::kNumParams, 6>(new F{p, *px}),
          nullptr, params.data(), pose);
    }
  problem.SetParameterBlockConstant(params.data());
  ceres::Solver::Options options;
  options.function_tolerance = 1e-16;
  options.parameter_tolerance = 1e-16;
  options.gradient_tolerance = 1e-16;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  EXPECT_LT((Eigen::Vector3d(pose[0], pose[1], pose[2]) - rvec).norm(), 1e-9)
      << summary.BriefReport();
  EXPECT_LT((Eigen::Vector3d(pose[3], pose[4], pose[5]) - t).norm(), 1e-9);
}
