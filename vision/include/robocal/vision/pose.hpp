#pragma once
// Pose conventions for all vision code.
//
// A pose is an Eigen::Isometry3d named `<to>_T_<from>`: it maps points expressed in frame <from>
// into frame <to>. `camera_T_board` maps board points (board frame, metres, z = 0 on the printed
// face) into the camera frame: p_camera = camera_T_board * p_board. Compose as
// camera_T_world = camera_T_board * board_T_world. Camera frame: OpenCV (x right, y down,
// z forward). Board frame: x along the columns, y along the rows (downwards on the print), z into
// the board, so a camera facing the print sees it with identity rotation.
#include <Eigen/Geometry>

namespace robocal::vision {

// From an OpenCV rotation vector (axis * angle, radians) and a translation.
Eigen::Isometry3d pose_from_rvec_tvec(const Eigen::Vector3d& rvec, const Eigen::Vector3d& tvec);
// The rotation vector (axis * angle, angle in [0, pi]) of a pose's rotation.
Eigen::Vector3d rvec_of(const Eigen::Isometry3d& pose);

// camera_T_board for a camera at `eye` (board frame) looking at `target` (board frame), with the
// image's "up" (-y of the camera) as close as possible to `up` (board frame).
Eigen::Isometry3d camera_T_board_look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                                         const Eigen::Vector3d& up);

// Rotation angle (radians) and translation distance between two poses (a^-1 * b).
double rotation_angle_between(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b);
double translation_between(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b);

}  // namespace robocal::vision
