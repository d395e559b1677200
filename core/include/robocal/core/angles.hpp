#pragma once
// Degrees for people, radians for the numerics: the conversion written once.

#include <numbers>

namespace robocal::core {

inline constexpr double kDegreesPerRadian = 180.0 / std::numbers::pi;

constexpr double degrees(double angle_rad) {
  return angle_rad * kDegreesPerRadian;
}
constexpr double radians(double angle_deg) {
  return angle_deg / kDegreesPerRadian;
}

}  // namespace robocal::core
