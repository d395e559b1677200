#include "robot_units.hpp"

#include "robocal/calib/robot_file.hpp"
#include "robocal/core/angles.hpp"

#include <fmt/core.h>

#include <cmath>
#include <numbers>
#include <string>

namespace robocal::calib {

namespace {

// A revolute joint may turn more than a full turn each way (a UR joint's ±2π with its zero offset
// added, an ABB wrist's ±400°); beyond two full turns a value is degrees. Degrees below 720° that
// read as radians under two turns (a ±10° limit) are not told apart.
constexpr double kMaxPlausibleAngleRad = 4.0 * std::numbers::pi;

std::string where(const std::string& source, int line) {
  return line > 0 ? fmt::format("{}:{}", source, line) : source;
}

[[noreturn]] void refuse_length(const std::string& at, const std::string& key, double value) {
  throw RobotFileError(fmt::format(
      "{}: {} is {:g} m, more than {:g} m: likely millimetres written where the robot file "
      "takes metres ({:g} mm would be {:g} m)",
      at, key, value, kMaxPlausibleLengthM, value, value / 1000.0));
}

[[noreturn]] void refuse_angle(const std::string& at, const std::string& key, double value) {
  throw RobotFileError(
      fmt::format("{}: {} is {:g} rad, beyond ±4π (two turns): likely degrees written where the "
                  "robot file takes "
                  "radians ({:g}° is {:.4g} rad; write deg({:g}))",
                  at, key, value, value, core::radians(value), value));
}

void check_parameters(const Mechanism& m, const std::string& source) {
  for (const Parameter& p : m.parameters) {
    const std::string at = where(source, p.line);
    if (p.unit == ParamUnit::kLength && std::abs(p.value) > kMaxPlausibleLengthM)
      refuse_length(at, "parameter '" + p.name + "'", p.value);
    if (p.unit == ParamUnit::kAngle && std::abs(p.value) > kMaxPlausibleAngleRad)
      refuse_angle(at, "parameter '" + p.name + "'", p.value);
  }
}

// A limit left at its default (none given) is ±1e300: not a value of the file.
bool given(double limit) {
  return std::abs(limit) < 1e299;
}

void check_joint_values(const Body& body, const std::string& source) {
  if (body.joint == JointType::kFixed) return;
  const bool revolute = body.joint == JointType::kRevolute;
  const std::string at = where(source, body.line);
  const auto check = [&](const std::string& key, double value) {
    if (revolute && std::abs(value) > kMaxPlausibleAngleRad)
      refuse_angle(at, "body '" + body.name + "': revolute joint's " + key, value);
    if (!revolute && std::abs(value) > kMaxPlausibleLengthM)
      refuse_length(at, "body '" + body.name + "': prismatic joint's " + key, value);
  };
  if (given(body.limits.lower)) check("lower limit", body.limits.lower);
  if (given(body.limits.upper)) check("upper limit", body.limits.upper);
  check("home", body.home);
}

}  // namespace

void check_robot_units(const Mechanism& m, const std::string& source) {
  check_parameters(m, source);
  for (const Body& body : m.bodies) check_joint_values(body, source);
}

}  // namespace robocal::calib
