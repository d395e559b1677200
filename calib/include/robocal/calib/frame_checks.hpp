#pragma once
// Checks of a model's frames that `robocal kin check` reports: a roll/pitch/yaw frame
// whose middle rotation is at or near ±90° sits at gimbal lock — its first and last rotations
// turn about the same axis, so identification cannot separate them (the Jacobian loses a column)
// and a small orientation change can need a large angle change.
#include "robocal/calib/mechanism.hpp"

#include <string>
#include <vector>

namespace robocal::calib {

// One plain-words warning per xyz_rpy body whose middle angle is within `margin_deg` of ±90°.
std::vector<std::string> gimbal_lock_warnings(const Mechanism& model, double margin_deg = 5.0);

}  // namespace robocal::calib
