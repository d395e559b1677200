#pragma once
// The identification's plausibility gate: a result is presented as a usable calibration only
// when the solve converged and its fit residuals are of the size the measurements' stated noise
// predicts. Residuals far beyond it (a board file 5 % off: 200x on the pose route, 10x on the
// pixel route; rendered sessions: 0.9-1.0x) mean the model cannot explain the data, and the
// parameters it found absorb whatever is wrong.
#include "robocal/calib/identification.hpp"

#include <string>

namespace robocal::calib {

struct FitGateOptions {
  // Largest plausible ratio of the residuals' noise to the stated noise, at the low end of its
  // 95 % interval (so few degrees of freedom do not fail a good fit).
  double max_noise_scale = 5.0;
};

struct FitVerdict {
  bool plausible = true;
  std::string reason;  // plain words when !plausible
};

FitVerdict judge_identification(const IdentificationResult& result,
                                const FitGateOptions& options = {});

}  // namespace robocal::calib
