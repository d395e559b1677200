// `robocal wizard`: the guided calibration for an operator (front end of app/src/wizard/).
#include "cli/command_registry.hpp"
#include "wizard/wizard.hpp"

#include <fmt/core.h>

#include <memory>

namespace robocal::app {

CommandSpec wizard_command() {
  return {
      "wizard", "Guided calibration: robot, controller, cameras, cell, plan, collect, identify",
      [](CLI::App& cmd) -> CommandAction {
        auto o = std::make_shared<wizard::WizardOptions>();
        auto resume = std::make_shared<std::string>();
        cmd.footer(
            "Walks you through a calibration, one step at a time; each step says what it does, "
            "asks its questions (the default is in [brackets]: Enter takes it), checks its "
            "result and says what to do when something is off:\n"
            "   1 robot       the robot model, and what the calibration can and cannot find\n"
            "   2 controller  connect (serial or tcp:HOST:PORT), firmware, axes; homing optional\n"
            "   3 cameras     open each camera, check the board is seen whole, sharp, exposed\n"
            "   4 cell        cameras, obstacles, safe workspace; the planner's camera suggestion\n"
            "   5 intrinsics  each camera's lens: a camera file, board images, or 'live' views\n"
            "                 (after each view: the image's coverage and what to add)\n"
            "   6 plan        measurement poses, plan.svg preview and a summary\n"
            "   7 safety      every motion checked without moving, the time it takes, then your\n"
            "                 confirmation\n"
            "   8 collection  the robot drives the plan, the cameras record (progress bar)\n"
            "   9 identify    board poses measured, the geometry fitted (rig views: 'live')\n"
            "  10 validate    the error on held-out poses\n"
            "  11 export      the calibrated robot for your controller\n\n"
            "Everything lives in FOLDER: wizard.yaml (the steps done, your answers), cell.yaml, "
            "plan.yaml, plan.svg, session/ (the recorded session, app/SESSION.md), export/. "
            "Stopped or interrupted at any step? `robocal wizard --resume FOLDER` continues "
            "at that step; nothing recorded is lost.\n\n"
            "During collection: Ctrl-C stops the robot at once (resume later, no pose is "
            "taken twice or lost); kill -USR1 PID pauses after the current pose, again to go "
            "on.\n\n"
            "Scripts: --answers FILE gives the answers by key (the key is shown with each "
            "question, e.g. robot.model), as YAML (robot: {model: linear_delta}) or key=value "
            "lines. Without a terminal every question needs an answer (or --defaults for the "
            "ones with a default); a missing one stops the wizard naming its key.\n\n"
            "Examples:\n"
            "  robocal wizard cal1\n"
            "  robocal wizard cal1 --answers answers.yaml\n"
            "  robocal wizard --resume cal1\n"
            "No robot or cameras at hand? `robocal sim-cell` starts a simulated cell and prints "
            "what to answer.\n\n"
            "Exit codes: 0 every step done; 1 a step stopped (it says why and what to do; "
            "--resume continues there); 2 bad command line; 3 a bad input file (answers file, "
            "a folder that is not a wizard folder); 5 a question has no answer and there is no "
            "terminal (the key is named); 130 / 143 interrupted by Ctrl-C / SIGTERM.");
        cmd.add_option("folder", o->folder, "New folder for this calibration");
        cmd.add_option("--resume", *resume, "Continue the wizard run in this folder");
        cmd.add_option("--answers", o->answers, "Answers by key (YAML or key=value lines)");
        cmd.add_flag("--defaults", o->accept_defaults,
                     "Take the default of a question nothing else answers");
        return [o, resume]() {
          if (!resume->empty()) {
            if (!o->folder.empty() && o->folder != *resume) {
              fmt::print(stderr, "error: give either FOLDER or --resume FOLDER\n");
              return static_cast<int>(kExitUsage);
            }
            o->folder = *resume;
            o->resume = true;
          }
          if (o->folder.empty()) {
            fmt::print(stderr, "error: give a FOLDER for the calibration (see --help)\n");
            return static_cast<int>(kExitUsage);
          }
          return wizard::run_wizard(*o);
        };
      }};
}

}  // namespace robocal::app
