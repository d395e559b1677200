#pragma once
// Where the robot stands in the measurement world, before identification: what hand-eye
// calibration alone gives. The nominal model's predicted positions of the measured frame are
// aligned with the measured positions by the best rigid transform (Umeyama, no scale), and the
// robot's base frame (its first body, hung from the world) is placed there.
#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Geometry>

#include <cstddef>
#include <vector>

namespace robocal::calib {

struct BaseFrameFit {
  std::size_t poses = 0;  // poses with a pose observation whose closure solved
  bool placed = false;    // false: fewer than 3 such poses, `params` unchanged
  Eigen::Isometry3d world_T_base = Eigen::Isometry3d::Identity();  // the aligning transform
};

// Aligns the predictions of `frame` (at `params`) with the first observation of each pose when
// it is a PoseObservation, and moves the root body's parameters (set_fixed_frame_pose at the
// first pose's actuators) so the model's base sits at world_T_base.
BaseFrameFit fit_base_frame(const Mechanism& model, Eigen::VectorXd& params, int frame,
                            const std::vector<PoseMeasurement>& poses);

}  // namespace robocal::calib
