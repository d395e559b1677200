#pragma once
// Test fixture only: the planar arm of planar_fixture.hpp watched by two cameras from above, with a
// 3x3 corner grid (5 cm pitch) on its measured frame.
#include "planar_fixture.hpp"
#include "robocal/calib/pixel_observations.hpp"

namespace robocal::calib::testing {

inline std::vector<Eigen::Vector3d> planar_target() {
  std::vector<Eigen::Vector3d> pts;
  for (int i = -1; i <= 1; ++i)
    for (int j = -1; j <= 1; ++j) pts.emplace_back(0.05 * i, 0.05 * j, 0.0);
  return pts;
}

// True cameras: 2.3 m above the arm's plane, 1 m apart, looking at its centre (camera 0 also
// carries distortion; camera 1 is a fisheye so both projection families are exercised).
inline std::vector<ObservingCamera> planar_true_cameras() {
  ObservingCamera c0;
  c0.name = "camera0";
  c0.model = vision::make_camera(vision::CameraKind::kPinholeRadtan, 1280, 960, 800.0, 801.0, 639.5,
                                 479.5, {-0.05, 0.02, 1e-4, -2e-4, 0.0});
  c0.world_T_camera = camera_looking_at(Eigen::Vector3d(-0.5, 0.0, 2.6),
                                        Eigen::Vector3d(0.1, -0.2, 0.32), Eigen::Vector3d::UnitY());
  ObservingCamera c1;
  c1.name = "camera1";
  c1.model = vision::make_camera(vision::CameraKind::kFisheyeKB4, 1280, 960, 600.0, 600.5, 641.0,
                                 478.0, {0.01, -0.005, 0.001, 0.0});
  c1.world_T_camera = camera_looking_at(Eigen::Vector3d(0.6, 0.1, 2.5),
                                        Eigen::Vector3d(0.1, -0.2, 0.32), Eigen::Vector3d::UnitY());
  return {c0, c1};
}

// What the identification is told: camera 0 exact (the gauge), camera 1 off by ~5 mm / 0.6°.
inline std::vector<ObservingCamera> planar_start_cameras() {
  auto cams = planar_true_cameras();
  cams[1].world_T_camera.translation() += Eigen::Vector3d(4e-3, -3e-3, 2e-3);
  cams[1].world_T_camera.linear() =
      Eigen::AngleAxisd(0.01, Eigen::Vector3d(1, 2, -1).normalized()).toRotationMatrix() *
      cams[1].world_T_camera.linear();
  return cams;
}

}  // namespace robocal::calib::testing
