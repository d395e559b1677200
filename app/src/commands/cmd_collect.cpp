// `robocal collect`: drive a plan's poses on the controller and record the cameras' frames into
// a session folder (front end of app/src/live/collect.cpp).
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "live/collect.hpp"
#include "robocal/robotio/camera_aravis.hpp"
#include "robocal/robotio/camera_v4l2.hpp"

#include <fmt/core.h>

#include <memory>

namespace robocal::app {
namespace {

struct CollectArgs {
  CollectOptions options;
  std::string session;
  std::vector<std::string> cameras;  // NAME=SOURCE
  std::string json;
  bool list_cameras = false;
  bool no_home = false;
  std::string gcode_mode = "auto";
  std::string firmware_geometry = "ask";
};

int list_cameras() {
  int n = 0;
  for (const auto& list : {robotio::discover_aravis_cameras(), robotio::discover_v4l2_cameras()}) {
    for (const auto& c : list) {
      fmt::print("{}:{}  {} {} serial {} ({}; sensor {}x{})\n", c.driver, c.id, c.vendor, c.model,
                 c.serial, c.address, c.sensor_width, c.sensor_height);
      ++n;
    }
  }
  if (n == 0)
    fmt::print("no cameras found (Aravis: GigE Vision / USB3 Vision; V4L2: /dev/video*)\n");
  return kExitOk;
}

int run_collect(CollectArgs& a) {
  if (a.list_cameras) return list_cameras();
  if (a.session.empty()) {
    fmt::print(stderr, "error: give the SESSION folder to record into (see --help)\n");
    return kExitUsage;
  }
  CollectOptions& o = a.options;
  o.session = a.session;
  o.home = !a.no_home;
  // Both words were checked by the command line (IsMember).
  o.gcode_mode = robotio::gcode_mode_from_string(a.gcode_mode).value_or(o.gcode_mode);
  o.firmware_geometry =
      robotio::geometry_choice_from_string(a.firmware_geometry).value_or(o.firmware_geometry);
  for (const std::string& c : a.cameras) {
    const std::size_t eq = c.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == c.size()) {
      fmt::print(stderr,
                 "error: --camera '{}': expected NAME=SOURCE, e.g. --camera left=aravis:SERIAL "
                 "(NAME as in the cell file)\n",
                 c);
      return kExitUsage;
    }
    o.cameras.push_back({c.substr(0, eq), c.substr(eq + 1)});
  }
  if (!o.dry_run && o.link.empty()) {
    fmt::print(stderr,
               "error: --link is required (tcp:HOST:PORT or a serial device such as "
               "/dev/ttyACM0); --dry-run checks the plan without a controller\n");
    return kExitUsage;
  }
  PipelineLog log;
  log.out = human_stream(a.json);
  const CollectOutcome outcome = collect_session(o, log);
  if (!outcome.message.empty()) fmt::print(stderr, "collect: {}\n", outcome.message);
  if (!a.json.empty()) write_json(outcome.summary, a.json);
  return collect_exit_code(outcome);
}

}  // namespace

