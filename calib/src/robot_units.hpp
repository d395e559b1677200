#pragma once
// The units a robot file is written in (metres, radians) checked against the values it holds: a
// length of metres that reads as millimetres, an angle or a revolute joint's limit that reads as
// degrees. Such a file loads and even closes its loops, but every figure computed from it is
// wrong by a factor of 1000 or 57 (and the safety guard would take its limits).
#include "robocal/calib/mechanism.hpp"

#include <string>

namespace robocal::calib {

// Above this a length of a robot file is taken for millimetres: no library robot (cable robots
// included) has a link or an offset of more than a few metres.
inline constexpr double kMaxPlausibleLengthM = 10.0;

// Throws RobotFileError ("<source>:<line>: ...") for the first value whose unit it cannot be in:
// a length parameter, a prismatic joint's limit or home beyond kMaxPlausibleLengthM; an angle
// parameter, a revolute joint's limit or home beyond ±4π (two turns). The message names the key,
// the value and the likely cause.
void check_robot_units(const Mechanism& m, const std::string& source);

}  // namespace robocal::calib
