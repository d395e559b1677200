#pragma once
// Placing a fixed frame of a mechanism: the values of a body's own parameters that put its frame
// at a wanted pose (e.g. the board mount on the tool, or the base frame in a camera world).
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Geometry>

namespace robocal::calib {

// Sets the parameters of a fixed body so that its frame has `world_T_desired` (given the rest of
// the chain at `params` and the actuators at `actuator_readings`); Gauss–Newton on the body's
// own parameters (central differences), any convention; redundant parameters of the frame keep
// their values (minimum-norm steps). Returns the remaining pose error (m + rad). Throws
// std::runtime_error when the body has no parameters or the closure fails.
double set_fixed_frame_pose(const Mechanism& model, Eigen::VectorXd& params, int body,
                            const Eigen::VectorXd& actuator_readings,
                            const Eigen::Isometry3d& world_T_desired);

}  // namespace robocal::calib
