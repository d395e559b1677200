#pragma once
// Plausibility gates of the calibration data and fit, in plain words: a reading the robot could
// not have (outside its joint limits: often degrees where the robot file uses radians, or
// millimetres for metres), and an identification whose fit residuals are far beyond the stated
// measurement noise (the model cannot explain the data: a wrong robot file, board, or readings).
// A result that fails a gate must not be presented as a usable calibration.
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>

#include <optional>
#include <string>

namespace robocal::calib {

// Why `readings` (one pose, the robot file's reading units) cannot be a real configuration of
// the robot: actuator k outside its joint limits (through the encoder model at `params`), beyond
// a tolerance of 1 % of the range; with a hint when the reading converted from degrees or
// millimetres would fit. nullopt when every reading is plausible.
std::optional<std::string> readings_problem(const Mechanism& model, const Eigen::VectorXd& params,
                                            const Eigen::VectorXd& readings);

}  // namespace robocal::calib
