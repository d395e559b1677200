#pragma once
// `robocal export`: a calibrated robot (a session's results/calibrated_robot.yaml) or a robot
// file written for a controller or another tool. The formats are calib's (firmware_delta.hpp,
// serial_exports.hpp); this stage resolves the input, calls the writer and writes the file.
#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace robocal::app {

struct ExportRequest {
  std::string input;   // session folder or robot file
  std::string format;  // klipper, marlin, rrf, urdf, dh
  std::string out;     // file to write ("" = none: the caller prints report["text"])
};

// The formats `robocal export --format` takes, in the order --help lists them.
const std::vector<std::string>& export_formats();

// Returns the report: input, robot, format, text, and for the firmware formats the settings by
// the firmware's names with the firmware model's residual (residual_rms_m, residual_max_m). Throws
// core::InputError naming the input for a session without identification results, a missing or
// malformed robot file, or a robot the format cannot describe (with the reason). Nothing is
// written unless the export succeeded; --out is written atomically.
nlohmann::json export_robot(const ExportRequest& request);

}  // namespace robocal::app
