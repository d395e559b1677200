#pragma once
// A simulated robot cell for the demo and for CI: a "true" robot (library robot + random
// perturbations), cameras placed to see the working volume (a pair, or an array of pairs where
// one pair sees too little of the robot's range), a target board on the
// end-effector and a calibration board. Everything the measurement pipeline gets from it are
// rendered images and actuator readings; the truth stays in SimulatedCell and is read only to
// report errors (validation).
//
// Frames: the cell's truth world is the robot's nominal base frame (z up; the Delta hangs below
// it). The cameras are placed by the planner (planner/camera_placement.hpp) on the side the
// end-effector board faces over the working volume (below it, looking up, for the Delta, whose
// board faces down; beside it for the linear delta, whose bed hides a board facing down, so its
// board hangs on the effector's side). The pipeline's world is camera 0's frame (the rig's
// gauge), so it never needs the truth world.
#include "robocal/calib/mechanism.hpp"
#include "robocal/planner/camera_placement.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/renderer.hpp"
#include "robocal/vision/target.hpp"

#include <Eigen/Geometry>

#include <memory>
#include <random>
#include <string>
#include <vector>

namespace robocal::app {

struct CellOptions {
  int image_width = 1600;
  int image_height = 1200;
  double focal_px = 1600.0;
  // Camera placement (planner::propose_cameras): angle between the two lines of sight, and the
  // smallest image of the end-effector board's pattern (shortest side, px) a pose must give to
  // be planned, which also bounds the cameras' distance. 250 px puts ~35 px on each 40 mm tag of
  // the default board; at 160 px (quick images, Delta cameras 2.1 m away) a quarter of the
  // poses' board fits failed the measure stage's consistency gate (chi2/dof 60-150).
  double triangulation_angle = 0.6;  // rad
  double min_board_image = 250.0;    // px
  // Where one pair sees the board at under a quarter of the reachable poses of a robot with loops,
  // an array of up to this many cameras (pairs placed by the planner) whose fields tile the range.
  int max_cameras = 6;
  // The end-effector board: ee_tags x ee_tags AprilTags (tag36h11, ids from 0); default 6x6 tags
  // of 40 mm with 10 mm gaps, a 290 mm pattern on the Delta's ~0.4 m plate. The board's tilt is
  // its least well measured quantity (depth across the board from 1-2 m away), and it grows
  // with the board's size and corner count: 6x6 instead of 4x4 tags of 40 mm (196 mm) halves
  // the rotation error of the measured pose (demo seed 1: 28 -> 13 mdeg RMS).
  int ee_tags = 6;
  double ee_tag_size = 0.04;     // m, black square of a tag
  double ee_tag_spacing = 0.01;  // m, gap between neighbouring tags
  // Realistic perturbations of the true robot (1-sigma): lengths, angles (incl. encoder zeros).
  double length_sigma = 0.5e-3;
  double angle_sigma = 0.2 * 3.14159265358979323846 / 180.0;
  // Unmodelled error: when non-zero, the parameters the robot file holds fixed (which
  // identification never estimates) are perturbed too, by the same tolerances, from this seed
  // (its own stream, so the rest of the cell is the same as without). 0: the idealised truth,
  // which differs from the drawing only where the model can follow.
  unsigned unmodelled_seed = 0;
  // Elastic deflection of the realistic truth (elastic_deflection below), m per m of reach
  // squared; 0: a rigid robot. A robot is built stiff enough to sag at most kMaxElasticSag
  // anywhere it reaches: where the law would give more (a reach beyond 1 m), the cell scales
  // it down (SimulatedCell::elastic_sag).
  double elastic_sag = 0.0;
  // Actuator readings: Gaussian noise and quantisation step, joint units (rad or m).
  double actuator_noise = 2e-6;
  double actuator_step = 1e-6;
  vision::RenderOptions render;  // sensor model (blur, noise, levels)
  CellOptions();
};

struct SimulatedCamera {
  vision::CameraModel model;         // true intrinsics (the pipeline never reads them)
  Eigen::Isometry3d camera_T_world;  // true extrinsics in the truth world
  // Precomputed for rendering; shared with the renderers of the live cell's cameras.
  std::shared_ptr<const vision::CameraRays> rays;
};

struct SimulatedCell {
  calib::Mechanism model;        // nominal robot, with the tool frame set to the board mount
  Eigen::VectorXd nominal;       // nominal parameters (designed board mount)
  Eigen::VectorXd truth;         // true parameters (perturbed)
  int target_frame = -1;         // body whose frame is the end-effector board's frame
  vision::TargetBoard ee_board;  // on the end-effector
  vision::TargetBoard calibration_board;  // hand-held, for intrinsics and rig views
  std::vector<SimulatedCamera> cameras;
  Eigen::Vector3d volume_centre = Eigen::Vector3d::Zero();  // truth world
  Eigen::Vector3d volume_extent = Eigen::Vector3d::Zero();  // half sizes of the sampled poses
  // The cell as the planner sees it before calibration: the NOMINAL intrinsics (no distortion),
  // the cameras where they were placed, the board on the target frame (frame_T_board = identity:
  // the target frame is the board's frame), no obstacles, no declared workspace.
  planner::Cell plan_cell;
  planner::CameraPlacement placement;  // what propose_cameras said
  CellOptions options;
  // The true robot's elastic sag, m per m^2: options.elastic_sag, scaled down where the
  // robot reaches further than the largest sag allows (kMaxElasticSag at its farthest reach).
  double elastic_sag = 0.0;
};

// The largest elastic sag of a simulated robot anywhere it reaches (m). At the law's 1e-4 /m,
// the rotary Delta (0.93 m at most), the UR5 (0.85 m) and the four-bar stay below it and keep
// the law; the
// Gantry-Tau, whose platform works up to 4 m from its base axis on its guideways, would sag
// 1.6 mm by the law, which no precision gantry does (its carts carry the structure along).
inline constexpr double kMaxElasticSag = 100e-6;

// The demo's cell for a seed (offline `simulate`/`demo` and `demo --live` share it, so the same
// seed gives the same true robot): quick = smaller images; the realistic truth has unmodelled
// error from its own stream and an elastic sag of 1e-4 per metre of reach squared.
CellOptions demo_cell_options(unsigned seed, bool quick, bool idealised_truth);

// Builds the cell around a library robot file. Throws std::runtime_error when the robot has no
// sampled configuration the cameras could see.
SimulatedCell make_simulated_cell(const std::string& robot_file, const CellOptions& options,
                                  std::mt19937& rng);

// The spread the cell's true robot is drawn from, per parameter (1 sigma; the unmodelled error's
// held parameters too where the cell has it): how far the robot that moves may be from the
// nominal one the poses are planned on (planner::PlanOptions::tolerance_sigma).
Eigen::VectorXd truth_spread(const SimulatedCell& cell);

// Actuator readings of `count` measurement poses planned on the cell's plan_cell (planner:
// feasible on the nominal robot and seen whole by both cameras as placed, selected by
// observability with the planner's default index, in selection order). Empty when nothing could be
// planned; `summary` says what was planned or why not.
std::vector<Eigen::VectorXd> plan_cell_poses(const SimulatedCell& cell, int count,
                                             std::mt19937& rng, std::string* summary);

// A rendered image with the seed it was rendered with.
struct RenderedImage {
  cv::Mat image;
  std::string name;
};

// The small elastic deflection of a real robot under its own weight, which no kinematic model
// holds: the frame sinks along the world's -z by `sag` times the square of its horizontal
// distance from the world's z axis (the robot's base axis), as a cantilever's tip sags more the
// further it reaches (1e-4 /m: 16 µm at 0.4 m, 64 µm at 0.8 m). Position only.
inline Eigen::Isometry3d elastic_deflection(Eigen::Isometry3d world_T_frame, double sag) {
  const Eigen::Vector3d p = world_T_frame.translation();
  world_T_frame.translation().z() -= sag * (p.x() * p.x() + p.y() * p.y());
  return world_T_frame;
}

// Pose of `body` in the truth world for actuator readings (closure solved on the true robot,
// then the cell's elastic deflection).
// Returns false when the closure cannot be solved.
bool true_frame_pose(const SimulatedCell& cell, const Eigen::VectorXd& readings,
                     Eigen::Isometry3d* world_T_frame);

// How many of the cell's (true) cameras see every corner of the end-effector board at
// `world_T_board`; a pose is recorded when it reaches plan_cell.cameras_needed().
int cameras_seeing_board(const SimulatedCell& cell, const Eigen::Isometry3d& world_T_board);

// Reads actuator values as a controller would: quantised with noise.
Eigen::VectorXd read_actuators(const SimulatedCell& cell, const Eigen::VectorXd& true_readings,
                               std::mt19937& rng);

// camera_T_board views of the calibration board for intrinsic calibration of one camera: board
// 0.6–1.1 m away, tilted 10–50°, its centre spread over a grid of image positions.
std::vector<Eigen::Isometry3d> intrinsic_view_poses(const SimulatedCell& cell, int camera,
                                                    int count, std::mt19937& rng);

// world_T_board views of the calibration board inside the working volume seen by all cameras
// (a pair), or, for an array, by two cameras at least: around each station's look-at point and
// between stations (the views that chain the rig), in turn.
std::vector<Eigen::Isometry3d> rig_view_poses(const SimulatedCell& cell, int count,
                                              std::mt19937& rng);

}  // namespace robocal::app
