#pragma once
// `robocal collect`: a plan's poses driven on a real controller and recorded by real cameras into
// a session folder (app/SESSION.md). Orchestration only: the guard, link, cameras and capture loop
// are robotio's, the plan and cell are the planner's; this file wires them, asks the operator
// before the first motion, shows progress, and says what is on disk when it stops.
//
// Safety (shared/reference/product.md): every motion passes one SafetyGuard, built from the
// robot file's actuator limits, the cell's declared workspace and obstacles (the planner's FCL
// scene as the guard's clearance check) and the speed limits given here. Nothing moves before the
// operator confirms (a typed "yes" on a terminal, or --yes for scripts); Ctrl-C or SIGTERM stops
// the robot through the guard and keeps every recorded pose; the p key or SIGUSR1 pauses between
// poses and pressing it again resumes.
#include "robocal/calib/mechanism.hpp"
#include "robocal/robotio/camera_source.hpp"
#include "robocal/robotio/capture.hpp"
#include "robocal/robotio/gcode_link.hpp"
#include "stages/stages.hpp"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace robocal::app {

struct CollectCamera {
  std::string name;    // the cell's camera name (also the image file names)
  std::string source;  // robotio/camera_open.hpp: aravis:ID or v4l2:/dev/videoN
};

struct CollectOptions {
  std::filesystem::path session;  // created, or continued with `resume`
  std::string robot;              // library name or file; empty = the cell's robot
  std::string cell;               // cell file (planner/README.md)
  std::string plan;               // plan file (`robocal plan`)
  std::string link;               // tcp:HOST:PORT or a serial device (/dev/ttyACM0)
  int baud = 115200;
  double steps_per_mm = 80.0;       // the controller's steps per mm (prismatic actuators)
  double steps_per_degree = 100.0;  // steps per degree (revolute actuators)
  double reply_timeout_s = 2.0;
  bool accept_unknown_firmware = false;
  // A Universal Robots link may unlock a protective stop through the dashboard server: only
  // after the start confirmation (which names it), and only before a move the guard passed.
  bool unlock_protective_stop = false;
  // G-code: a delta printer in its own kinematics or one axis per motor (auto: native when the
  // robot file's firmware computes a linear delta and the firmware reports delta geometry), and
  // which geometry to trust when the firmware's disagrees with the robot file's (ask: refuse
  // before anything moves, naming each difference).
  robotio::GcodeMode gcode_mode = robotio::GcodeMode::kAuto;
  robotio::GeometryChoice firmware_geometry = robotio::GeometryChoice::kAsk;
  std::vector<CollectCamera> cameras;
  double speed = 0.02;        // actuator units/s (m/s prismatic, rad/s revolute)
  double acceleration = 0.5;  // actuator units/s^2
  int shots = 2;              // frames per camera per pose (>= 2: the settled-frame test)
  bool home = true;           // home the controller before the first pose
  bool dry_run = false;       // check every motion through the guard; move nothing
  bool resume = false;        // continue an interrupted session at the next unrecorded pose
  bool yes = false;           // the operator's confirmation given on the command line
  // A plan whose status is `infeasible` (the planner found too few feasible poses) is refused
  // unless this is set: collecting it takes the robot's time for a calibration that may not
  // identify it.
  bool accept_infeasible_plan = false;
  bool say_next_step = true;  // print what to run next (not inside the wizard, which goes on)
  // Opens a camera's source instead of robotio::open_camera_source (the live demo's cameras
  // rendered in-process where no GigE address is left for them); empty: open_camera_source.
  std::function<std::unique_ptr<robotio::CameraSource>(const CollectCamera&)> open_camera;
  // Called after every motion, once the controller reports the robot settled, with its readings
  // (a pose's pose.yaml keeps the same readings of the motion its shots were taken after).
  std::function<void(const Eigen::VectorXd& readings)> on_settled;
};

struct CollectOutcome {
  // ok | dry_run_ok | refused (a motion the guard refuses) | failed (controller or camera) |
  // cancelled (not confirmed) | incomplete (stopped early) | interrupted (SIGINT / SIGTERM)
  std::string status;
  std::string message;     // why, when not ok
  int signal = 0;          // the signal that interrupted it
  nlohmann::json summary;  // everything, for --json (status, message and signal included)
};

// Runs the collection. Throws InputError for bad files / arguments (exit 3).
CollectOutcome collect_session(const CollectOptions& options, const PipelineLog& log);

// 0 complete (or a dry run whose motions all passed), 1 stopped early, refused, failed or
// cancelled (what is recorded stays), 130 / 143 interrupted by SIGINT / SIGTERM.
int collect_exit_code(const CollectOutcome& outcome);

// The unit of the robot's actuator readings: "rad" (revolute), "m" (prismatic) or "m or rad".
std::string actuator_unit(const calib::Mechanism& model);

// The time a motion of `distance` (actuator units) takes from standstill to standstill at
// `speed` and `acceleration`: a trapezoidal profile, or a triangle when it is too short to
// reach the speed.
double motion_seconds(double distance, double speed, double acceleration);

}  // namespace robocal::app
