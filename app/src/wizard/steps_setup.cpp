// The first three steps: the robot model (and what can be identified, before anything moves),
// the controller (connected, firmware identified, optionally homed), the cameras (opened, one
// frame checked for the target, sharpness and exposure).
#include "cli/cli_common.hpp"
#include "robocal/calib/identifiability.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/robotio/camera_aravis.hpp"
#include "robocal/robotio/camera_checks.hpp"
#include "robocal/robotio/camera_open.hpp"
#include "robocal/robotio/controller_probe.hpp"
#include "robocal/robotio/delta_firmware.hpp"
#include "robocal/robotio/gcode_link.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/link_factory.hpp"
#include "robocal/robotio/safety_guard.hpp"
#include "robocal/vision/apriltag_detector.hpp"
#include "session/session_robot.hpp"
#include "wizard/live_views.hpp"
#include "wizard/step.hpp"

#include <fmt/core.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <random>
#include <sstream>

namespace robocal::app::wizard {
namespace {

namespace fs = std::filesystem;

// Which of the robot file's free parameters 6-D board poses (what the cameras measure) can
// separate, from poses spread over the reachable workspace at the nominal geometry.
void explain_identifiability(const WizardContext& ctx, const calib::Mechanism& model) {
  const calib::MechanismPredictor predictor(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  std::mt19937 rng(1);
  const auto poses = calib::sample_actuators(predictor, {nominal}, 30, rng);
  const calib::SolveOptions solve = calib::solve_options_from_model(model, false);
  std::vector<std::size_t> cand = solve.candidates;
  if (cand.empty())
    for (std::size_t i = 0; i < predictor.parameter_count(); ++i) cand.push_back(i);
  const auto all_names = predictor.parameter_labels();
  std::vector<std::string> names;
  std::vector<int> preference;
  for (const std::size_t c : cand) {
    names.push_back(all_names[c]);
    if (!solve.preference.empty()) preference.push_back(solve.preference[c]);
  }
  Eigen::MatrixXd J(static_cast<Eigen::Index>(6 * poses.size()),
                    static_cast<Eigen::Index>(cand.size()));
  Eigen::Index rows = 0;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    calib::FramePrediction fp;
    std::string why;
    if (!predictor.predict(nominal, poses[i], static_cast<int>(i), true, fp, why)) continue;
    for (std::size_t k = 0; k < cand.size(); ++k)
      J.block(rows, static_cast<Eigen::Index>(k), 6, 1) =
          fp.jacobian.col(static_cast<Eigen::Index>(cand[k]));
    rows += 6;
  }
  if (rows == 0) {
    say_check(ctx, false, "the model reaches none of 30 sampled poses",
              "check the robot file's joint limits");
    return;
  }
  const auto report = calib::analyze_identifiability(J.topRows(rows), names, {}, preference);
  fmt::print(ctx.out,
             "What a calibration with this model can find (6-D board poses seen by the cameras, "
             "{} poses spread over the workspace):\n"
             "  {} of the {} free geometric parameters can be identified;\n"
             "  {} have no effect on what the cameras see or cannot be told apart from others:\n"
             "  they stay at their nominal values (only their combinations are identified).\n",
             poses.size(), report.rank, cand.size(), report.redundant.size());
  std::size_t shown = 0;
  for (const auto& r : report.redundancies) {
    if (shown++ == 6) {
      fmt::print(ctx.out, "  ... and {} more (robocal identify explains each)\n",
                 report.redundancies.size() - 6);
      break;
    }
    fmt::print(ctx.out, "  - {}\n", r.explanation);
  }
  ctx.state.set("robot.identifiable", std::to_string(report.rank));
  ctx.state.set("robot.held", std::to_string(report.redundant.size()));
  say_check(ctx, report.rank > 0,
            fmt::format("{} parameters identifiable before anything moves", report.rank),
            "the model has nothing the cameras can measure: check its free parameters");
}

// What the operator wants from the cell: the robot's geometry (with where the cameras are), or
// only where the cameras and the board are for a robot whose controller is trusted.
void ask_goal(const WizardContext& ctx) {
  fmt::print(ctx.out,
             "geometry: calibrate the robot's kinematics (identify, validate, export the "
             "calibrated robot).\nhandeye: only locate the camera(s) and the board relative to "
             "the robot, from the flange poses its controller reports (an accurate arm with its "
             "own calibration); the robot's model is not changed.\n");
  ctx.state.set("robot.goal",
                ctx.ask.choose("robot.goal", "What to calibrate", {"geometry", "handeye"},
                               ctx.state.get("robot.goal", "geometry")));
}

class RobotStep final : public Step {
 public:
  std::string key() const override { return "robot"; }
  std::string title() const override { return "The robot model"; }
  std::string what() const override {
    return "Which robot is this? Give a library name or the path of a robot file. The wizard "
           "then says what the calibration can and cannot find with this model.";
  }
  StepOutcome run(WizardContext& ctx) override {
    fmt::print(ctx.out, "Library robots: {}\n", fmt::join(library_robot_names(), ", "));
    for (;;) {
      const std::string name = ctx.ask.ask("robot.model", "Robot (library name or robot file)",
                                           ctx.state.get("robot.model"));
      try {
        const std::string file = resolve_robot(name);
        const calib::Mechanism model = load_robot(file);
        ctx.state.set("robot.model", name);
        ctx.state.set("robot.file", fs::absolute(file).string());
        fmt::print(ctx.out, "Robot: {} ({} actuators), from {}\n", model.name,
                   model.actuated.size(), file);
        ask_goal(ctx);
        if (!hand_eye_only(ctx.state)) explain_identifiability(ctx, model);
        return StepOutcome::done();
      } catch (const InputError& e) {
        say_check(ctx, false, e.what(),
                  "type one of the library names above, or the path of your robot file "
                  "(robot files: calib/README.md)");
      }
    }
  }
};

// A positive number for `key`, asked again (on a terminal) until one is given.
double ask_positive(const WizardContext& ctx, const std::string& key, const std::string& question,
                    const std::string& default_value) {
  for (;;) {
    const std::string text = ctx.ask.ask(key, question, default_value);
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (end != text.c_str() && *end == '\0' && std::isfinite(v) && v > 0) return v;
    say_check(ctx, false, fmt::format("'{}' is not a positive number", text),
              "give the number the firmware uses, e.g. 80");
  }
}

// The firmware's delta geometry differs from the robot file's: the operator says which to trust
// (the moves use the firmware's own model either way; the choice is recorded with the session).
void ask_geometry_choice(WizardContext& ctx, const std::string& link, const std::string& why) {
  say_check(ctx, false, why,
            "check the printer's rods and radius, or the robot file; then say which is right");
  const std::string choice =
      ctx.ask.choose("controller.firmware_geometry",
                     "Which delta geometry do you trust, the firmware's or the robot file's?",
                     {"firmware", "robot-file"}, "robot-file");
  ctx.state.set("controller.firmware_geometry", choice);
  ctx.state.set("controller.link", link);
}

// Where the controller says the axes are, in the robot file's units.
void print_axes(const WizardContext& ctx, const Eigen::VectorXd& values, bool prismatic,
                bool revolute) {
  std::string q;
  for (Eigen::Index i = 0; i < values.size(); ++i)
    q += fmt::format("{}{:.4f}", i == 0 ? "" : ", ", values[i]);
  fmt::print(ctx.out, "Axes now at: [{}] ({})\n", q,
             prismatic && revolute ? "m or rad"
             : prismatic           ? "m"
                                   : "rad");
}

// The export format of a printer's firmware ("" for another controller): the export step
// proposes the settings for the firmware the link talked to.
std::string export_format_of(robotio::Firmware firmware) {
  switch (firmware) {
    case robotio::Firmware::kKlipper:
      return "klipper";
    case robotio::Firmware::kMarlin:
      return "marlin";
    case robotio::Firmware::kRepRapFirmware:
      return "rrf";
    case robotio::Firmware::kUnknown:
      break;
  }
  return "";
}

// The network address behind a link address, for the probe: "tcp:H:P" and "open:H:P" -> "H:P",
// "ur:H" -> "H", "ur:H:R:S:D" -> "H:D" (its dashboard server); "" for a serial device or manual.
std::string probe_address_of(const std::string& link) {
  for (const char* scheme : {"tcp:", "open:"})
    if (link.rfind(scheme, 0) == 0) {
      const std::string rest = link.substr(std::string(scheme).size());
      return robotio::is_probe_address(rest) ? rest : "";
    }
  if (link.rfind("ur:", 0) == 0) {
    std::string rest = link.substr(3);
    const std::size_t colon = rest.find(':');
    if (colon == std::string::npos) return rest;
    const std::string there = rest.substr(0, colon) + rest.substr(rest.rfind(':'));
    return robotio::is_probe_address(there) ? there : "";
  }
  return "";
}

// Probes `address`, says what answers there and proposes the matching link; the link the
// operator accepts, nullopt when nothing robocal speaks to answers (said why).
std::optional<std::string> probe_and_propose(WizardContext& ctx, const std::string& address) {
  fmt::print(ctx.out, "Looking at {}...\n", address);
  const robotio::ProbeResult found = robotio::probe_controller(address);
  if (found.link.empty()) {
    say_check(ctx, false, found.explanation,
              "a Universal Robots controller answers on port 29999 (its dashboard server), a "
              "Klipper printer's Moonraker on 7125; an open link adapter or a G-code board on "
              "the port its configuration gives");
    return std::nullopt;
  }
  say_check(ctx, true, "found " + found.explanation);
  const std::string use =
      ctx.ask.ask("controller.probed_link",
                  "Link address to connect through (Enter to use the one proposed)", found.link);
  return use;
}

class ControllerStep final : public Step {
 public:
  std::string key() const override { return "controller"; }
  std::string title() const override { return "Connect the controller"; }
  std::string what() const override {
    return "The wizard connects to the robot's controller: a G-code board (Marlin or "
           "RepRapFirmware) over a serial port or TCP, a Klipper printer through Moonraker, a "
           "Universal Robots controller, or an open link adapter. Give just its network address "
           "to find out what answers there. It "
           "identifies the controller and reads where the axes are; nothing moves unless you ask "
           "for homing.";
  }
  StepOutcome run(WizardContext& ctx) override {
    const calib::Mechanism model = load_robot(ctx.state.get("robot.file"));
    // The firmware's steps per unit turn actuator units into G-code axis units: asked only for
    // the kinds of axes this robot has.
    bool prismatic = false;
    bool revolute = false;
    for (const int a : model.actuated) {
      const bool p =
          model.bodies[static_cast<std::size_t>(a)].joint == calib::JointType::kPrismatic;
      prismatic = prismatic || p;
      revolute = revolute || !p;
    }
    const double steps_mm =
        prismatic ? ask_positive(ctx, "controller.steps_per_mm",
                                 "Steps per mm of the linear axes (the firmware's M92; M503 "
                                 "prints it)",
                                 ctx.state.get("controller.steps_per_mm", "80"))
                  : std::stod(ctx.state.get("controller.steps_per_mm", "80"));
    const double steps_deg =
        revolute ? ask_positive(ctx, "controller.steps_per_degree",
                                "Steps per degree of the rotary axes (the firmware's M92; M503 "
                                "prints it)",
                                ctx.state.get("controller.steps_per_degree", "100"))
                 : std::stod(ctx.state.get("controller.steps_per_degree", "100"));
    ctx.state.set("controller.steps_per_mm", fmt::format("{}", steps_mm));
    ctx.state.set("controller.steps_per_degree", fmt::format("{}", steps_deg));
    for (;;) {
      std::string link =
          ctx.ask.ask("controller.link",
                      "Controller address (a serial device such as /dev/ttyACM0, tcp:HOST:PORT, "
                      "ur:HOST for a UR, open:HOST:PORT for an open link adapter, or "
                      "HOST[:PORT] to probe it)",
                      ctx.state.get("controller.link", "/dev/ttyACM0"));
      if (robotio::is_probe_address(link)) {
        const std::optional<std::string> probed = probe_and_propose(ctx, link);
        if (!probed) {
          if (ctx.ask.choose("controller.problem", "Try another address, or stop here",
                             {"retry", "quit"}, "retry") == "quit")
            return StepOutcome::stopped(fmt::format(
                "no controller robocal speaks to at {}; fix the address and resume", link));
          continue;
        }
        link = *probed;
      }
      robotio::SafetyGuard guard(model, model.nominal_parameters(), robotio::SafetyLimits{});
      robotio::GcodeLinkOptions lo;
      lo.address = link;
      lo.axes = robotio::axes_for_robot(model, steps_mm, steps_deg);
      lo.reply_timeout = std::chrono::milliseconds(2000);
      lo.reconnect_attempts = 2;
      // A delta printer in its own kinematics when its firmware reports delta geometry.
      lo.mode = robotio::GcodeMode::kAuto;
      lo.geometry =
          robotio::geometry_choice_from_string(ctx.state.get("controller.firmware_geometry", "ask"))
              .value_or(robotio::GeometryChoice::kAsk);
      try {
        const std::unique_ptr<robotio::RobotLink> robot_owner = robotio::make_robot_link(guard, lo);
        robotio::RobotLink& robot = *robot_owner;
        const auto fw = robot.connect();
        fmt::print(ctx.out, "Controller at {}: {}\n", link, fw.name);
        const robotio::ActuatorReadings readings = robot.read_actuators();
        print_axes(ctx, readings.values, prismatic, revolute);
        ctx.state.set("controller.link", link);
        ctx.state.set("controller.firmware", fw.name);
        ctx.state.set("controller.export_format", export_format_of(fw.firmware));
        // A delta printer in its firmware's own kinematics: the plan keeps to what it can
        // command (the plan step reads the frame back).
        const std::optional<robotio::CarriageFrame> frame = robotio::firmware_delta_frame(robot);
        ctx.state.set("controller.firmware_frame",
                      frame ? robotio::carriage_frame_text(*frame) : std::string());
        if (frame)
          fmt::print(ctx.out,
                     "The printer is driven in its firmware's own delta kinematics, as it "
                     "prints.\n");
        say_check(ctx, true, "the controller answers and reports its axes");
        // The hand-eye route trusts the flange pose; without one it falls back to the robot
        // file's nominal model, which the operator should know before anything is recorded.
        if (readings.base_T_flange)
          fmt::print(ctx.out,
                     "The controller reports its flange pose: recorded with every pose.\n");
        else if (hand_eye_only(ctx.state))
          say_check(ctx, false,
                    "the controller reports no flange pose: the hand-eye calibration will take "
                    "the flange from the robot file's nominal model for its readings",
                    "for a controller's own, calibrated pose, connect through a link that reports "
                    "it (a Universal Robots controller whose RTDE has tcp_offset, or an open link "
                    "adapter with the flange_pose capability, robotio/OPEN_LINK.md)");
        if (ctx.ask.confirm("controller.home",
                            "Home the robot now? Every axis moves to its endstop (collection "
                            "homes anyway, after the safety confirmation)",
                            false)) {
          guard.arm("the operator confirmed homing in the wizard");
          robot.home();
          fmt::print(ctx.out, "Homed.\n");
        }
        robot.disconnect();
        return StepOutcome::done();
      } catch (const robotio::GeometryDisagreement& e) {
        ask_geometry_choice(ctx, link, e.what());
      } catch (const robotio::LinkError& e) {
        // What does answer there, in plain words, when the address is a network one.
        if (const std::string there = probe_address_of(link); !there.empty())
          fmt::print(ctx.out, "What answers at {}: {}.\n", there,
                     robotio::probe_controller(there).explanation);
        say_check(ctx, false, fmt::format("no controller at {}: {}", link, e.what()),
                  "is the controller switched on and its cable plugged in? Is the address right "
                  "(serial: ls /dev/ttyACM* /dev/ttyUSB*; network: its IP and port)? A controller "
                  "that is not Marlin or RepRapFirmware needs an open link adapter "
                  "(open:HOST:PORT, robotio/OPEN_LINK.md)");
        if (ctx.ask.choose("controller.problem", "Try another address, or stop here",
                           {"retry", "quit"}, "retry") == "quit")
          return StepOutcome::stopped(fmt::format(
              "no controller at {} ({}); fix the connection and resume", link, e.what()));
      }
    }
  }
};

struct CameraEntry {
  std::string name, source;
};

std::vector<CameraEntry> parse_cameras(const std::string& text) {
  std::vector<CameraEntry> out;
  std::istringstream in(text);
  std::string item;
  while (in >> item) {
    const auto eq = item.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == item.size())
      throw InputError(fmt::format("'{}': expected NAME=SOURCE, e.g. cam0=aravis:SERIAL", item));
    out.push_back({item.substr(0, eq), item.substr(eq + 1)});
  }
  if (out.empty()) throw InputError("no camera given");
  return out;
}

// What the cameras' check found: every camera opened, and every check passed. In an array (more
// than two cameras) each pose is seen by the cameras facing it: a camera that sees part of the
// board, or none, is no problem as long as two see it whole.
struct CameraCheck {
  bool opened = true;
  bool ok = true;
  int whole = 0;  // cameras that see the whole board
};

// The checks that say whether the board is in a camera's view (robotio::check_live_frame).
bool is_view_check(const robotio::LiveCheck& k) {
  return k.name == "target" || k.name == "corners";
}

// Opens each camera (at width x height, or its full sensor when width is 0), checks one frame.
CameraCheck check_cameras(const WizardContext& ctx, const std::vector<CameraEntry>& cams,
                          const vision::TargetBoard& board, int width, int height) {
  CameraCheck result;
  const bool array = cams.size() > 2;
  vision::AprilTagDetectorOptions dopt;
  dopt.family = board.spec.family;
  vision::AprilTagDetector detector(dopt);
  for (const auto& c : cams) {
    try {
      auto cam = open_camera_at(c.source, c.name, width, height);
      const auto info = cam->info();
      cam->start(robotio::TriggerMode::kSoftware);
      const robotio::Frame frame = cam->grab(std::chrono::milliseconds(5000));
      cam->stop();
      std::string exposure = "?";
      try {
        exposure = fmt::format("{:.0f} us", cam->exposure_us());
      } catch (const std::exception&) {
      }
      cam->close();
      fmt::print(ctx.out, "{} ({} {} {}x{}; exposure {}):\n", c.name, info.vendor, info.model,
                 frame.image.cols, frame.image.rows, exposure);
      const auto report = robotio::check_live_frame(frame.image, board, detector);
      const bool in_view = std::all_of(report.checks.begin(), report.checks.end(),
                                       [](const auto& k) { return !is_view_check(k) || k.ok; });
      for (const auto& k : report.checks) {
        // (Sharpness is measured on the board's tags: only the exposure is judged without it.)
        const bool problem = !k.ok && (in_view || !array || k.name == "exposure");
        fmt::print(ctx.out, "  {:<10} {}  {}\n", k.name,
                   k.ok ? "ok     " : (problem ? "PROBLEM" : "note   "), k.summary);
        if (problem && !k.advice.empty())
          fmt::print(ctx.out, "             advice: {}\n", k.advice);
        result.ok = result.ok && !problem;
      }
      if (!in_view && array)
        fmt::print(ctx.out,
                   "  (the board is not wholly in this camera's view here: in an array of cameras "
                   "each pose is seen by the cameras facing it)\n");
      result.whole += in_view ? 1 : 0;
    } catch (const std::exception& e) {
      fmt::print(ctx.out, "{}: cannot open {}: {}\n", c.name, c.source, e.what());
      result.opened = false;
      result.ok = false;
    }
  }
  if (array && result.whole < 2) {
    fmt::print(ctx.out, "{} of the {} cameras see the whole board; two must, at every pose\n",
               result.whole, cams.size());
    result.ok = false;
  }
  return result;
}

class CamerasStep final : public Step {
 public:
  std::string key() const override { return "cameras"; }
  std::string title() const override { return "The cameras"; }
  std::string what() const override {
    return "Name each camera and say where it is (aravis:ID for GigE / USB3 Vision, "
           "v4l2:/dev/videoN for USB). The wizard takes a frame from each and checks that the "
           "board on the robot is seen whole, sharp and well exposed.";
  }
  StepOutcome run(WizardContext& ctx) override {
    std::string found;
    int k = 0;
    for (const auto& c : robotio::discover_aravis_cameras())
      found += fmt::format("{}cam{}=aravis:{}", found.empty() ? "" : " ", k++, c.id);
    fmt::print(ctx.out, "Cameras found: {}\n",
               found.empty() ? "none through Aravis (GigE Vision, USB3 Vision); give yours as "
                               "NAME=SOURCE"
                             : found);
    for (;;) {
      const std::string list =
          ctx.ask.ask("cameras.list", "Cameras as NAME=SOURCE, separated by spaces",
                      ctx.state.get("cameras.list", found));
      const std::string target = ctx.ask.ask(
          "cameras.target", "Target file of the board on the end-effector (vision/README.md)",
          ctx.state.get("cameras.target"));
      const std::string size = ctx.ask.ask(
          "cameras.size",
          "Image size the cameras deliver, WIDTHxHEIGHT as their intrinsics ('full': the whole "
          "sensor)",
          ctx.state.get("cameras.size", "full"));
      std::vector<CameraEntry> cams;
      vision::TargetBoard board;
      int width = 0;
      int height = 0;
      try {
        cams = parse_cameras(list);
        board = load_board(target);
        if (size != "full" && size != "keep" &&
            (std::sscanf(size.c_str(), "%dx%d", &width, &height) != 2 || width <= 0 || height <= 0))
          throw InputError(fmt::format("'{}': give the size as WIDTHxHEIGHT, e.g. 1280x960", size));
      } catch (const InputError& e) {
        say_check(ctx, false, e.what(),
                  "give the cameras as NAME=SOURCE and an existing target file");
        continue;
      }
      ctx.state.set("cameras.list", list);
      ctx.state.set("cameras.size", size);
      ctx.state.set("cameras.target", fs::absolute(target).string());
      for (;;) {
        const CameraCheck check = check_cameras(ctx, cams, board, width, height);
        const bool ok = check.ok;
        say_check(ctx, ok,
                  ok ? (cams.size() > 2 ? "the cameras facing the board see it whole, sharp and "
                                          "well exposed"
                                        : "every camera sees the whole board, sharp and well "
                                          "exposed")
                  : check.opened ? "a camera is not ready (above)"
                                 : "a camera cannot be opened (above)",
                  check.opened
                      ? "move the robot or the camera until the board is in view, focus, adjust "
                        "the exposure or the light, then retry"
                      : "check the camera's cable and power and its NAME=SOURCE (aravis:ID as "
                        "listed above, v4l2:/dev/videoN: ls /dev/video*), then retry or give the "
                        "list again ('quit', then resume)");
        if (ok) return StepOutcome::done();
        const std::string c =
            ctx.ask.choose("cameras.problem", "Retry the check, continue anyway, or stop here",
                           {"retry", "continue", "quit"}, "retry");
        if (c == "continue") return StepOutcome::done();
        if (c == "quit")
          return StepOutcome::stopped(
              "the cameras are not ready (see the checks above); resume "
              "when they are");
      }
    }
  }
};

}  // namespace

std::unique_ptr<Step> robot_step() {
  return std::make_unique<RobotStep>();
}
std::unique_ptr<Step> controller_step() {
  return std::make_unique<ControllerStep>();
}
std::unique_ptr<Step> cameras_step() {
  return std::make_unique<CamerasStep>();
}

}  // namespace robocal::app::wizard
