#pragma once
// Opening a camera from the text an operator types, with the simulated cell's own kind beside
// robotio's (aravis:, v4l2:):
//
//   sim:FILE   a camera of `robocal sim-cell` rendered in this process: FILE (written by
//              sim-cell) names the simulated cell (robot, seed) and the simulator's true-pose
//              channel; each frame shows the end-effector board where the simulated controller
//              really holds it. sim-cell serves its cameras as GigE Vision cameras where the
//              machine gives each its own address; a camera it cannot serve so is this kind.
#include "robocal/robotio/camera_source.hpp"

#include <filesystem>
#include <memory>
#include <string>

namespace robocal::app {

// What a sim: camera file holds (format robocal-sim-camera-1).
struct SimCameraFile {
  std::string robot;  // robot file of the simulated cell
  unsigned seed = 1;
  bool quick = false;
  bool idealised_truth = false;
  std::string camera;  // cam0, cam1, ...
  std::string truth;   // the simulator's true-pose channel, HOST:PORT
};

std::string sim_camera_yaml(const SimCameraFile& file);
// Throws InputError naming the file and what is wrong.
SimCameraFile load_sim_camera_file(const std::filesystem::path& path);

// Opens the camera `text` names (sim:FILE here, any other kind through
// robotio::open_camera_source), calling it `name` in messages. Throws as
// robotio::open_camera_source does; a bad sim: file is an InputError naming it.
std::unique_ptr<robotio::CameraSource> open_camera(const std::string& text,
                                                   const std::string& name);

}  // namespace robocal::app
