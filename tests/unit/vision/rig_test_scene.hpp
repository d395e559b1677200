#pragma once
// The bench's stereo scene for the rig/pose tests: two 2448x2048 cameras, f = 2400 px, 0.5 m
// baseline, 30 deg convergence, a 200 mm AprilTag grid (6 x 6 tags) about 1.15 m away.
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/observations.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/synthetic_observations.hpp"

#include <Eigen/Geometry>

#include <cmath>
#include <random>
#include <vector>

namespace robocal::vision::testing {

inline CameraModel bench_camera() {
  return make_camera(CameraKind::kPinholeRadtan, 2448, 2048, 2400.0, 2400.0, 1223.5, 1023.5,
                     {-0.08, 0.05, 0.0002, -0.0001, 0.0});
}

// World frame: x right, y down, z forward (like the cameras); cameras at x = -/+ baseline / 2,
// optical axes crossing on the z axis at `converge_z`.
inline std::vector<RigCamera> stereo_rig(double baseline = 0.5, double convergence_deg = 30.0) {
  const double half = 0.5 * baseline;
  const double converge_z = half / std::tan(0.5 * convergence_deg * M_PI / 180.0);
  std::vector<RigCamera> rig(2);
  for (int i = 0; i < 2; ++i) {
    rig[i].name = i == 0 ? "left" : "right";
    rig[i].model = bench_camera();
    rig[i].camera_T_world =
        camera_T_board_look_at(Eigen::Vector3d(i == 0 ? -half : half, 0, 0),
                               Eigen::Vector3d(0, 0, converge_z), Eigen::Vector3d(0, -1, 0));
  }
  return rig;
}

inline BoardPoints bench_board() {
  const double tag = 0.2 / 7.5;  // 6 tags + 5 gaps of 0.3 tag = 200 mm
  return apriltag_grid_points(6, 6, tag, 0.3 * tag);
}

// A random board pose: its centre near (0, 0, distance) in the world, facing the cameras (board
// z along +world z), tilted up to max_tilt_deg about a random in-plane axis and spun about its
// normal.
inline Eigen::Isometry3d random_target_pose(std::mt19937_64& rng, double distance = 1.15,
                                            double max_tilt_deg = 35.0, double board_half = 0.1) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double tilt = std::abs(u(rng)) * max_tilt_deg * M_PI / 180.0;
  const double axis_angle = u(rng) * M_PI;
  const double spin = u(rng) * M_PI;
  const Eigen::Vector3d axis(std::cos(axis_angle), std::sin(axis_angle), 0.0);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() =
      (Eigen::AngleAxisd(tilt, axis) * Eigen::AngleAxisd(spin, Eigen::Vector3d::UnitZ()))
          .toRotationMatrix();
  // One draw a statement, z first (robocal/core/random_draws.hpp says why).
  const double z = distance + 0.05 * u(rng);
  const double y = 0.05 * u(rng);
  const double x = 0.05 * u(rng);
  const Eigen::Vector3d centre(x, y, z);
  pose.translation() = centre - pose.linear() * Eigen::Vector3d(board_half, board_half, 0.0);
  return pose;
}

inline std::vector<CameraFrame> observe(const std::vector<RigCamera>& rig,
                                        const Eigen::Isometry3d& world_T_target,
                                        const BoardPoints& board, double sigma_px,
                                        std::mt19937_64& rng) {
  std::vector<CameraFrame> frame;
  for (const RigCamera& cam : rig)
    frame.push_back(
        simulate_frame(cam.model, cam.camera_T_world * world_T_target, board, sigma_px, rng));
  return frame;
}

// Pose error as the 6-vector of the covariance convention: [log(R_est R_true^T); t_est - t_true].
inline Eigen::Matrix<double, 6, 1> pose_error(const Eigen::Isometry3d& estimate,
                                              const Eigen::Isometry3d& truth) {
  Eigen::Matrix<double, 6, 1> e;
  const Eigen::AngleAxisd aa(estimate.linear() * truth.linear().transpose());
  e.head<3>() = aa.axis() * aa.angle();
  e.tail<3>() = estimate.translation() - truth.translation();
  return e;
}

}  // namespace robocal::vision::testing
