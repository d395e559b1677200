#pragma once
// A board pose measured by the camera pipeline as calib's pose observation. The covariance goes
// from vision's rotation-first order to the project's position-first convention
// (core/pose_covariance.hpp).
#include "robocal/calib/observations.hpp"
#include "robocal/core/pose_covariance.hpp"
#include "robocal/vision/pose_measurement.hpp"

namespace robocal::app {

inline calib::PoseObservation to_pose_observation(const vision::PoseMeasurement& measurement) {
  return calib::PoseObservation::with_covariance(measurement.world_T_target,
                                                 core::position_first(measurement.covariance));
}

}  // namespace robocal::app
