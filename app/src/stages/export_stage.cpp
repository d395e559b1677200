// `robocal export` (export_stage.hpp).
#include "stages/export_stage.hpp"

#include "session/results_layout.hpp"

#include "robocal/calib/firmware_delta.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/calib/serial_exports.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/input_error.hpp"

#include <fmt/core.h>

#include <filesystem>
#include <stdexcept>

namespace robocal::app {
namespace fs = std::filesystem;

const std::vector<std::string>& export_formats() {
  static const std::vector<std::string> formats = {"klipper", "marlin", "rrf", "urdf", "dh"};
  return formats;
}

namespace {

struct ExportSource {
  std::string robot_file;  // the file the model is read from
  std::string kind;        // "session" or "robot_file"
};

// A session exports its calibrated robot; anything else must be a robot file.
ExportSource resolve(const std::string& input) {
  if (!fs::exists(input)) throw core::InputError(input + ": no such session folder or robot file");
  if (!fs::is_directory(input)) return {input, "robot_file"};
  const ResultsLayout results{input};
  if (!fs::exists(results.calibrated_robot()))
    throw core::InputError(fmt::format(
        "{}: no identification results ({} is missing{}): run `robocal identify {}` first", input,
        ResultsLayout::kCalibratedRobot,
        fs::exists(results.identification()) ? "; the last identification did not produce one" : "",
        input));
  return {results.calibrated_robot().string(), "session"};
}

calib::DeltaFirmware firmware_of(const std::string& format) {
  if (format == "marlin") return calib::DeltaFirmware::kMarlin;
  if (format == "rrf") return calib::DeltaFirmware::kReprapFirmware;
  return calib::DeltaFirmware::kKlipper;
}

}  // namespace

nlohmann::json export_robot(const ExportRequest& request) {
  const ExportSource source = resolve(request.input);
  const calib::Mechanism model = calib::load_robot_file(source.robot_file);
  const Eigen::VectorXd params = model.nominal_parameters();
  nlohmann::json report = {{"input", request.input},
                           {"source", source.kind},
                           {"robot_file", source.robot_file},
                           {"robot", model.name},
                           {"format", request.format}};
  const auto refuse = [&](const std::string& why) {
    return core::InputError(
        fmt::format("{}: cannot export as {}: {}", request.input, request.format, why));
  };
  std::string text;
  if (request.format == "urdf" || request.format == "dh") {
    try {
      text = request.format == "urdf" ? calib::urdf_text(model, params)
                                      : calib::dh_table_text(model, params);
    } catch (const std::invalid_argument& e) {
      throw refuse(e.what());
    }
  } else {
    const calib::DeltaFirmware firmware = firmware_of(request.format);
    if (const std::string why = calib::firmware_delta_mismatch(model, firmware); !why.empty())
      throw refuse(why);
    const calib::FirmwareDeltaFit fit = calib::fit_firmware_delta(model, params, firmware);
    text = calib::firmware_delta_text(fit, model.name);
    nlohmann::json settings = nlohmann::json::object();
    for (const auto& [name, value] : calib::firmware_delta_settings(fit)) settings[name] = value;
    report["firmware"] = calib::to_string(firmware);
    report["settings"] = settings;
    report["settings_units"] = "mm and degrees (the firmware's)";
    report["residual_rms_m"] = fit.residual_rms;
    report["residual_max_m"] = fit.residual_max;
    report["workspace_samples"] = fit.readings.size();
    report["endstop_readings_m"] = fit.model.endstop_reading;
    report["firmware_frame"] = {{"x_m", fit.frame.x},
                                {"y_m", fit.frame.y},
                                {"roll_rad", fit.frame.roll},
                                {"pitch_rad", fit.frame.pitch}};
  }
  report["text"] = text;
  if (!request.out.empty()) {
    core::write_file_atomic(request.out, text);
    report["out"] = request.out;
  }
  report["status"] = "ok";
  return report;
}

}  // namespace robocal::app
