#include "robocal/calib/plausibility.hpp"

#include <fmt/core.h>

#include <cmath>
#include <numbers>

namespace robocal::calib {
namespace {

bool within(double q, const JointLimits& limits, double tolerance) {
  return q >= limits.lower - tolerance && q <= limits.upper + tolerance;
}

}  // namespace

std::optional<std::string> readings_problem(const Mechanism& model, const Eigen::VectorXd& params,
                                            const Eigen::VectorXd& readings) {
  if (readings.size() != static_cast<Eigen::Index>(model.actuated.size())) {
    return fmt::format("{} readings for {} actuators", readings.size(), model.actuated.size());
  }
  for (std::size_t k = 0; k < model.actuated.size(); ++k) {
    const Body& body = model.bodies[model.actuated[k]];
    const JointLimits& limits = body.limits;
    const bool bounded = limits.lower > -1e299 && limits.upper < 1e299;
    const double reading = readings[static_cast<Eigen::Index>(k)];
    const double scale = params[body.encoder_scale_param];
    const double offset = params[body.encoder_offset_param];
    const double q = scale * reading + offset;
    if (!std::isfinite(q)) {
      return fmt::format("actuator {} ({}) reads {}: not a number", k + 1, body.name, reading);
    }
    if (!bounded) {
      continue;
    }
    const double tolerance = 0.01 * (limits.upper - limits.lower);
    if (within(q, limits, tolerance)) {
      continue;
    }
    const bool revolute = body.joint == JointType::kRevolute;
    const double unit_guess = revolute ? std::numbers::pi / 180.0 : 1e-3;
    const bool guess_fits = within(scale * reading * unit_guess + offset, limits, tolerance);
    const char* unit = revolute ? "rad" : "m";
    std::string hint;
    if (guess_fits) {
      hint = revolute ? " (in degrees? the robot file's readings are radians)"
                      : " (in millimetres? the robot file's readings are metres)";
    }
    return fmt::format(
        "actuator {} ({}) reads {:.6g}: joint value {:.6g} {} is outside the robot file's limits "
        "[{:.6g}, {:.6g}] {}{}",
        k + 1, body.name, reading, q, unit, limits.lower, limits.upper, unit, hint);
  }
  return std::nullopt;
}

}  // namespace robocal::calib
