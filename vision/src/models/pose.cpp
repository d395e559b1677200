#include "robocal/vision/pose.hpp"

#include <cmath>

namespace robocal::vision {

Eigen::Isometry3d pose_from_rvec_tvec(const Eigen::Vector3d& rvec, const Eigen::Vector3d& tvec) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  const double angle = rvec.norm();
  if (angle > 0.0) pose.linear() = Eigen::AngleAxisd(angle, rvec / angle).toRotationMatrix();
  pose.translation() = tvec;
  return pose;
}

Eigen::Vector3d rvec_of(const Eigen::Isometry3d& pose) {
  const Eigen::AngleAxisd aa(pose.linear());
  return aa.axis() * aa.angle();
}

Eigen::Isometry3d camera_T_board_look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                                         const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d y = -(up - up.dot(z) * z);  // image y points down, i.e. away from `up`
  if (y.norm() < 1e-12) y = z.unitOrthogonal();
  y.normalize();
  const Eigen::Vector3d x = y.cross(z);
  Eigen::Matrix3d board_R_camera;
  board_R_camera << x, y, z;
  Eigen::Isometry3d board_T_camera = Eigen::Isometry3d::Identity();
  board_T_camera.linear() = board_R_camera;
  board_T_camera.translation() = eye;
  return board_T_camera.inverse();
}

double rotation_angle_between(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd((a.linear().transpose() * b.linear())).angle();
}

double translation_between(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.inverse() * b).translation().norm();
}

}  // namespace robocal::vision
