// `robocal sim-controller`: a simulated robot controller in its own process, speaking G-code
// (Marlin or RepRapFirmware dialect) on a loopback TCP port and a pseudo-terminal, or the open
// link protocol (robotio/OPEN_LINK.md) on the TCP port, with a hidden
// "true" robot and fault injection. Orchestration only: the simulator is robocal_robotio's
// SimController.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/text_lines.hpp"
#include "robocal/robotio/sim_controller.hpp"
#include "session/session_robot.hpp"

#include <fmt/core.h>
#include <fmt/format.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <numbers>
#include <random>

namespace robocal::app {
namespace {

std::atomic<bool> g_sim_stop{false};
extern "C" void on_sim_signal(int /*signal*/) {
  g_sim_stop = true;
}

struct SimCliOptions {
  std::string robot;
  unsigned seed = 0;
  std::string perturbation;
  double length_sigma = 0.5e-3;
  double angle_sigma_deg = 0.2;
  std::string protocol = "gcode";
  std::string open_version = "1.0";
  std::string firmware = "marlin";
  std::string firmware_name;
  bool mute = false;
  int tcp_port = 0;
  bool no_pty = false;
  std::string pty_link;
  int pose_port = 0;
  std::string log = "sim-controller.jsonl";
  double steps_per_mm = 80.0;
  double steps_per_degree = 100.0;
  double noise = 2e-6;
  double backlash = 5e-6;
  double feed = 3000.0;
  double acceleration = 1000.0;
  double busy_interval = 2.0;
  double temperature_interval = 0.0;
  std::string faults;
  std::string fault_script;
  unsigned fault_seed = 1;
  double slow_ms = 250.0;
  std::string kinematics = "axes";
  std::vector<std::string> delta_settings;
  double max_seconds = 0.0;
  bool exit_with_parent = false;
  robotio::SimUrOptions ur;
  bool ur_remote_off = false;
  std::vector<double> ur_tcp_offset;
  bool no_flange_pose = false;
  double flange_noise_mm = 0.0;
  double flange_noise_deg = 0.0;
};

robotio::SimRobot make_sim_robot(const SimCliOptions& o) {
  robotio::SimRobot r;
  const std::string robot_file = resolve_robot(o.robot);
  try {
    r.model = calib::load_robot_file(robot_file);
  } catch (const calib::RobotFileError& e) {
    throw InputError(e.what());
  }
  const Eigen::VectorXd nominal = r.model.nominal_parameters();
  r.truth = nominal;
  if (o.seed != 0) {
    std::mt19937 rng(o.seed);
    r.truth = calib::perturb_parameters(
        nominal, calib::tolerance_sigmas(r.model, o.length_sigma, o.angle_sigma_deg * M_PI / 180.0),
        rng);
  }
  if (!o.perturbation.empty()) {
    for (const core::ContentLine& line : core::read_content_lines(o.perturbation)) {
      try {
        calib::apply_parameter_override(r.model, r.truth, line.text);
      } catch (const std::exception& e) {
        throw InputError(fmt::format("{}:{}: {}", o.perturbation, line.number, e.what()));
      }
    }
  }
  try {
    r.axes = robotio::axes_for_robot(r.model, o.steps_per_mm, o.steps_per_degree);
  } catch (const std::invalid_argument& e) {
    throw InputError(e.what());
  }
  // The firmware's home position is where it believes the endstops are: nominal geometry.
  r.home_readings = calib::readings_from_joint_values(r.model, nominal, r.model.home_actuated());
  // A controller homes before anything else: a robot that cannot stand at its home (loops that do
  // not close: rods too short for the frame, lengths in millimetres) has no pose to report. Said
  // with the file and the cause before the controller announces itself ready, not found by the
  // first client.
  for (const auto& [which, params] :
       {std::pair{"nominal", nominal}, {"true (perturbed)", r.truth}}) {
    const calib::ForwardResult fk =
        calib::forward_kinematics(r.model, params, r.home_readings, r.model.tool);
    if (!fk.closure.ok())
      throw InputError(fmt::format(
          "{}: the {} robot cannot assemble at its home position (actuator readings {}): its "
          "loops do not close there ({}); check its lengths (metres), joint limits and home "
          "values (`robocal kin check {}`)",
          robot_file, which, fmt::join(r.home_readings, ", "), calib::to_string(fk.closure.status),
          robot_file));
  }
  r.noise_sigma = o.noise;
  r.backlash = o.backlash;
  return r;
}

// The delta firmware's own geometry: the robot file's drawing, as its owner entered it, with
// any --delta-setting changes.
robotio::CarriageFrame delta_firmware(const calib::Mechanism& model, robotio::Firmware dialect,
                                      const SimCliOptions& o) {
  const robotio::RobotFileDelta file = robotio::robot_file_delta(model);
  if (!file.problem.empty()) throw InputError("--kinematics delta: " + file.problem);
  robotio::CarriageFrame f;
  f.geometry = robotio::drawing_geometry(file, dialect);
  for (const std::string& item : o.delta_settings) {
    try {
      robotio::apply_delta_setting(f.geometry, item);
    } catch (const std::invalid_argument& e) {
      throw InputError(std::string("--delta-setting: ") + e.what());
    }
  }
  f.endstop_reading = file.endstop_reading;
  f.steps_per_mm = o.steps_per_mm;
  return f;
}

// --faults as the simulator reads it: a spec it cannot read is a bad command line.
CLI::Validator fault_spec_check() {
  return {[](const std::string& spec) {
            try {
              robotio::parse_fault_spec(spec);
              return std::string();
            } catch (const std::invalid_argument& e) {
              return std::string(e.what());
            }
          },
          "FAULTS"};
}

int run_sim_controller(const SimCliOptions& o) {
  robotio::SimOptions s;
  if (o.firmware == "marlin") {
    s.dialect = robotio::Firmware::kMarlin;
  } else if (o.firmware == "rrf" || o.firmware == "reprapfirmware") {
    s.dialect = robotio::Firmware::kRepRapFirmware;
  } else if (o.firmware == "klipper") {
    // Klipper is reached through Moonraker, in its own delta kinematics.
    s.dialect = robotio::Firmware::kKlipper;
    if (o.protocol != "gcode" && o.protocol != "moonraker")
      throw InputError("--firmware klipper is served through Moonraker (--protocol moonraker)");
    if (o.kinematics != "delta")
      throw InputError(
          "--firmware klipper drives a delta in Klipper's kinematics: add "
          "--kinematics delta");
    s.protocol = robotio::SimProtocol::kMoonraker;
  } else {
    throw InputError("--firmware must be marlin, rrf or klipper, got '" + o.firmware + "'");
  }
  if (o.protocol == "open") {
    s.protocol = robotio::SimProtocol::kOpen;
    if (std::sscanf(o.open_version.c_str(), "%d.%d", &s.open_major, &s.open_minor) != 2)
      throw InputError("--open-version must be MAJOR.MINOR, got '" + o.open_version + "'");
  } else if (o.protocol == "ur") {
    s.protocol = robotio::SimProtocol::kUr;
    s.ur = o.ur;
    s.ur.remote_control = !o.ur_remote_off;
    if (!o.ur_tcp_offset.empty())
      std::copy(o.ur_tcp_offset.begin(), o.ur_tcp_offset.end(), s.ur.tcp_offset.begin());
  } else if (o.protocol == "moonraker") {
    if (s.dialect != robotio::Firmware::kKlipper)
      throw InputError(
          "--protocol moonraker serves a Klipper printer: add --firmware klipper "
          "--kinematics delta");
  } else if (o.protocol != "gcode") {
    throw InputError("--protocol must be gcode, open, ur or moonraker, got '" + o.protocol + "'");
  }
  s.firmware_name = o.firmware_name;
  s.mute = o.mute;
  s.tcp_port = o.tcp_port;
  // The open link protocol and the UR's ports are TCP only.
  s.pty = s.protocol == robotio::SimProtocol::kGcode && !o.no_pty;
  s.pty_link = o.pty_link;
  s.pose_port = o.pose_port;
  s.log_path = o.log;
  s.busy_interval = o.busy_interval;
  s.temperature_interval = o.temperature_interval;
  s.feed = o.feed;
  s.acceleration = o.acceleration;
  s.max_seconds = o.max_seconds;
  s.exit_with_parent = o.exit_with_parent;
  s.flange_pose = !o.no_flange_pose;
  s.flange_noise_m = o.flange_noise_mm * 1e-3;
  s.flange_noise_rad = o.flange_noise_deg * std::numbers::pi / 180.0;
  s.seed = o.seed + 1;
  try {
    s.faults = robotio::parse_fault_spec(o.faults);
    if (!o.fault_script.empty()) robotio::load_fault_script(o.fault_script, s.faults);
  } catch (const std::invalid_argument& e) {
    throw InputError(e.what());
  }
  s.faults.seed = o.fault_seed;
  s.faults.slow_seconds = o.slow_ms / 1000.0;

  robotio::SimRobot robot = make_sim_robot(o);
  if (o.kinematics == "delta") {
    s.delta = delta_firmware(robot.model, s.dialect, o);
    // The firmware homes to its endstops (Marlin then backs off by M666).
    for (int i = 0; i < 3; ++i)
      robot.home_readings[i] = s.delta->endstop_reading[static_cast<std::size_t>(i)] -
                               robotio::homing_backoff(s.delta->geometry, i) / 1000.0;
  }
  const std::string robot_name = robot.model.name;
  const std::string letters = robot.axes.letters;
  robotio::SimController sim(std::move(robot), s);
  try {
    sim.start();
  } catch (const std::runtime_error& e) {
    throw InputError(e.what());
  }
  // Announce like a board appearing on the bus; tools parse these lines.
  const std::string speaks =
      s.protocol == robotio::SimProtocol::kOpen
          ? fmt::format("open link protocol {}.{}", s.open_major, s.open_minor)
      : s.protocol == robotio::SimProtocol::kUr
          ? std::string("Universal Robots (RTDE, secondary interface, dashboard server)")
      : s.protocol == robotio::SimProtocol::kMoonraker
          ? std::string("Klipper in delta kinematics behind Moonraker (JSON-RPC on a WebSocket)")
          : fmt::format("{} dialect{}", robotio::to_string(s.dialect),
                        s.delta ? " in delta kinematics" : "");
  fmt::print("robocal sim-controller: {}, robot {} (axes {}), truth {}\n", speaks, robot_name,
             letters,
             o.seed != 0 ? fmt::format("perturbed with seed {}", o.seed) : std::string("nominal"));
  if (!sim.tcp_address().empty()) fmt::print("tcp {}\n", sim.tcp_address());
  if (!sim.pty_path().empty()) fmt::print("pty {}\n", sim.pty_path());
  if (!o.pty_link.empty()) fmt::print("pty-link {}\n", o.pty_link);
  if (!sim.pose_address().empty()) fmt::print("pose {}\n", sim.pose_address());
  if (!sim.ur_address().empty()) fmt::print("ur {}\n", sim.ur_address());
  if (s.protocol == robotio::SimProtocol::kMoonraker)
    fmt::print("moonraker moonraker:{}\n", sim.tcp_address());
  if (!o.log.empty()) fmt::print("log {}\n", o.log);
  fmt::print("ready\n");
  std::fflush(stdout);

  g_sim_stop = false;
  struct sigaction sa {};
  sa.sa_handler = on_sim_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  sim.run(g_sim_stop);
  const robotio::SimCounters c = sim.counters();
  fmt::print(stderr, "sim-controller: {} lines, {} motions, {} stops, {} connections\n", c.lines,
             c.motions, c.stops, c.connections);
  return kExitOk;
}

}  // namespace

CommandSpec sim_controller_command() {
  return {"sim-controller",
          "Simulated robot controller (G-code over TCP and a pseudo-terminal) for tests and demos",
          [](CLI::App& cmd) -> CommandAction {
            auto o = std::make_shared<SimCliOptions>();
            cmd.description(
                "Runs a simulated printer-style controller holding a hidden \"true\" robot (the\n"
                "robot file with perturbed geometry, stepper quantisation, backlash, actuator\n"
                "noise, trapezoidal move times). It speaks G-code (Marlin or RepRapFirmware\n"
                "dialect, one G-code axis per actuator: X Y Z U V W A B C, mm or degrees) on a\n"
                "loopback TCP port and on a pseudo-terminal, as a USB board appears, and prints:\n"
                "  tcp 127.0.0.1:PORT / pty /dev/pts/N / pose 127.0.0.1:PORT / ready\n"
                "The pose channel serves the TRUE end-effector pose (send \"pose\\n\", get one\n"
                "JSON line) for simulated cameras only. Every received line and every motion is\n"
                "logged as JSON lines (--log). Faults: --faults drop=0.05,busy=0.05,... or\n"
                "all=0.05; kinds: drop busy error stall corrupt lost_ok resend slow garbage\n"
                "partial; --fault-script FILE for '<command index> <kind>' lines.\n"
                "--protocol open serves the open link protocol (JSON lines, robotio/OPEN_LINK.md)\n"
                "on the TCP port instead; its faults: drop busy error stall lost_ok slow garbage.\n"
                "--protocol ur serves a Universal Robots controller: RTDE on the TCP port,\n"
                "URScript (movej, stopj) on --secondary-port, the dashboard server on\n"
                "--dashboard-port, announced as 'ur ur:127.0.0.1:RTDE:SECONDARY:DASHBOARD' (a\n"
                "--link address); its faults (on movej): drop error stall slow (late RTDE\n"
                "packages) missing (RTDE packages not sent) pstop (a protective stop).\n"
                "--firmware klipper --kinematics delta serves a Klipper delta printer behind\n"
                "Moonraker's JSON-RPC API on a WebSocket (ws://127.0.0.1:PORT/websocket),\n"
                "announced as 'moonraker moonraker:127.0.0.1:PORT' (a --link address); its\n"
                "faults (on printer.gcode.script): drop error slow shutdown (Klippy halts).\n"
                "Its read replies carry the true robot's base -> flange pose (capability\n"
                "flange_pose, as an accurate industrial controller reports it; --flange-noise-mm\n"
                "and --flange-noise-deg add noise, --no-flange-pose leaves the capability out).\n"
                "Stops on Ctrl-C or SIGTERM. Exit codes: 0 ok, 2 bad command line, 3 bad input.");
            cmd.add_option("--robot", o->robot, "Robot file or library robot name")->required();
            cmd.add_option("--seed", o->seed,
                           "Perturb the true geometry with this seed (0 = nominal truth)");
            cmd.add_option("--perturbation", o->perturbation,
                           "File of NAME=VALUE lines setting true parameters");
            cmd.add_option("--length-sigma", o->length_sigma, "Perturbation of lengths, m");
            cmd.add_option("--angle-sigma", o->angle_sigma_deg, "Perturbation of angles, deg");
            cmd.add_option("--protocol", o->protocol,
                           "gcode (TCP and pty), open (the open link protocol, "
                           "robotio/OPEN_LINK.md, TCP only) or ur (Universal Robots: RTDE, "
                           "secondary interface, dashboard server); moonraker comes with "
                           "--firmware klipper")
                ->check(CLI::IsMember({"gcode", "open", "ur", "moonraker"}));
            cmd.add_option("--secondary-port", o->ur.secondary_port,
                           "ur: URScript port (0 = any free; 30002 on a real UR)")
                ->check(CLI::Range(0, 65535));
            cmd.add_option("--dashboard-port", o->ur.dashboard_port,
                           "ur: dashboard server port (0 = any free; 29999 on a real UR)")
                ->check(CLI::Range(0, 65535));
            cmd.add_flag("--ur-remote-off", o->ur_remote_off,
                         "ur: the pendant is in local control (URScript is ignored)");
            cmd.add_option("--ur-speed-slider", o->ur.speed_fraction,
                           "ur: the pendant's speed slider, 0..1")
                ->check(CLI::Range(0.0, 1.0));
            cmd.add_flag("--ur-protective-stop", o->ur.protective_stop,
                         "ur: start in a protective stop");
            cmd.add_option("--ur-unknown-output", o->ur.unknown_outputs,
                           "ur: an RTDE output this controller's software predates (answered "
                           "NOT_FOUND); repeatable");
            cmd.add_option("--ur-tcp-offset", o->ur_tcp_offset,
                           "ur: the active TCP, flange -> TCP: x,y,z (m),rx,ry,rz (rotation "
                           "vector, rad)")
                ->expected(6)
                ->delimiter(',');
            cmd.add_option("--ur-unlock-delay", o->ur.unlock_delay,
                           "ur: seconds after a protective stop before it may be unlocked")
                ->check(CLI::Range(0.0, 60.0));
            cmd.add_option("--open-version", o->open_version,
                           "Open protocol version the controller speaks (MAJOR.MINOR)");
            cmd.add_option("--firmware", o->firmware,
                           "marlin, rrf or klipper (through Moonraker, delta kinematics)")
                ->check(CLI::IsMember({"marlin", "rrf", "reprapfirmware", "klipper"}));
            cmd.add_option("--kinematics", o->kinematics,
                           "axes (one G-code axis per actuator) or delta (the firmware's own "
                           "delta kinematics, M665/M666 from the robot file's drawing)")
                ->check(CLI::IsMember({"axes", "delta"}));
            cmd.add_option("--delta-setting", o->delta_settings,
                           "Change one figure of the delta firmware's geometry, NAME=VALUE (mm, "
                           "deg): L, L_A, L_B, L_C, R, H, X, Y, Z, M666_X, M666_Y, M666_Z");
            cmd.add_option("--firmware-name", o->firmware_name,
                           "Replace the M115 firmware name (to test unknown firmwares)");
            cmd.add_flag("--mute", o->mute, "Accept connections but never answer");
            cmd.add_option("--tcp-port", o->tcp_port, "TCP port (0 = any free, -1 = none)")
                ->check(CLI::Range(-1, 65535));
            cmd.add_flag("--no-pty", o->no_pty, "Do not open a pseudo-terminal");
            cmd.add_option("--pty-link", o->pty_link,
                           "Keep a symlink here to the current pty (it changes after a drop)");
            cmd.add_option("--pose-port", o->pose_port,
                           "TCP port of the true-pose channel (0 = any free, -1 = none)")
                ->check(CLI::Range(-1, 65535));
            cmd.add_option("--log", o->log, "JSONL log of every line and motion");
            cmd.add_option("--steps-per-mm", o->steps_per_mm, "Prismatic actuators")
                ->check(CLI::Range(0.01, 1e6));
            cmd.add_option("--steps-per-degree", o->steps_per_degree, "Revolute actuators")
                ->check(CLI::Range(0.01, 1e6));
            cmd.add_option("--noise", o->noise, "Actuator repeatability (1 sigma), readings")
                ->check(CLI::Range(0.0, 1.0));
            cmd.add_option("--backlash", o->backlash, "Backlash, readings")
                ->check(CLI::Range(0.0, 1.0));
            cmd.add_option("--feed", o->feed, "Default feed, G-code units/min");
            cmd.add_option("--acceleration", o->acceleration, "Default, G-code units/s^2");
            cmd.add_option("--busy-interval", o->busy_interval,
                           "Seconds between busy: keep-alives (Marlin; M113 changes it)");
            cmd.add_option("--temperature-interval", o->temperature_interval,
                           "Auto-report temperatures every N s (0 = off)");
            cmd.add_option("--faults", o->faults, "Fault rates, e.g. all=0.05")
                ->check(fault_spec_check());
            cmd.add_option("--fault-script", o->fault_script, "Scripted faults file");
            cmd.add_option("--fault-seed", o->fault_seed, "Seed of the fault draws");
            cmd.add_option("--slow-ms", o->slow_ms, "Delay of a slow reply, ms");
            cmd.add_option("--max-seconds", o->max_seconds,
                           "Exit after this long (0 = until stopped)");
            cmd.add_flag("--no-flange-pose", o->no_flange_pose,
                         "Open protocol: no flange_pose capability (a controller that reports "
                         "actuator positions only)");
            cmd.add_option("--flange-noise-mm", o->flange_noise_mm,
                           "Open protocol: noise of the reported flange position (1 sigma per "
                           "axis, mm)")
                ->check(CLI::Range(0.0, 100.0));
            cmd.add_option("--flange-noise-deg", o->flange_noise_deg,
                           "Open protocol: noise of the reported flange rotation (1 sigma per "
                           "axis, degrees)")
                ->check(CLI::Range(0.0, 10.0));
            cmd.add_flag("--exit-with-parent", o->exit_with_parent,
                         "Exit when standard input closes (a pipe from the starting process: "
                         "robocal demo and the tests start it so)");
            return [o] { return run_sim_controller(*o); };
          }};
}

}  // namespace robocal::app
