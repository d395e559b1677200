#pragma once
// The robot cell the planner plans in: cameras (calibrated intrinsics + pose in the world, or
// "unknown, roughly here"), obstacles (boxes, cylinders, spheres, STL meshes), the declared safe
// workspace, margins, the target mounted on the measured frame, and what "visible" means.
// Read from a cell file (YAML; format and examples in planner/README.md, testdata/cells/).
//
// Frames and units: the world is the robot file's world (root) frame; metres and radians (a cell
// file may say `units: mm`, then every length in it is millimetres and is converted on reading).
// A camera pose maps camera coordinates to world (x_world = R x_cam + p), camera z = optical
// axis, x right, y down (OpenCV). The target pose maps board coordinates (vision/target.hpp:
// origin at the pattern's top-left corner, z into the board) to the measured frame's coordinates.
#include "robocal/core/input_error.hpp"
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/target.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace robocal::planner {

// Any problem with a cell file (or a file it names); the message starts with "file:line: ".
// The project's one bad-input type (core/input_error.hpp), under the name planner code uses.
using CellFileError = core::InputError;

struct CellCamera {
  std::string name;
  std::string file;  // camera file as resolved (absolute or relative to the working directory)
  vision::CameraModel model;
  Eigen::Isometry3d world_T_camera = Eigen::Isometry3d::Identity();
  // false: the operator gave only a rough pose ("unknown, roughly here"); the planner then
  // widens the image border by what `pose_uncertainty` (m) can shift the image at the target's
  // distance, so planned poses stay in view wherever the camera really is within it.
  bool pose_known = true;
  double pose_uncertainty = 0.0;
  int line = 0;
};

enum class ObstacleKind : std::uint8_t { kBox, kCylinder, kSphere, kMesh };

struct Obstacle {
  std::string name;
  ObstacleKind kind = ObstacleKind::kBox;
  Eigen::Isometry3d world_T_obstacle = Eigen::Isometry3d::Identity();  // centre; cylinder axis z
  Eigen::Vector3d size = Eigen::Vector3d::Zero();                      // box: full edge lengths
  double radius = 0.0;                                                 // cylinder, sphere
  double length = 0.0;                                                 // cylinder
  // Mesh: triangles in the obstacle frame (already scaled to metres).
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3i> triangles;
  std::string mesh_file;
  int line = 0;
};

// Axis-aligned box in the world that the measured frame and every target corner must stay in.
struct SafeWorkspace {
  bool declared = false;
  Eigen::Vector3d min = Eigen::Vector3d::Constant(-1e300);
  Eigen::Vector3d max = Eigen::Vector3d::Constant(1e300);
  int line = 0;
  bool contains(const Eigen::Vector3d& p) const {
    return (p.array() >= min.array()).all() && (p.array() <= max.array()).all();
  }
};

struct Margins {
  double clearance = 0.01;          // m, robot links vs obstacles
  double self_clearance = 0.002;    // m, robot link vs robot link (non-adjacent links)
  double joint_limit_angle = 0.0;   // rad, kept from every revolute limit and ball-joint cone
  double joint_limit_length = 0.0;  // m, kept from every prismatic limit
  double image_border = 10.0;       // px, target corners stay this far inside the image
};

struct TargetMount {
  std::string file;
  vision::TargetBoard board;
  std::string frame;  // body name of the measured frame; empty = the robot's tool
  Eigen::Isometry3d frame_T_board = Eigen::Isometry3d::Identity();
  int line = 0;
};

enum class RequiredCorners : std::uint8_t {
  kAll,      // every detectable corner of the board
  kOutline,  // the four extreme corners of the pattern
};

struct VisibilityRequirements {
  std::vector<std::string> cameras;  // must all see the target; empty = every camera
  // At least this many of those cameras must see the target (0: all of them). A camera array
  // whose fields tile a working volume larger than one view (camera_placement.hpp) needs two:
  // a pose seen by any two of its cameras is measured in stereo.
  int min_cameras = 0;
  double max_incidence = 1.0471975511965976;  // rad (60°): board normal vs line of sight
  double min_image_size = 40.0;               // px, shortest side of the target's image
  RequiredCorners corners = RequiredCorners::kAll;
};

struct Cell {
  std::string name;
  std::string source;      // the cell file (for messages)
  std::string robot_file;  // optional robot file named by the cell (resolved), "" if none
  std::vector<CellCamera> cameras;
  std::vector<Obstacle> obstacles;
  SafeWorkspace workspace;
  Margins margins;
  TargetMount target;
  VisibilityRequirements visibility;

  // Index of a camera by name, -1 if absent.
  int camera_index(const std::string& name) const;
  // Cameras that must see the target (visibility.cameras, or all).
  std::vector<int> required_cameras() const;
  // How many of the required cameras must see it (visibility.min_cameras, or all of them).
  int cameras_needed() const;
};

// Reads a cell file; camera, target and mesh files are resolved relative to the cell file's
// folder. Throws CellFileError ("file:line: problem") for anything wrong, including a missing or
// malformed camera/target/mesh file (the message then names both files).
Cell load_cell_file(const std::string& path);
// Same from text; relative file names resolve against `base_dir`.
Cell parse_cell_yaml(const std::string& text, const std::string& source,
                     const std::string& base_dir);

// Reads an STL mesh (ASCII or binary); throws CellFileError naming the file.
void read_stl(const std::string& path, double scale, std::vector<Eigen::Vector3d>& vertices,
              std::vector<Eigen::Vector3i>& triangles);

// The board corners the visibility test requires (board frame).
std::vector<Eigen::Vector3d> required_corner_points(const vision::TargetBoard& board,
                                                    RequiredCorners which);
// The four extreme corners of the pattern's corner set (board frame, z = 0), in order around.
std::vector<Eigen::Vector3d> board_outline(const vision::TargetBoard& board);

}  // namespace robocal::planner
