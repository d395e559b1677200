// `robocal export SESSION_OR_ROBOT_FILE --format F`: the calibrated robot for a controller or
// another tool (stages/export_stage.hpp; the formats are calib's).
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "stages/export_stage.hpp"

#include <fmt/core.h>

#include <memory>

namespace robocal::app {

CommandSpec export_command() {
  return {"export",
          "Write the calibrated robot as Klipper, Marlin or RepRapFirmware delta "
          "settings, a URDF or a DH table",
          [](CLI::App& cmd) -> CommandAction {
            auto input = std::make_shared<std::string>();
            auto format = std::make_shared<std::string>();
            auto out = std::make_shared<std::string>();
            auto json = std::make_shared<std::string>();
            cmd.footer(
                "INPUT is a session folder (its results/calibrated_robot.yaml, written by "
                "`robocal identify`) or a robot file.\n\n"
                "A session is exported in the user's frames: the robot file's own base frame and "
                "its own tool (the nozzle, the flange) on the calibrated geometry; the "
                "end-effector board the calibration measured and the first camera are written "
                "beside them as frames of their own (URDF links 'board' and 'camera0'; comments "
                "in the firmware settings and the DH table; --json 'frames').\n\n"
                "Linear-delta printers (klipper, marlin, rrf): the firmware knows a smaller delta "
                "model than robocal (towers on one circle, one rod length per tower -- Marlin: "
                "one for all --, endstop offsets). Its settings are fitted by least squares so "
                "that the firmware puts the nozzle where the calibrated model does, over the "
                "workspace, and the error that remains is printed beside them (RMS and max, um): "
                "what the firmware cannot represent (tower tilt, towers off the circle, ...), "
                "beside the firmware with the drawing's settings and robocal's full model; "
                "`robocal compensate SESSION --gcode` carries the rest. "
                "Klipper: [printer] delta_radius and [stepper_a/b/c] angle, arm_length, "
                "position_endstop (paste into printer.cfg). Marlin: M665 L R H X Y Z and M666 X "
                "Y Z (send, then M500). RepRapFirmware: M665 L R H X Y Z and M666 X Y Z (put in "
                "config.g). The endstops are assumed to trigger at the top of the towers (the "
                "robot file's upper carriage limit); the output says so.\n\n"
                "Serial arms (urdf, dh): urdf writes every body as a link with the same frame "
                "(joint origins xyz/rpy; joint values = the controller's readings; limits, "
                "velocity and effort from the robot file, else pi rad/s and 150 N m, 0.5 m/s and "
                "1000 N, named in a comment); dh prints the "
                "DH or modified-DH table (read from the robot file when its joints are given that "
                "way, else derived from the joint axes; nearly parallel axes are refused, saying "
                "why).\n\n"
                "A robot the format cannot describe (e.g. a rotary Delta for Klipper, a parallel "
                "robot for URDF) or a session without identification results: an error saying "
                "why, exit code 3, nothing written. --out is written atomically (a reader never "
                "sees half a file).\n\n"
                "Examples:\n"
                "  robocal export s1 --format klipper --out printer_delta.cfg\n"
                "  robocal export testdata/robots/ur5.yaml --format urdf --out ur5.urdf\n"
                "  robocal export s1 --format marlin --json -");
            cmd.add_option("input", *input, "Session folder or robot file")->required();
            cmd.add_option("--format", *format, "klipper, marlin, rrf, urdf or dh")
                ->required()
                ->check(CLI::IsMember(export_formats()));
            cmd.add_option("--out", *out, "Write the export here (default: print it)");
            cmd.add_option("--json", *json,
                           "Write the JSON report (settings, residual, text) here ('-' = stdout)");
            return [input, format, out, json]() {
              const nlohmann::json report = export_robot({*input, *format, *out});
              std::FILE* human = *json == "-" ? stderr : stdout;
              if (out->empty()) {
                if (*json != "-") fmt::print(human, "{}", report.at("text").get<std::string>());
              } else {
                fmt::print(human, "wrote {} ({} for '{}')\n", *out, *format,
                           report.at("robot").get<std::string>());
                if (report.contains("residual_rms_m"))
                  fmt::print(human,
                             "residual of {}'s delta model against the calibrated model: RMS "
                             "{:.1f} um, max {:.1f} um\n",
                             report.at("firmware").get<std::string>(),
                             report.at("residual_rms_m").get<double>() * 1e6,
                             report.at("residual_max_m").get<double>() * 1e6);
                if (report.contains("nominal_rms_m"))
                  fmt::print(human,
                             "(with the robot file's drawing: RMS {:.1f} um{}); `robocal "
                             "compensate --firmware {}` carries the rest\n",
                             report.at("nominal_rms_m").get<double>() * 1e6,
                             report.contains("model_fit_rms_m")
                                 ? fmt::format("; robocal's full model fits the measurements to "
                                               "{:.1f} um",
                                               report.at("model_fit_rms_m").get<double>() * 1e6)
                                 : std::string(),
                             *format);
              }
              if (!json->empty()) write_json(report, *json);
              return kExitOk;
            };
          }};
}

}  // namespace robocal::app
