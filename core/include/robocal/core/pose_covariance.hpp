#pragma once
// The project's one convention for the uncertainty of a pose world_T_frame = (R, p):
//
//   perturbation  δ = [δp; δφ]  (position in m, then rotation vector in rad, both in the world
//                               frame):  world_T_frame = [exp(δφ) R, p + δp]
//   covariance    6x6 over δ in that order (PoseCovariance)
//
// Calibration (observations, identification) works in it throughout. The camera pipeline's
// estimators keep OpenCV's rotation-first order [δφ; δp] (rvec before tvec) inside, and so do
// the files that store their results (measured_poses.json, rig files: they say so in a
// "covariance_convention" field); they convert at their edge with the two functions below, and
// nowhere else.
#include <Eigen/Core>

namespace robocal::core {

using PoseCovariance = Eigen::Matrix<double, 6, 6>;

// [δφ; δp] -> [δp; δφ].
inline PoseCovariance position_first(const Eigen::Matrix<double, 6, 6>& rotation_first) {
  const auto& v = rotation_first;
  PoseCovariance out;
  out << v.bottomRightCorner<3, 3>(), v.bottomLeftCorner<3, 3>(),  // position rows
      v.topRightCorner<3, 3>(), v.topLeftCorner<3, 3>();           // rotation rows
  return out;
}

// [δp; δφ] -> [δφ; δp] (the inverse of position_first).
inline Eigen::Matrix<double, 6, 6> rotation_first(const PoseCovariance& position_first_cov) {
  // Swapping the two 3x3 block rows and columns is its own inverse.
  return position_first(position_first_cov);
}

}  // namespace robocal::core
