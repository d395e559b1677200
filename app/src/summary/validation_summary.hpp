#pragma once
// Summaries a person reads at the end of a run.
#include <nlohmann/json.hpp>

#include <cstdio>

namespace robocal::app {

// Human-readable closing summary of a validation report (nominal vs calibrated error, the
// parameters that changed most, what could not be identified) and its identification report.
void print_validation_summary(std::FILE* out, const nlohmann::json& validation,
                              const nlohmann::json& identification);

}  // namespace robocal::app
