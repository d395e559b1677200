#pragma once
// Writes a calibrated robot file: the original robot file's text with the estimated parameter
// values substituted (comments, layout and expressions of unchanged values kept) and a provenance
// comment block at the top. The result is re-parsed before it is returned, and every parameter
// must read back as the value written (else std::runtime_error): a calibrated file that loads to
// something else is never produced.
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace robocal::calib {

// `original` = text of the robot file `model` was loaded from; `values` = full parameter vector;
// `changed` = indices to write (others keep their text); `provenance` = lines for the header.
std::string calibrated_robot_yaml(const std::string& original, const Mechanism& model,
                                  const Eigen::VectorXd& values,
                                  const std::vector<std::size_t>& changed,
                                  const std::vector<std::string>& provenance);

}  // namespace robocal::calib
