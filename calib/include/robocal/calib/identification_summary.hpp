#pragma once
// The plain-words terminal summary of an identification (what `robocal identify` prints unless
// --quiet): status, what was estimated and what was held (the gauge) and why, the noise the
// residuals show beside the stated one, fit and predicted accuracy, outliers, warnings.
#include "robocal/calib/identification.hpp"

#include <string>
#include <vector>

namespace robocal::calib {

std::string summary_text(const IdentificationResult& result);

// `text` (e.g. an identifiability explanation) with every raw parameter name of `result` that has
// a label replaced by the label: "body26.d1 moves like ..." -> "rod 26 length moves like ...".
// Only whole names are replaced (body2.d1 inside body22.d1 is left alone).
std::string in_plain_words(const std::string& text, const IdentificationResult& result);

// A text cut where it names a parameter, for a reader that shows names its own way (the report
// page: the label, with the raw name as a tooltip). `parameter` is an index into `names`, or -1
// for plain text between names. Whole names only, as in_plain_words; the longest name wins.
struct TextPart {
  std::string text;
  int parameter = -1;
};
std::vector<TextPart> parameter_mentions(const std::string& text,
                                         const std::vector<std::string>& names);

// One line per validation ("held-out: 12 poses, position RMS 1.23 mm -> 12.5 µm").
std::string validation_line(const std::string& label, const ValidationReport& report);
// The same, naming what the errors are of (`what`: "position", "probe height", ...): poses
// measured by probe heights only have height errors, not position errors.
std::string validation_line(const std::string& label, const ValidationReport& report,
                            const std::string& what);

}  // namespace robocal::calib
