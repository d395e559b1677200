#pragma once
// What the live demo and `robocal sim-cell` share: the simulated cell for a seed with the
// calibration-board poses the operator shows its cameras, the cameras' specifications, the
// rendering of those calibration views, and the simulated robot's speed.
#include "live/live_cameras.hpp"
#include "live/live_demo.hpp"
#include "session/results_files.hpp"
#include "simcell/simulated_cell.hpp"
#include "stages/stages.hpp"

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace robocal::app {

// The path of the running robocal program (to start `robocal sim-controller` beside it).
std::string robocal_binary();

// The offline demo's cell and calibration board poses for the same seed (stages/simulate.cpp
// draws them from its random stream in this order).
struct LiveCell {
  SimulatedCell cell;
  std::vector<std::vector<Eigen::Isometry3d>> intrinsic_views;  // camera_T_board per camera
  std::vector<Eigen::Isometry3d> rig_views;                     // world_T_board
};

LiveCell make_live_cell(const LiveDemoOptions& o, const std::string& robot_file);

// The cell's cameras as the renderer takes them (cam0, cam1, ...), each with its own noise seed.
std::vector<LiveCameraSpec> camera_specs(const SimulatedCell& cell, unsigned seed, int threads);

// The operator waves the calibration board: held where the script says, each view taken by the
// cameras that should see it, written where app/SESSION.md keeps calibration views
// (dir/intrinsics/<camera>/view_NNN.png, dir/rig/view_NNN/<camera>.png).
void take_calibration_views(const LiveCell& lc, const std::vector<LiveCameraSpec>& specs, bool gige,
                            const std::filesystem::path& dir, const PipelineLog& log,
                            nlohmann::json& report);

// The simulated robot's speed (actuator units/s).
double default_speed(const calib::Mechanism& model);

}  // namespace robocal::app
