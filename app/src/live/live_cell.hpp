#pragma once
// The live demo's cell as files an operator would have: the planner's cell file (cameras where
// they were placed, with the lens's datasheet intrinsics; the declared workspace; the board on the
// robot's tool), the simulator's true robot (a perturbation file of NAME=VALUE lines for
// `robocal sim-controller --perturbation`), and the plan. Built from the offline demo's
// SimulatedCell for the same seed, so the live and the offline demo calibrate the same robot.
#include "robocal/planner/cell.hpp"
#include "robocal/robotio/safety_guard.hpp"
#include "robocal/robotio/sim_process.hpp"
#include "simcell/simulated_cell.hpp"

#include <Eigen/Core>

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace robocal::app {

struct LiveCellFiles {
  std::filesystem::path cell;          // cell.yaml (planner/README.md)
  std::filesystem::path perturbation;  // truth.txt: every true parameter, NAME=VALUE
  std::filesystem::path ee_target;     // the end-effector board's target file
  std::filesystem::path calibration_target;
};

// Writes the cell's files into `dir` (created). `robot_file` = the library robot's file (whose
// tool frame the cell's target position refers to).
LiveCellFiles write_live_cell(const SimulatedCell& cell, const std::string& robot_file,
                              const std::filesystem::path& dir);

// Whether the controller can command actuator readings (an empty one: every reading).
using Commandable = std::function<bool(const Eigen::VectorXd&)>;

// Whether the simulated controller runs a delta printer in its firmware's own kinematics: a
// G-code controller (`protocol` "gcode") of a linear delta, unless `gcode_mode` is "raw"; Klipper
// always (it drives a delta only in its own kinematics: InputError for another robot).
bool simulated_native_delta(const calib::Mechanism& model, const std::string& protocol,
                            const std::string& firmware, const std::string& gcode_mode);

// The --link address of a simulated controller speaking `protocol`: ur:..., open:HOST:PORT, or for
// G-code tcp:HOST:PORT, and moonraker:HOST:PORT for a Klipper printer (`klipper`), served on the
// same port.
std::string simulated_link_address(const robotio::SimControllerProcess& sim,
                                   const std::string& protocol, bool klipper);

// What a delta firmware ("marlin", "rrf" or "klipper") whose kinematics is the robot file's
// drawing (sim-controller --kinematics delta) can command: not a carriage below the nozzle.
Commandable drawing_commandability(const calib::Mechanism& model, const std::string& firmware);

// Poses of the nominal robot where both cameras (two of an array's) see the whole board, chained
// so that the safety guard (the same one collect builds: limits, workspace, the cell's collision
// scene) lets every motion through, starting from the controller's home, and that `commandable`
// accepts. At most `count`.
std::vector<Eigen::VectorXd> sampled_poses(const SimulatedCell& cell,
                                           const calib::Mechanism& library,
                                           const planner::Cell& pcell, int count, unsigned seed,
                                           const robotio::MoveSpeed& speed,
                                           const Commandable& commandable = {});

// The planned poses: actuator readings in motion order, and how they were chosen.
struct LivePlan {
  std::vector<Eigen::VectorXd> readings;
  std::string how;      // a sentence for the operator
  bool planner = true;  // false: the fallback (the cell's own sampled poses)
  double predicted_rms_m = 0.0;
};

// Plans `count` measurement poses with the planner on the cell file (nominal robot) and writes
// the plan file; where the planner cannot plan for this robot, falls back to poses sampled on
// the nominal robot where both cameras see the board whose motions the safety guard allows (at
// `speed`), and says so. Deterministic in `seed`. `commandable`, when given, leaves out the
// planned poses the controller cannot command (a delta firmware's kinematics cannot put a
// carriage below the nozzle), saying how many.
LivePlan plan_live_poses(const SimulatedCell& cell, const std::string& robot_file,
                         const LiveCellFiles& files, int count, unsigned seed, bool quick,
                         const std::filesystem::path& plan_file, const robotio::MoveSpeed& speed,
                         std::FILE* out, const Commandable& commandable = {});

}  // namespace robocal::app
