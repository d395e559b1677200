// `robocal export` (export_stage.hpp).
#include "stages/export_stage.hpp"

#include "session/results_layout.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"

#include "robocal/calib/compensation.hpp"
#include "robocal/calib/firmware_delta.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/calib/serial_exports.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/input_error.hpp"

#include <fmt/core.h>

#include <cmath>
#include <filesystem>
#include <stdexcept>

namespace robocal::app {
namespace fs = std::filesystem;

const std::vector<std::string>& export_formats() {
  static const std::vector<std::string> formats = {"klipper", "marlin", "rrf", "urdf", "dh"};
  return formats;
}

namespace {

// The model an export writes: the robot in the user's frames, and the frames a calibration
// measured in beside it.
struct ExportModel {
  calib::Mechanism model;
  Eigen::VectorXd params;
  std::string robot_file;  // the file the parameter values were read from
  std::string kind;        // "session" or "robot_file"
  std::vector<calib::ExtraFrame> extra;
  calib::FirmwareTextNotes notes;
  nlohmann::json frames = nlohmann::json::object();
};

std::string mm(const Eigen::Vector3d& p) {
  return fmt::format("x {:+.3f}, y {:+.3f}, z {:+.3f} mm", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
}

nlohmann::json pose_json(const Eigen::Isometry3d& T) {
  const Eigen::Vector3d p = T.translation();
  const Eigen::Vector3d r = calib::rotation_log(T.linear());
  return {{"translation_m", {p.x(), p.y(), p.z()}}, {"rotation_vector_rad", {r.x(), r.y(), r.z()}}};
}

const std::string& body_name(const calib::Mechanism& model, int body) {
  static const std::string world = "world";
  return body < 0 ? world : model.bodies.at(static_cast<std::size_t>(body)).name;
}

// A session's calibrated robot in the user's frames. Identification works in the measurement
// world (the first camera's frame) with the end-effector board in the measured frame's place
// (session.yaml's target mount replaces that frame's values); a controller or URDF user wants the
// robot's own base frame and its own tool (the nozzle, the flange). The robot's own frames come
// from the session's robot file; the board and the camera are written beside them.
ExportModel session_model(const std::string& input) {
  const Session s = load_session(input);
  const ResultsLayout results{input};
  const SessionRobot robot = session_robot(s, "");
  ExportModel out;
  out.model = robot.model;
  out.kind = "session";
  out.robot_file = results.calibrated_robot().string();
  const calib::Mechanism calibrated = load_robot(out.robot_file);
  bool same = calibrated.parameters.size() == out.model.parameters.size();
  for (std::size_t i = 0; same && i < calibrated.parameters.size(); ++i)
    same = calibrated.parameters[i].name == out.model.parameters[i].name;
  if (!same)
    throw core::InputError(fmt::format(
        "{}: its parameters are not those of the session's robot file {}: identify the session "
        "again (`robocal identify {}`)",
        out.robot_file, robot.file, input));
  const bool mounted = !s.target_mount.empty();
  const calib::UserFrames user =
      calib::user_frames(out.model, calibrated.nominal_parameters(), out.model.nominal_parameters(),
                         robot.frame, mounted);
  out.params = user.params;
  // The model's own values are the calibrated ones, as when the calibrated file itself is read
  // (the firmware fit takes the endstops' readings from them).
  for (std::size_t i = 0; i < out.model.parameters.size(); ++i)
    out.model.parameters[i].value = out.params[static_cast<Eigen::Index>(i)];

  const std::string tool = body_name(out.model, out.model.tool);
  const std::string measured = body_name(out.model, robot.frame);
  const std::string camera = s.cameras.empty() ? std::string("camera 0") : s.cameras.front().name;
  // The base frame's pose in the robot's world (the file's values; identity for the library's).
  const Eigen::VectorXd home =
      calib::readings_from_joint_values(out.model, out.params, out.model.home_actuated());
  const calib::JointState state =
      calib::make_joint_state(out.model, out.params, home, out.model.home_passive());
  const Eigen::Isometry3d world_T_base = calib::frame_pose(out.model, out.params, state, 0);
  const Eigen::Isometry3d base_T_camera = world_T_base.inverse() * user.world_T_measurement;
  out.extra.push_back(
      {"camera0", 0, base_T_camera,
       fmt::format("the session's first camera '{}' as calibrated (the frame the calibration "
                   "measured in; OpenCV axes: x right, y down, z along the optical axis)",
                   camera)});
  out.frames["world"] = "the robot file's world frame (its base frame '" + body_name(out.model, 0) +
                        "' at the file's values)";
  out.frames["tool"] = {{"frame", tool},
                        {"what",
                         "the robot file's tool at its file values, on the calibrated "
                         "bodies before it"}};
  out.frames["camera0"] = {
      {"camera", camera}, {"parent", body_name(out.model, 0)}, {"pose", pose_json(base_T_camera)}};
  out.notes.tool = fmt::format("the robot file's tool frame '{}' (at its file values)", tool);
  out.notes.measured = fmt::format("camera '{}' at {} in the robot's base frame", camera,
                                   mm(base_T_camera.translation()));
  if (mounted) {
    // The board replaced the measured frame's values during identification: written as its own
    // frame, on the same predecessor, where identification found it.
    out.extra.push_back(
        {"board", user.measured_parent, user.parent_T_measured,
         fmt::format("the end-effector board as calibrated (the measured frame, mounted in "
                     "place of '{}' during calibration; not the tool)",
                     measured)});
    out.frames["measured_frame"] = {{"frame", "board"},
                                    {"replaces", measured},
                                    {"parent", body_name(out.model, user.measured_parent)},
                                    {"pose", pose_json(user.parent_T_measured)}};
    out.notes.measured =
        fmt::format("the end-effector board at {} from '{}' (the calibration's measured frame); {}",
                    mm(user.parent_T_measured.translation()),
                    body_name(out.model, user.measured_parent), out.notes.measured);
  } else {
    out.frames["measured_frame"] = {{"frame", measured}};
  }
  // How closely the full calibrated model follows the measurements (identification's fit).
  try {
    const auto ident = nlohmann::json::parse(core::read_text_file(results.identification()));
    const auto& rms = ident.at("result").at("residuals").at("position_rms_m");
    if (rms.is_number()) out.notes.model_rms = rms.get<double>();
  } catch (const std::exception&) {
    // No figure to quote: the settings stand without it.
  }
  out.notes.compensate =
      "`robocal compensate " + input + " --firmware FORMAT --gcode PROGRAM --out OUT`";
  return out;
}

// A session exports its calibrated robot in the user's frames; anything else must be a robot
// file, exported as it is.
ExportModel resolve(const std::string& input) {
  if (!fs::exists(input)) throw core::InputError(input + ": no such session folder or robot file");
  if (fs::is_directory(input)) {
    const ResultsLayout results{input};
    if (!fs::exists(results.calibrated_robot()))
      throw core::InputError(fmt::format(
          "{}: no identification results ({} is missing{}): run `robocal identify {}` first", input,
          ResultsLayout::kCalibratedRobot,
          fs::exists(results.identification()) ? "; the last identification did not produce one"
                                               : "",
          input));
    if (!fs::exists(fs::path(input) / "session.yaml"))
      throw core::InputError(input + ": not a session folder (no session.yaml) nor a robot file");
    return session_model(input);
  }
  ExportModel out;
  out.model = calib::load_robot_file(input);
  out.params = out.model.nominal_parameters();
  out.robot_file = input;
  out.kind = "robot_file";
  out.frames["world"] = "the robot file's world frame";
  out.frames["tool"] = {{"frame", body_name(out.model, out.model.tool)}};
  return out;
}

calib::DeltaFirmware firmware_of(const std::string& format) {
  if (format == "marlin") return calib::DeltaFirmware::kMarlin;
  if (format == "rrf") return calib::DeltaFirmware::kReprapFirmware;
  return calib::DeltaFirmware::kKlipper;
}

}  // namespace

nlohmann::json export_robot(const ExportRequest& request) {
  const ExportModel source = resolve(request.input);
  const calib::Mechanism& model = source.model;
  const Eigen::VectorXd& params = source.params;
  nlohmann::json report = {{"input", request.input},          {"source", source.kind},
                           {"robot_file", source.robot_file}, {"robot", model.name},
                           {"format", request.format},        {"frames", source.frames}};
  const auto refuse = [&](const std::string& why) {
    return core::InputError(
        fmt::format("{}: cannot export as {}: {}", request.input, request.format, why));
  };
  std::string text;
  if (request.format == "urdf" || request.format == "dh") {
    try {
      text = request.format == "urdf" ? calib::urdf_text(model, params, source.extra)
                                      : calib::dh_table_text(model, params, source.extra);
    } catch (const std::invalid_argument& e) {
      throw refuse(e.what());
    }
  } else {
    const calib::DeltaFirmware firmware = firmware_of(request.format);
    if (const std::string why = calib::firmware_delta_mismatch(model, firmware); !why.empty())
      throw refuse(why);
    const calib::FirmwareDeltaFit fit = calib::fit_firmware_delta(model, params, firmware);
    calib::FirmwareTextNotes notes = source.notes;
    if (const auto at = notes.compensate.find("FORMAT"); at != std::string::npos)
      notes.compensate.replace(at, 6, request.format);
    text = calib::firmware_delta_text(fit, model.name, notes);
    nlohmann::json settings = nlohmann::json::object();
    for (const auto& [name, value] : calib::firmware_delta_settings(fit)) settings[name] = value;
    report["firmware"] = calib::to_string(firmware);
    report["settings"] = settings;
    report["settings_units"] = "mm and degrees (the firmware's)";
    report["residual_rms_m"] = fit.residual_rms;
    report["residual_max_m"] = fit.residual_max;
    report["nominal_rms_m"] = fit.nominal_rms;
    report["nominal_max_m"] = fit.nominal_max;
    if (std::isfinite(source.notes.model_rms)) report["model_fit_rms_m"] = source.notes.model_rms;
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
