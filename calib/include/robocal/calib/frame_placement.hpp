#pragma once
// Placing a fixed frame of a mechanism: the values of a body's own parameters that put its frame
// at a wanted pose (e.g. the board mount on the tool, or the base frame in a camera world).
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Geometry>

#include <string>
#include <utility>
#include <vector>

namespace robocal::calib {

// Sets the parameters of a fixed body so that its frame has `world_T_desired` (given the rest of
// the chain at `params` and the actuators at `actuator_readings`); Gauss–Newton on the body's
// own parameters (central differences), any convention; redundant parameters of the frame keep
// their values (minimum-norm steps). Returns the remaining pose error (m + rad). Throws
// std::runtime_error when the body has no parameters or the closure fails.
double set_fixed_frame_pose(const Mechanism& model, Eigen::VectorXd& params, int body,
                            const Eigen::VectorXd& actuator_readings,
                            const Eigen::Isometry3d& world_T_desired);

// A target mounted with an offset on a fixed frame (a board `frame_T_offset` from the tool frame,
// as a cell file states it): the values of that frame's own parameters that put the frame where
// the board is, so every pose of the frame is the board's. The frame must be a fixed body outside
// every closed loop (then its parameters move nothing else); the placement is solved at the home
// configuration and holds at every configuration. Returns (parameter name, value) per parameter
// of the body. Throws std::invalid_argument naming the body when it is not such a frame, has no
// parameters, or the placement does not reach the offset (residual above 1e-9 m + rad).
std::vector<std::pair<std::string, double>> mounted_frame_parameters(
    const Mechanism& model, const Eigen::VectorXd& params, int body,
    const Eigen::Isometry3d& frame_T_offset);

}  // namespace robocal::calib
