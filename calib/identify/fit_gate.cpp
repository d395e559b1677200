#include "robocal/calib/fit_gate.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/core.h>

namespace robocal::calib {

namespace {

double model_error_for(const NoiseGroup& group, const FitGateOptions& options) {
  if (group.unit == "m") return options.model_error_m;
  if (group.unit == "rad") return options.model_error_rad;
  if (group.unit == "px") return options.model_error_px;
  return 0.0;
}

// The stated noise and the allowance in the group's unit, in words ("1.6 µm", "0.012 px").
std::string in_unit(double value, const std::string& unit) {
  if (unit == "m") return fmt::format("{:.3g} µm", value * 1e6);
  if (unit == "rad") return fmt::format("{:.3g} mrad", value * 1e3);
  return fmt::format("{:.3g} {}", value, unit);
}

}  // namespace

FitGateOptions fit_gate_options(const UnmodelledErrorSpec& unmodelled, double pixels_per_metre) {
  FitGateOptions options;
  options.model_error_m = unmodelled.position;
  options.model_error_rad = unmodelled.rotation;
  options.model_error_px = unmodelled.position * std::max(0.0, pixels_per_metre);
  return options;
}

FitVerdict judge_identification(const IdentificationResult& result, const FitGateOptions& options) {
  FitVerdict v;
  if (result.status != IdentificationStatus::kConverged) {
    v.plausible = false;
    v.reason = fmt::format("the identification did not converge ({}): {}", to_string(result.status),
                           result.message);
    return v;
  }
  for (const NoiseGroup& group : result.noise.groups) {
    if (!group.estimable) continue;
    const double model_error = model_error_for(group, options);
    const double allowed = std::hypot(options.max_noise_scale * group.stated_sigma, model_error);
    if (group.scale_low * group.stated_sigma <= allowed) continue;
    v.plausible = false;
    v.reason = fmt::format(
        "the fit residuals of the {} measurements are {:.1f}x their stated noise ({} against "
        "{} stated; 95 % interval {:.1f}-{:.1f}x); up to {} is plausible ({:.0f}x the noise, "
        "with the robot's unmodelled error of {}: robot file `unmodelled_error`): the model "
        "cannot explain the measurements. Check the robot file, the end-effector board's file "
        "and the actuator readings' units",
        group.type, group.scale, in_unit(group.estimated_sigma(), group.unit),
        in_unit(group.stated_sigma, group.unit), group.scale_low, group.scale_high,
        in_unit(allowed, group.unit), options.max_noise_scale, in_unit(model_error, group.unit));
    return v;
  }
  return v;
}

}  // namespace robocal::calib