CommandSpec collect_command() {
  return {
      "collect", "Drive the robot through a plan and record every camera at each pose",
      [](CLI::App& cmd) -> CommandAction {
        auto a = std::make_shared<CollectArgs>();
        CollectOptions& o = a->options;
        cmd.footer(
            "Moves the robot through the poses of a plan (`robocal plan`) over its controller "
            "link and records, at each pose, the controller's actuator readings before and "
            "after the shots and `--shots` frames from every camera of the cell, into a "
            "session folder (app/SESSION.md): poses/pose_NNN/ with pose.yaml and "
            "<camera>_<k>.png. Each pose folder appears whole or not at all.\n\n"
            "Safety: every motion passes the safety guard first: actuator limits of the robot "
            "file, the cell's declared workspace, its obstacles with the cell's clearance "
            "(the planner's collision model), and --speed / --acceleration. Before the first "
            "motion (homing included) the command shows what it will do and asks you to type "
            "yes; scripts give --yes instead (without a terminal and without --yes nothing "
            "moves). Ctrl-C or SIGTERM stops the robot at once; a second Ctrl-C kills the "
            "program. The p key (on a terminal) or SIGUSR1 (kill -USR1 PID) pauses after the "
            "current pose; pressing p or sending SIGUSR1 again goes on.\n\n"
            "Interrupted? Every recorded pose is complete on disk; run the same command with "
            "--resume to record the rest (no pose is taken twice).\n\n"
            "Examples:\n"
            "  robocal collect --list-cameras\n"
            "  robocal collect s1 --cell cell.yaml --plan plan.yaml --dry-run\n"
            "  robocal collect s1 --cell cell.yaml --plan plan.yaml --link /dev/ttyACM0 \\\n"
            "      --camera left=aravis:ID1 --camera right=aravis:ID2\n"
            "  robocal collect s1 --cell cell.yaml --plan plan.yaml --link tcp:10.0.0.5:23 \\\n"
            "      --camera left=v4l2:/dev/video0 --resume\n\n"
            "Exit codes: 0 every pose recorded (or a dry run with every motion allowed), 1 "
            "stopped early, refused or cancelled (what is recorded stays), 2 bad command "
            "line, 3 a bad input file, 130/143 interrupted by Ctrl-C / SIGTERM.");
        cmd.add_option("session", a->session, "Session folder to create (or continue)");
        cmd.add_option("--cell", o.cell, "Cell file: cameras, obstacles, workspace, target");
        cmd.add_option("--plan", o.plan, "Plan file written by `robocal plan`");
        cmd.add_option("--robot", o.robot,
                       "Library robot name or robot file (default: the cell's)");
        cmd.add_option("--link", o.link,
                       "Controller: tcp:HOST:PORT or a serial device (/dev/ttyACM0) for G-code; "
                       "open:HOST:PORT for an open link adapter (robotio/OPEN_LINK.md); manual: "
                       "the operator moves the robot and types its readings");
        cmd.add_option("--baud", o.baud, "Serial baud rate")->check(CLI::PositiveNumber);
        cmd.add_option("--steps-per-mm", o.steps_per_mm,
                       "Controller steps per mm of prismatic actuators (its M92 setting)")
            ->check(CLI::PositiveNumber);
        cmd.add_option("--steps-per-degree", o.steps_per_degree,
                       "Controller steps per degree of revolute actuators")
            ->check(CLI::PositiveNumber);
        cmd.add_option("--reply-timeout", o.reply_timeout_s,
                       "Seconds of controller silence before a command is retried")
            ->check(CLI::Range(0.05, 60.0));
        cmd.add_flag("--accept-unknown-firmware", o.accept_unknown_firmware,
                     "Talk to a controller whose firmware is neither Marlin nor RepRapFirmware");
        cmd.add_flag("--unlock-protective-stop", o.unlock_protective_stop,
                     "UR link: unlock a protective stop through the dashboard server before the "
                     "next move (the start confirmation says so; inspect each stop's cause)");
        cmd.add_option("--gcode-mode", a->gcode_mode,
                       "auto (default: a delta printer in its own kinematics when its firmware "
                       "reports delta geometry, else one axis per motor), native, or raw")
            ->check(CLI::IsMember({"auto", "native", "raw"}));
        cmd.add_option("--firmware-geometry", a->firmware_geometry,
                       "When the firmware's delta geometry differs from the robot file's: ask "
                       "(refuse, naming each difference), firmware or robot-file (trust it)")
            ->check(CLI::IsMember({"ask", "firmware", "robot-file"}));
        cmd.add_option("--camera", a->cameras,
                       "NAME=SOURCE per cell camera: aravis:ID|SERIAL|IP or v4l2:/dev/videoN");
        cmd.add_flag("--list-cameras", a->list_cameras, "List the cameras found and exit");
        cmd.add_option("--speed", o.speed,
                       "Actuator speed limit per second (m/s prismatic, rad/s revolute)")
            ->check(CLI::Range(1e-6, 10.0));
        cmd.add_option("--acceleration", o.acceleration,
                       "Actuator acceleration limit per second squared")
            ->check(CLI::Range(1e-6, 1000.0));
        cmd.add_option("--shots", o.shots, "Frames per camera per pose (>= 2: the stillness test)")
            ->check(CLI::Range(2, 20));
        cmd.add_flag("--no-home", a->no_home, "Do not home the controller first");
        cmd.add_flag("--dry-run", o.dry_run,
                     "Check every motion through the safety guard; move nothing, record nothing");
        cmd.add_flag("--resume", o.resume, "Continue an interrupted collection in SESSION");
        cmd.add_flag("--yes", o.yes, "Confirm the motion without a prompt (scripts)");
        cmd.add_flag("--accept-infeasible-plan", o.accept_infeasible_plan,
                     "Collect a plan whose status is infeasible (refused otherwise: the planner "
                     "found too few feasible poses)");
        cmd.add_option("--json", a->json, "Write the JSON summary here ('-' = stdout)");
        return [a]() { return run_collect(*a); };
      }};
}

}  // namespace robocal::app
