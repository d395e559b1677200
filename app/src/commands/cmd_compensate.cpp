// `robocal compensate SESSION (--targets FILE | --gcode FILE --out FILE)`: the calibrated robot
// turned into commands for a controller that knows only the nominal model.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "stages/stages.hpp"

#include <fmt/core.h>

#include <memory>

namespace robocal::app {

CommandSpec compensate_command() {
  return {
      "compensate",
      "Correct a robot's commands with its calibrated model (targets or a G-code program)",
      [](CLI::App& cmd) -> CommandAction {
        auto o = std::make_shared<CompensateOptions>();
        auto json = std::make_shared<std::string>();
        auto tolerance_um = std::make_shared<double>(10.0);
        cmd.footer(
            "A controller computes its motions with the robot's NOMINAL model (the drawing), so "
            "the real robot misses every target by its geometry errors. This command uses the "
            "session's calibrated model (results/identification.json, written by `robocal "
            "identify` or `robocal demo`) to correct what the controller is told:\n\n"
            "  --targets FILE  actuator commands for a list of task-space targets: the "
            "calibrated inverse kinematics of each target, with its assembly-mode verdict "
            "(ok, ambiguous = near a singularity, other_mode, unreachable). Also the same "
            "readings as a task-space command for a nominal controller (commanded_*). A target "
            "that is unreachable or only reachable on another assembly mode is listed with its "
            "line and the reason and gets no command; the exit code is then 1.\n"
            "     CSV: one target per line, 'x, y, z' in metres (serial arms: 'x, y, z, rx, ry, "
            "rz', a rotation vector in radians, as `robocal kin ik`); '#' comments and a header "
            "line are allowed. YAML: 'targets: [[x, y, z], ...]'.\n"
            "  --gcode FILE --out FILE  rewrite a program written for the nominal model "
            "(printer-style robots such as linear_delta: G0/G1, G2/G3 arcs, G90/G91, G92, "
            "M82/M83; millimetres) so that, run by the unchanged controller, the tool goes where "
            "the program meant: every point p becomes FK_nominal(IK_calibrated(p)), arcs are cut "
            "into chords and every move is subdivided until the predicted tool path stays within "
            "--tolerance of the meant line. Feeds, comments and other commands are kept; "
            "extrusion is shared over the pieces. A line that cannot be compensated (malformed, "
            "unreachable, a move from an unknown position) is an error naming the line, and "
            "--out is then not touched.\n"
            "     The output is written in the units the controller reads (--axes, else the "
            "robot file's `controller: {gcode_axes}`; neither: refused): 'tool' -- X Y Z are the "
            "tool position (a firmware with the robot's kinematics, e.g. a printer's delta "
            "kinematics); 'actuators' -- one axis per actuator, X Y Z U V W A B C in actuator "
            "order, mm or degrees (raw-axis mode, as robocal's G-code link drives a robot, e.g. "
            "the rotary Delta): every point becomes the calibrated inverse kinematics' actuator "
            "positions, moves are subdivided until the axes' straight interpolation keeps the "
            "tool within --tolerance of the meant path, F becomes the axes' rate.\n"
            "     --firmware klipper|marlin|rrf: the printer runs `robocal export SESSION "
            "--format F`'s delta settings, not the drawing: the program (in the firmware's "
            "frame) is rewritten for them, carrying what their smaller model leaves.\n\n"
            "Coordinates are the robot file's base frame (not the cameras'): the calibrated "
            "model's base placement is replaced by the file's; the tool is the robot file's tool "
            "on the identified geometry (the end-effector board's mount is the board's, not the "
            "tool's).\n\n"
            "Examples:\n"
            "  robocal compensate session/ --targets targets.csv --out commands.csv\n"
            "  robocal compensate session/ --gcode part.gcode --out part_compensated.gcode "
            "--tolerance 5\n\n"
            "Exit codes: 0 every target compensated, 1 some target refused, 2 bad command "
            "line, 3 bad input (no identification results, malformed file or G-code line).");
        cmd.add_option("session", o->session, "Session folder with identification results")
            ->required();
        auto* targets = cmd.add_option(
            "--targets", o->targets, "Targets file (.csv or .yaml): actuator commands per target");
        auto* gcode = cmd.add_option("--gcode", o->gcode,
                                     "G-code program written for the nominal model: rewrite it");
        targets->excludes(gcode);
        gcode->excludes(targets);
        cmd.add_option("--out", o->out,
                       "Output file (written atomically); targets: stdout when omitted");
        cmd.add_option("--tolerance", *tolerance_um,
                       "G-code: largest tool error between emitted points (µm)")
            ->check(CLI::Range(0.1, 1000.0))
            ->capture_default_str();
        cmd.add_option("--route", o->route,
                       "Which calibrated model: pose (6-D pose route) or pixel (camera in the "
                       "loop)")
            ->check(CLI::IsMember({"pose", "pixel"}))
            ->capture_default_str();
        cmd.add_option("--axes", o->axes,
                       "G-code: the controller's axis words are the tool position (tool) or the "
                       "actuators (actuators); default: the robot file's controller.gcode_axes")
            ->check(CLI::IsMember({"tool", "actuators"}));
        cmd.add_option("--firmware", o->firmware,
                       "The controller runs `robocal export SESSION --format F`'s delta settings "
                       "(klipper, marlin, rrf): compensate what they leave; coordinates are then "
                       "the firmware's frame")
            ->check(CLI::IsMember({"klipper", "marlin", "rrf"}));
        cmd.add_option("--robot", o->robot_override,
                       "Robot file to use instead of the session's (checked against it)");
        cmd.add_option("--json", *json, "Write the JSON report here ('-' = stdout)");
        return [o, json, tolerance_um]() {
          if (o->targets.empty() && o->gcode.empty()) {
            fmt::print(stderr,
                       "error: give --targets FILE or --gcode FILE --out FILE (see robocal "
                       "compensate --help)\n");
            return int{kExitUsage};
          }
          if (*json == "-" && o->out.empty()) {
            fmt::print(stderr, "error: --json - takes stdout: give --out FILE for the output\n");
            return int{kExitUsage};
          }
          o->tolerance = *tolerance_um * 1e-6;
          PipelineLog log;
          // The command output may take stdout (targets without --out, or --json -).
          log.out = (o->gcode.empty() && o->out.empty()) || *json == "-" ? stderr : stdout;
          const auto report = compensate_session(*o, log);
          if (report.value("mode", "") == "targets")
            fmt::print(log.out, "compensate: {} targets, {} refused{}\n",
                       report.value("targets", 0), report.value("refused", 0),
                       o->out.empty() ? "" : " -> " + o->out.string());
          if (!json->empty()) write_json(report, *json);
          return exit_code_of(report);
        };
      }};
}

}  // namespace robocal::app
