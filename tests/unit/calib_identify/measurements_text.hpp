#pragma once
// Parsing measurements-file text in the file-format tests.
#include <string>

#include "robocal/calib/measurements_file.hpp"

namespace robocal::calib::testing {

// The error message for `text` read as "m.yaml", or "" when it parses.
inline std::string measurements_error(const std::string& text) {
  try {
    parse_measurements_yaml(text, "m.yaml");
  } catch (const MeasurementsFileError& e) {
    return e.what();
  }
  return "";
}

}  // namespace robocal::calib::testing
