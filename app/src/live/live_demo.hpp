#pragma once
// `robocal demo --live`: the whole live loop on one machine. `robocal sim-controller` runs as a
// separate process on loopback holding the true, perturbed robot (the offline demo's true robot
// for the same seed); the cell's two cameras are served as GigE Vision cameras through Aravis'
// fake camera where this machine allows it (otherwise rendered in-process, said so); the operator
// shows the calibration board to the cameras (a scripted board pose sequence); the planner plans
// the measurement poses; `robocal collect`'s collect_session drives them (guard, confirmation,
// progress, resume); then measure -> identify -> validate against the simulator's truth ->
// report. Orchestration only.
#include "stages/stages.hpp"

#include <filesystem>
#include <string>

namespace robocal::app {

struct LiveDemoOptions {
  std::string robot = "rotary_delta";
  unsigned seed = 1;
  int poses = 60;
  int held_out = 500;
  // Calibration-board views per camera; 0: as the offline demo for a pair of cameras, half as many
  // for an array (kArrayIntrinsicViews), where the operator shows the board to every camera.
  int intrinsic_views = 0;
  int rig_views = SimulateOptions{}.rig_views;
  int threads = 2;
  bool quick = false;
  bool idealised_truth = false;
  bool gige = true;  // try the fake GigE cameras (false: in-process rendering)
  bool yes = false;  // the operator's confirmation before the first motion
  bool resume = false;
  double speed = 0.0;  // actuator units/s; 0: 2 rad/s revolute, 0.5 m/s prismatic
  std::string route = "both";
  // Printers (the linear delta): the firmware the simulated printer runs (marlin, rrf, klipper)
  // and how it is driven: raw (one axis per motor) or native (its own delta kinematics; the
  // candidate poses it cannot command are left out before the planner selects). Klipper is
  // always native, through Moonraker.
  std::string firmware = "marlin";
  std::string gcode_mode = "raw";
  std::string out;   // demo folder: session/ and setup/ inside
  std::string json;  // report path ('-' stdout)
};

// Intrinsic views per camera of an array of more than two cameras, by default: six cameras at 96
// views each would have the operator show the board 576 times; 48 each still gives an array 1.5
// times the views of a pair, at a few micrometres of held-out error (docs/figures.md).
inline constexpr int kArrayIntrinsicViews = 48;

// Intrinsic views per camera of `robocal demo --live` when --intrinsic-views is not given, for
// any number of cameras: rendering and calibrating the views was most of the live demo's time
// for a pair of cameras too; 48 views take half the time of 96 at a few micrometres of held-out
// error (`--intrinsic-views 96` for the difference, docs/figures.md).
inline constexpr int kLiveIntrinsicViews = 48;

// Runs the live demo; returns the process exit code (0: calibrated and improved).
int run_live_demo(const LiveDemoOptions& options);

}  // namespace robocal::app
