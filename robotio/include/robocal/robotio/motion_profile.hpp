#pragma once
// Trapezoidal motion profile (constant acceleration to the feed rate, cruise, constant
// deceleration), the profile G-code firmwares plan a single isolated move with. The link uses it
// for its settle timeout, the simulated controller for its move times.
#include <algorithm>
#include <cmath>

namespace robocal::robotio {

// Duration of a move of length `distance` at feed `speed` with `acceleration` (same units).
inline double trapezoid_seconds(double distance, double speed, double acceleration) {
  if (!(distance > 0.0)) return 0.0;
  if (!(speed > 0.0) || !(acceleration > 0.0)) return 0.0;
  const double ramp = speed * speed / acceleration;  // distance spent accelerating + braking
  if (distance >= ramp) return distance / speed + speed / acceleration;
  return 2.0 * std::sqrt(distance / acceleration);  // triangle: never reaches `speed`
}

// Distance covered after `t` seconds of that move (for a move interrupted midway).
inline double trapezoid_distance(double distance, double speed, double acceleration, double t) {
  const double total = trapezoid_seconds(distance, speed, acceleration);
  if (t <= 0.0) return 0.0;
  if (t >= total) return distance;
  const double peak = std::min(speed, std::sqrt(distance * acceleration));
  const double t_ramp = peak / acceleration;
  const double d_ramp = 0.5 * acceleration * t_ramp * t_ramp;
  if (t < t_ramp) return 0.5 * acceleration * t * t;
  const double t_cruise_end = total - t_ramp;
  if (t < t_cruise_end) return d_ramp + peak * (t - t_ramp);
  const double left = total - t;
  return distance - 0.5 * acceleration * left * left;
}

}  // namespace robocal::robotio
