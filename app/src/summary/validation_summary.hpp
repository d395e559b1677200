#pragma once
// Summaries a person reads at the end of a run, and the words they share with the report page.
#include "session/results_files.hpp"

#include "robocal/calib/identification_summary.hpp"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <string>
#include <vector>

namespace robocal::app {

// What it means that a model "cannot answer" a held-out configuration (validate counts these as
// its failures): the same words in the terminal, the validation log and the report page.
inline constexpr const char* kNoAnswerMeaning =
    "no answer on the intended assembly mode: a loop that does not close, or a configuration at "
    "or across a mode boundary";

// A sentence that names parameters: `parameter` of each part indexes ParameterAccount::names
// (-1: plain text). Each reader shows a parameter its own way (the terminal by its label, the
// report page by its label with the name in the robot file as a tooltip).
using ParameterSentence = std::vector<calib::TextPart>;

// What the identification did with the model's parameters, in the words every summary uses.
struct ParameterWords {
  std::string identified;  // "50 of the 158 free parameters were identified ...": the counts
  std::string held;        // "108 of the 158 free parameters are held at nominal ..."
  // Why parameters are held: those without effect (one sentence), then each one that moves the
  // measurements like others; then what else the analysis says (a relinearised solve, pairs the
  // data barely separate, too few equations).
  std::vector<ParameterSentence> reasons, notes;
};
ParameterWords parameter_words(const ParameterAccount& account);
// The sentence with every parameter named by its label.
std::string with_labels(const ParameterSentence& sentence, const ParameterAccount& account);

// Human-readable closing summary of a validation report (nominal vs calibrated error, the
// parameters that changed most, what could not be identified) and its identification report.
// Throws InputError when the identification report lacks its parameter analysis.
void print_validation_summary(std::FILE* out, const nlohmann::json& validation,
                              const nlohmann::json& identification);

}  // namespace robocal::app
