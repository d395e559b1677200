#pragma once
// JSON form of an identification result (the `robocal identify` result file). Field names are
// stable; units are metres and radians throughout.
#include "robocal/calib/identification.hpp"

#include <nlohmann/json.hpp>

namespace robocal::calib {

nlohmann::json to_json(const IdentifiabilityReport& report);
nlohmann::json to_json(const ErrorStatistics& stats);
nlohmann::json to_json(const ValidationReport& report);
nlohmann::json to_json(const KFoldReport& report);
nlohmann::json to_json(const IdentificationResult& result);

}  // namespace robocal::calib
