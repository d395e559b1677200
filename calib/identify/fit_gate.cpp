#include "robocal/calib/fit_gate.hpp"

#include <fmt/core.h>

namespace robocal::calib {

FitVerdict judge_identification(const IdentificationResult& result, const FitGateOptions& options) {
  FitVerdict v;
  if (result.status != IdentificationStatus::kConverged) {
    v.plausible = false;
    v.reason = fmt::format("the identification did not converge ({}): {}", to_string(result.status),
                           result.message);
    return v;
  }
  for (const NoiseGroup& group : result.noise.groups) {
    if (group.estimable && !(group.scale_low <= options.max_noise_scale)) {
      v.plausible = false;
      v.reason = fmt::format(
          "the fit residuals of the {} measurements are {:.1f}x their stated noise (95 % "
          "interval {:.1f}-{:.1f}x; plausible up to {:.0f}x): the model cannot explain the "
          "measurements. Check the robot file, the end-effector board's file and the actuator "
          "readings' units",
          group.type, group.scale, group.scale_low, group.scale_high, options.max_noise_scale);
      return v;
    }
  }
  return v;
}

}  // namespace robocal::calib
