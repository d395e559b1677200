#pragma once
// The plain-words terminal summary of an identification (what `robocal identify` prints unless
// --quiet): status, what was estimated and what was held (the gauge) and why, the noise the
// residuals show beside the stated one, fit and predicted accuracy, outliers, warnings.
#include "robocal/calib/identification.hpp"

#include <string>

namespace robocal::calib {

std::string summary_text(const IdentificationResult& result);

// One line per validation ("held-out: 12 poses, position RMS 1.23 mm -> 12.5 um").
std::string validation_line(const std::string& label, const ValidationReport& report);

}  // namespace robocal::calib
