// `robocal sim-cell`: a simulated cell (controller and cameras) to try the wizard and `collect`
// on without hardware. Orchestration only: live/sim_cell.hpp.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "live/sim_cell.hpp"

#include <memory>

namespace robocal::app {

CommandSpec sim_cell_command() {
  return {"sim-cell",
          "A simulated cell (robot controller and cameras) to try the wizard without hardware",
          [](CLI::App& cmd) -> CommandAction {
            auto o = std::make_shared<SimCellOptions>();
            cmd.description(
                "Starts a simulated cell as real hardware appears: `robocal sim-controller` (a\n"
                "controller speaking G-code over TCP and a pseudo-terminal, holding a true robot\n"
                "whose geometry differs from the robot file's by realistic tolerances) and the\n"
                "cell's cameras, served as GigE Vision cameras through Aravis' fake camera where\n"
                "the machine gives each its own address (otherwise as sim:FILE cameras that the\n"
                "program opening them renders), each showing the board on the robot's tool. The\n"
                "folder gets what an operator has: cell/ (cell file, datasheet intrinsics, board\n"
                "files), calibration_views/ (images of the calibration board held in front of\n"
                "the cameras) and wizard_answers.yaml; simulator/ keeps the true robot and\n"
                "cameras for validation only. It prints what to answer in `robocal wizard` and\n"
                "runs until Ctrl-C or SIGTERM. Exit codes: 0 stopped, 1 the simulated\n"
                "controller ended, 2 bad command line, 3 bad input.");
            cmd.add_option("--robot", o->robot, "Library robot name or robot file")
                ->capture_default_str();
            cmd.add_option("--seed", o->seed, "Seed of the true robot and cameras (1 or more)")
                ->capture_default_str();
            cmd.add_option("--out", o->out,
                           "The cell's folder (default: ./sim-cell-ROBOT-seedN; an earlier "
                           "sim-cell folder of the same robot and seed is reused)");
            cmd.add_flag("--quick", o->quick, "Smaller images (faster, less accurate)");
            cmd.add_flag("--idealised-truth", o->idealised_truth,
                         "A rigid true robot that differs from its file only where the model can "
                         "follow (no unmodelled error, no elastic sag)");
            cmd.add_flag(
                "--in-process", [o](std::int64_t) { o->gige = false; },
                "Do not serve GigE cameras: every camera is a sim:FILE camera");
            cmd.add_option("--firmware", o->firmware,
                           "The G-code controller's firmware: marlin, rrf, or klipper (a delta "
                           "printer reached through Moonraker)")
                ->check(CLI::IsMember({"marlin", "rrf", "klipper"}))
                ->capture_default_str();
            cmd.add_option("--gcode-mode", o->gcode_mode,
                           "A delta printer: native (its firmware's own delta kinematics, as "
                           "printers run) or raw (one G-code axis per motor)")
                ->check(CLI::IsMember({"native", "raw"}))
                ->capture_default_str();
            cmd.add_option(
                   "--protocol", o->protocol,
                   "What the controller speaks: gcode (the --firmware dialect) or open (the "
                   "open link protocol, robotio/OPEN_LINK.md, reporting the flange pose "
                   "as an industrial controller does)")
                ->check(CLI::IsMember({"gcode", "open"}))
                ->capture_default_str();
            cmd.add_option("--port", o->tcp_port, "The controller's TCP port (0: any free one)")
                ->check(CLI::Range(0, 65535));
            cmd.add_option("--max-seconds", o->max_seconds, "Stop after this long (0: at Ctrl-C)")
                ->check(CLI::NonNegativeNumber);
            return [o] { return run_sim_cell(*o); };
          }};
}

}  // namespace robocal::app
