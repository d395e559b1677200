#pragma once
// Summaries a person reads at the end of a run.
#include <nlohmann/json.hpp>

#include <cstdio>

namespace robocal::app {

// What it means that a model "cannot answer" a held-out configuration (validate counts these as
// its failures): the same words in the terminal, the validation log and the report page.
inline constexpr const char* kNoAnswerMeaning =
    "no answer on the intended assembly mode: a loop that does not close, or a configuration at "
    "or across a mode boundary";

// Human-readable closing summary of a validation report (nominal vs calibrated error, the
// parameters that changed most, what could not be identified) and its identification report.
void print_validation_summary(std::FILE* out, const nlohmann::json& validation,
                              const nlohmann::json& identification);

}  // namespace robocal::app
