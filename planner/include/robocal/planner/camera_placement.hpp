#pragma once
// Camera placement: where to put cameras so they see the robot's working volume.
//
// From the robot's reachable configurations (reach.hpp, within the cell's workspace when it
// declares one) the target's centre positions and face normals give candidate viewing
// directions: the mean direction the printed face looks to (one side for a Delta's level board),
// and the face directions of 16 spread samples (a serial arm's board faces every way, and a
// camera pair can only watch one side of its range). For each direction, the poses whose board
// faces within 40° of it give the look-at point (their mean) and the volume's radius (incl. the
// target's half diagonal); the cameras look at it from that side, on a circle around the
// direction, each tilted by half the triangulation angle (two cameras: the baseline is
// 2·d·sin(angle/2)). Distances d from 60 % to 160 % of the one fitting the volume's sphere into
// the narrower half field of view (15 % margin), capped by the one keeping the target's image at
// min_image_size. The placement seeing the target whole (outline in the image with the border,
// incidence, size) at the most sampled poses wins; its coverage is then measured with the full
// feasibility test (feasibility.hpp, obstacles and occlusion included).
//
// Camera arrays: where one group of cameras sees the target at fewer than `min_coverage` of the
// reachable poses (a Gantry-Tau's 3 m of guideway, a wire robot's wide frame) and
// `max_cameras` allows more, further groups ("stations", `cameras` each, from the same tried
// placements) are added greedily, each the one that adds the most poses seen by at least two
// cameras of the array, until the coverage reaches `array_coverage`, a station adds less than
// 2 % or the count reaches `max_cameras`. A station joins only if it shares a view with the
// array (some pose seen by one of its cameras and one already placed): the rig is calibrated by
// chaining board views through such overlaps (vision/rig_calibration.hpp). The array's cell
// then asks for two cameras, any two, at each pose (VisibilityRequirements::min_cameras).
#include "robocal/calib/mechanism.hpp"
#include "robocal/planner/cell.hpp"

#include <Eigen/Geometry>

#include <string>
#include <vector>

namespace robocal::planner {

struct PlacementOptions {
  int cameras = 2;
  double triangulation_angle = 0.6;  // rad (~34°) between the two cameras' lines of sight
  double min_coverage = 0.5;         // fraction of reachable poses visible to every camera
  int samples = 600;                 // reachable configurations sampled
  unsigned seed = 3;
  int max_cameras = 0;          // > cameras: an array of stations allowed (see above)
  double array_coverage = 0.9;  // an array stops growing at this coverage
};

struct CameraPlacement {
  std::vector<Eigen::Isometry3d> world_T_camera;
  Eigen::Vector3d look_at = Eigen::Vector3d::Zero();
  Eigen::Vector3d view_direction = Eigen::Vector3d::UnitZ();  // from the volume to the cameras
  double distance = 0.0;                                      // m, camera to look-at point
  double baseline = 0.0;                                      // m, between the first two cameras
  double volume_radius = 0.0;
  double coverage = 0.0;  // fraction of reachable sampled poses visible to every camera
  // An array: the point each station of `cameras_per_station` cameras looks at (camera i is in
  // station i / cameras_per_station), and how many cameras must see a pose (0: all of them).
  std::vector<Eigen::Vector3d> station_look_at;
  int cameras_per_station = 0;
  int min_cameras = 0;
  std::string summary;
};

// `cell` supplies the target mount, obstacles, workspace, margins and visibility limits; its
// cameras supply the intrinsics (the first camera's model is used for every proposed camera) and
// their poses are ignored. Throws std::invalid_argument when the robot reaches nothing.
CameraPlacement propose_cameras(const calib::Mechanism& model, const Eigen::VectorXd& params,
                                const Cell& cell, const PlacementOptions& options = {});

// The cell with its cameras moved to a placement (camera i gets pose i, known); an array's
// visibility asks for its min_cameras.
Cell with_cameras(const Cell& cell, const CameraPlacement& placement);

}  // namespace robocal::planner
