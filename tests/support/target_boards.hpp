#pragma once
// Target boards and board poses that the vision tests and benches set up again and again: one
// place to build a board from its few numbers and to put its centre in front of the camera.
#include <Eigen/Geometry>

#include "robocal/vision/target.hpp"

namespace robocal::testing {

/// A spec of `kind` with its grid size set; the builders below fill in the rest.
inline vision::TargetSpec grid_spec(vision::TargetKind kind, int cols, int rows) {
  vision::TargetSpec s;
  s.kind = kind;
  s.cols = cols;
  s.rows = rows;
  return s;
}

inline vision::TargetBoard apriltag_grid_board(int cols, int rows, double tag_size,
                                               int first_id = 0) {
  auto s = grid_spec(vision::TargetKind::kAprilTagGrid, cols, rows);
  s.tag_size = tag_size;
  s.first_id = first_id;
  return vision::build_target(s);
}

inline vision::TargetBoard chessboard_board(int cols, int rows, double square_size) {
  auto s = grid_spec(vision::TargetKind::kChessboard, cols, rows);
  s.square_size = square_size;
  return vision::build_target(s);
}

/// ChArUco board with TargetSpec's default dictionary (DICT_6X6_250).
inline vision::TargetBoard charuco_board(int cols, int rows, double square_size,
                                         double marker_size) {
  auto s = grid_spec(vision::TargetKind::kCharuco, cols, rows);
  s.square_size = square_size;
  s.marker_size = marker_size;
  return vision::build_target(s);
}

/// The board of the real rct_charuco image set (OpenCV's create(cols=5, rows=7) layout).
inline vision::TargetBoard rct_charuco_board() {
  return charuco_board(5, 7, 0.036195, 0.018256);
}

/// Centre of the board's pattern extent, in the board plane.
inline Eigen::Vector2d board_centre(const vision::TargetBoard& b) {
  return (b.extent_min + b.extent_max) / 2;
}

/// camera_T_board with orientation `r` that puts the board's centre at `distance` on the optical
/// axis.
inline Eigen::Isometry3d centred_board_pose(const vision::TargetBoard& b, const Eigen::Matrix3d& r,
                                            double distance) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = r;
  const Eigen::Vector2d c = board_centre(b);
  pose.translation() = Eigen::Vector3d(0, 0, distance) - r * Eigen::Vector3d(c.x(), c.y(), 0);
  return pose;
}

/// centred_board_pose tilted about the board's x axis, then its y axis, then rolled about the
/// optical axis (degrees).
inline Eigen::Isometry3d tilted_board_pose(const vision::TargetBoard& b, double distance,
                                           double tilt_x_deg, double tilt_y_deg, double roll_deg) {
  const Eigen::Matrix3d r = (Eigen::AngleAxisd(roll_deg * M_PI / 180, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(tilt_x_deg * M_PI / 180, Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(tilt_y_deg * M_PI / 180, Eigen::Vector3d::UnitY()))
                                .toRotationMatrix();
  return centred_board_pose(b, r, distance);
}

}  // namespace robocal::testing
