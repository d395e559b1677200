#pragma once
// The identification's plausibility gate: a result is presented as a usable calibration only
// when the solve converged and its fit residuals are of the size the measurements' stated noise
// predicts. Residuals far beyond it (a board file 5 % off: 200x on the pose route, 10x on the
// pixel route; rendered sessions: 0.9-1.0x) mean the model cannot explain the data, and the
// parameters it found absorb whatever is wrong.
#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism.hpp"

#include <string>

namespace robocal::calib {

// The residuals' noise is plausible up to hypot(max_noise_scale x stated noise, model error):
// the measurement noise the data states, with room for the robot's unmodelled error (its robot
// file's `unmodelled_error`, which no kinematic parameter can follow). A wrong board file or
// wrong actuator units still stand out: their residuals are 10-200x the noise and far beyond
// any plausible model error.
struct FitGateOptions {
  // Largest plausible ratio of the residuals' noise to the stated noise, at the low end of its
  // 95 % interval (so few degrees of freedom do not fail a good fit).
  double max_noise_scale = 5.0;
  // The robot's unmodelled error per residual unit (RMS per axis): "m" (points, pose positions,
  // distances, probe heights), "rad" (pose rotations), "px" (corner pixels: the position error
  // as the cameras see it: fit_gate_options). 0 = none allowed.
  double model_error_m = 0.0;
  double model_error_rad = 0.0;
  double model_error_px = 0.0;
};

// The gate's options for a robot: its stated unmodelled error (robot file `unmodelled_error`);
// `pixels_per_metre` converts the position part for the pixel residuals (0: none).
FitGateOptions fit_gate_options(const UnmodelledErrorSpec& unmodelled, double pixels_per_metre);

struct FitVerdict {
  bool plausible = true;
  std::string reason;  // plain words when !plausible
};

FitVerdict judge_identification(const IdentificationResult& result,
                                const FitGateOptions& options = {});

}  // namespace robocal::calib
