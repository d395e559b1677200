#pragma once
// Conversions between vision's measurements and calib's observations. The two libraries document
// different 6x6 covariance orders (both with world-frame rotation perturbations):
//   vision::PoseMeasurement::covariance   [d_theta (rad); d_t (m)]
//   calib::PoseObservation::with_covariance [position (m); rotation vector (rad)]
// so the blocks are swapped here, in one place, with a test.
#include "robocal/calib/observations.hpp"
#include "robocal/vision/pose_measurement.hpp"

#include <Eigen/Core>

namespace robocal::app {

// Reorders a vision pose covariance [rotation; translation] into calib's [position; rotation].
inline Eigen::Matrix<double, 6, 6> vision_to_calib_covariance(
    const Eigen::Matrix<double, 6, 6>& vision_covariance) {
  const auto& v = vision_covariance;
  Eigen::Matrix<double, 6, 6> out;
  out << v.bottomRightCorner<3, 3>(), v.bottomLeftCorner<3, 3>(),  // position rows
      v.topRightCorner<3, 3>(), v.topLeftCorner<3, 3>();           // rotation rows
  return out;
}

inline calib::PoseObservation to_pose_observation(const vision::PoseMeasurement& measurement) {
  return calib::PoseObservation::with_covariance(
      measurement.world_T_target, vision_to_calib_covariance(measurement.covariance));
}

}  // namespace robocal::app
