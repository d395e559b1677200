#pragma once
// The names of a camera model's parameters in their layout order (CameraModel::params), for
// reports and for the parameters of a camera-in-the-loop fit. In robocal_vision_camera, so calib
// names camera parameters the way vision's intrinsic calibration does, from one list.
#include "robocal/vision/camera_model.hpp"

#include <string>
#include <vector>

namespace robocal::vision {

/// "fx", "fy", "cx", "cy", then the distortion terms of `kind` ("k1", "k2", "p1", ...).
std::vector<std::string> camera_param_names(CameraKind kind);

}  // namespace robocal::vision
