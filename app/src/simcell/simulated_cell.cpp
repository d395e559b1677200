#include "simcell/simulated_cell.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/frame_placement.hpp"
#include "robocal/calib/identification.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/planner/feasibility.hpp"
#include "robocal/planner/plan.hpp"
#include "robocal/planner/task_sampling.hpp"
#include "robocal/vision/pose.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

namespace robocal::app {

namespace {

constexpr double kPi = 3.14159265358979323846;

Eigen::Vector2d board_centre(const vision::TargetBoard& board) {
  return 0.5 * (board.extent_min + board.extent_max);
}

// A rotation that tilts the board by `tilt` about a random in-plane axis, then turns it by `yaw`
// about its normal.
Eigen::Matrix3d random_tilt(double tilt, double yaw, std::mt19937& rng) {
  std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
  const double a = angle(rng);
  const Eigen::Vector3d axis(std::cos(a), std::sin(a), 0.0);
  return (Eigen::AngleAxisd(tilt, axis) * Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()))
      .toRotationMatrix();
}

vision::CameraModel true_camera(const CellOptions& o, std::mt19937& rng) {
  std::normal_distribution<double> unit(0.0, 1.0);
  const double f = o.focal_px * (1.0 + 0.01 * unit(rng));
  const double cx = 0.5 * (o.image_width - 1) + 8.0 * unit(rng);
  const double cy = 0.5 * (o.image_height - 1) + 8.0 * unit(rng);
  // A typical industrial lens: barrel distortion, small decentring.
  const std::vector<double> distortion = {-0.08 + 0.01 * unit(rng), 0.06 + 0.01 * unit(rng),
                                          2e-4 * unit(rng), 2e-4 * unit(rng), 0.0};
  return vision::make_camera(vision::CameraKind::kPinholeRadtan, o.image_width, o.image_height, f,
                             f * (1.0 + 1e-3 * unit(rng)), cx, cy, distortion);
}

// Fraction of a board's corners visible in a camera at camera_T_board.
double visible_fraction(const vision::CameraModel& camera, const vision::TargetBoard& board,
                        const Eigen::Isometry3d& camera_T_board,
                        const vision::RenderOptions& options) {
  const auto truth = vision::corner_truth(camera, {{board, camera_T_board}}, options);
  if (truth.empty()) return 0.0;
  const auto seen =
      std::count_if(truth.begin(), truth.end(), [](const auto& c) { return c.visible; });
  return static_cast<double>(seen) / static_cast<double>(truth.size());
}

// How far the collision shapes rigidly attached to `frame` (its body, the fixed bodies above it
// and the first moving body they hang from) reach along the world `direction` at readings `q`:
// the largest direction . p over their points; -inf when there are none.
double farthest_rigid_shape_point(const calib::Mechanism& model, const Eigen::VectorXd& params,
                                  const Eigen::VectorXd& q, int frame,
                                  const Eigen::Vector3d& direction) {
  double farthest = -std::numeric_limits<double>::infinity();
  for (int b = frame; b >= 0;) {
    const calib::Body& body = model.bodies.at(static_cast<std::size_t>(b));
    if (!body.collision.empty()) {
      const auto fk = calib::forward_kinematics(model, params, q, b);
      if (fk.closure.ok()) {
        for (const calib::CollisionShape& shape : body.collision) {
          if (shape.kind == calib::ShapeKind::kCapsule) {
            farthest = std::max(farthest, std::max(direction.dot(fk.pose * shape.a),
                                                   direction.dot(fk.pose * shape.b)) +
                                              shape.radius);
          } else {
            for (int k = 0; k < 8; ++k) {
              const Eigen::Vector3d corner(k & 1 ? 1.0 : -1.0, k & 2 ? 1.0 : -1.0,
                                           k & 4 ? 1.0 : -1.0);
              farthest = std::max(
                  farthest,
                  direction.dot(fk.pose *
                                (shape.a + shape.rotation * corner.cwiseProduct(shape.half_size))));
            }
          }
        }
      }
    }
    if (body.joint != calib::JointType::kFixed) break;
    b = body.parent;
  }
  return farthest;
}

// Lowest world z of those shapes; +inf when none.
double lowest_rigid_shape_point(const calib::Mechanism& model, const Eigen::VectorXd& params,
                                const Eigen::VectorXd& q, int frame) {
  return -farthest_rigid_shape_point(model, params, q, frame, -Eigen::Vector3d::UnitZ());
}

// Fraction of 1500 joint-space samples that are reachable, collision-free and seen whole by
// both cameras of `placement`, among those reachable and collision-free (fixed seed: the same
// samples for every placement compared).
double placement_coverage(const SimulatedCell& cell, const planner::CameraPlacement& placement) {
  const planner::Cell placed = planner::with_cameras(cell.plan_cell, placement);
  planner::FeasibilityOptions options = planner::feasibility_options_from_cell(placed);
  options.tolerance_draws = 0;  // what the cameras see; the reach edge's margin is the plan's
  const planner::FeasibilityChecker checker(cell.model, cell.nominal, placed, cell.target_frame,
                                            options);
  std::mt19937 rng(17);
  // A serial arm's board faces every way in joint samples: measure with the task-space
  // candidates the poses will be planned from (plan_cell_poses).
  if (planner::task_space_sampling_applies(checker)) {
    const auto cands = planner::sample_facing_cameras(checker, 400, rng, nullptr);
    const auto seen = std::count_if(cands.begin(), cands.end(),
                                    [](const planner::Candidate& c) { return c.feasible(); });
    return static_cast<double>(seen) / static_cast<double>(cands.size());
  }
  std::size_t reachable = 0, seen = 0;
  for (const planner::Candidate& c : checker.sample(1500, rng, nullptr)) {
    if (c.rejection != planner::Rejection::kNone && c.rejection < planner::Rejection::kFacingAway)
      continue;
    ++reachable;
    seen += c.feasible() ? 1 : 0;
  }
  return reachable > 0 ? static_cast<double>(seen) / static_cast<double>(reachable) : 0.0;
}

// A board hung on the side of a platform that keeps its orientation, where no camera sees a
// level board under it (the linear Delta: its bed hides the face looking down from every camera
// below it, and a camera between bed and effector would be too close): the board stands
// vertically, its printed face looking out along `face` (horizontal, world), its top edge just
// under the platform's shapes and its plane just in front of them, centred on the tool point.
// It takes 4 x 4 tags, at most a third of the height the platform travels (`travel`), so that
// it clears the bed over most of the range.
struct SideMount {
  vision::TargetBoard board;       // for the cell's renderer
  vision::TargetBoard plan_board;  // the same, for its plan cell (boards are moved, not copied)
  Eigen::VectorXd nominal;         // the nominal parameters with the board's mount
  planner::CameraPlacement placement;
  double coverage = 0.0;
};

vision::TargetBoard side_board(const CellOptions& options, double travel) {
  vision::TargetSpec spec;
  spec.kind = vision::TargetKind::kAprilTagGrid;
  spec.name = "end_effector";
  spec.cols = spec.rows = 4;
  spec.tag_size = options.ee_tag_size;
  spec.tag_spacing = options.ee_tag_spacing;
  spec.first_id = 0;
  const vision::TargetBoard full = vision::build_target(spec);
  const double height = full.extent_max.y() - full.extent_min.y();
  const double scale = std::min(1.0, travel / 3.0 / height);
  spec.tag_size *= scale;
  spec.tag_spacing *= scale;
  return vision::build_target(spec);
}

Eigen::Isometry3d side_board_pose(const SimulatedCell& cell, const vision::TargetBoard& board,
                                  const Eigen::VectorXd& q, const Eigen::Isometry3d& tool,
                                  const Eigen::Vector3d& face) {
  // Board axes: z away from the printed face, x horizontal, y down (the rows hang downwards).
  Eigen::Isometry3d world_T_board = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d z = -face;
  const Eigen::Vector3d y = -Eigen::Vector3d::UnitZ();
  world_T_board.linear().col(0) = y.cross(z);
  world_T_board.linear().col(1) = y;
  world_T_board.linear().col(2) = z;
  const Eigen::Vector3d at = tool.translation();
  const double front =
      std::max(face.dot(at),
               farthest_rigid_shape_point(cell.model, cell.nominal, q, cell.target_frame, face));
  const double top =
      std::min(at.z(), lowest_rigid_shape_point(cell.model, cell.nominal, q, cell.target_frame));
  // The top edge's middle, 5 mm below and 5 mm in front of the platform.
  Eigen::Vector3d top_middle = at + (front - face.dot(at) + 0.005) * face;
  top_middle.z() = top - 0.005;
  const Eigen::Vector2d middle = board_centre(board);
  world_T_board.translation() =
      top_middle - world_T_board.linear() * Eigen::Vector3d(middle.x(), board.extent_min.y(), 0.0);
  return world_T_board;
}

SideMount best_side_mount(const SimulatedCell& cell, const Eigen::VectorXd& q,
                          const Eigen::Isometry3d& tool, const planner::PlacementOptions& options) {
  SideMount best;
  const double travel = 2.0 * cell.volume_extent.z();
  for (const Eigen::Vector3d& face : {Eigen::Vector3d(0, -1, 0), Eigen::Vector3d(1, 0, 0),
                                      Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(-1, 0, 0)}) {
    SimulatedCell side = cell;
    side.ee_board = side_board(cell.options, travel);
    side.plan_cell.target.board = side_board(cell.options, travel);
    calib::set_fixed_frame_pose(side.model, side.nominal, side.target_frame, q,
                                side_board_pose(cell, side.ee_board, q, tool, face));
    try {
      side.placement = planner::propose_cameras(side.model, side.nominal, side.plan_cell, options);
    } catch (const std::invalid_argument&) {
      continue;
    }
    const double coverage = placement_coverage(side, side.placement);
    if (coverage > best.coverage) {
      best.board = std::move(side.ee_board);
      best.plan_board = std::move(side.plan_cell.target.board);
      best.nominal = side.nominal;
      best.placement = side.placement;
      best.coverage = coverage;
    }
  }
  return best;
}

// The end-effector board is mounted by moving the tool frame's own parameters
// (set_fixed_frame_pose): that is only a mounting when the tool is a fixed frame outside every
// loop. Refuses anything else before any work, in words (it would otherwise surface as an
// internal "closure failed while placing a frame").
void check_mountable(const calib::Mechanism& model, int target_frame,
                     const std::string& robot_file) {
  const calib::Body& tool = model.bodies.at(static_cast<std::size_t>(target_frame));
  bool in_loop = false;
  for (const calib::Closure& c : model.closures)
    in_loop = in_loop || (c.body_a >= target_frame && c.body_a < tool.subtree_end) ||
              (c.body_b >= target_frame && c.body_b < tool.subtree_end);
  // Identification places the robot in the cameras' world by moving its first body, which must
  // therefore be a fixed base frame.
  const calib::Body& root = model.bodies.front();
  if (root.joint != calib::JointType::kFixed)
    throw calib::RobotFileError(robot_file + ":" + std::to_string(root.line) +
                                ": the first body '" + root.name +
                                "' is a moving joint: a robot needs a fixed base frame first, "
                                "from which the mechanism hangs (testdata/robots/README.md)");
  if (tool.joint != calib::JointType::kFixed || in_loop)
    throw calib::RobotFileError(
        robot_file + ":" + std::to_string(tool.line) + ": the tool frame '" + tool.name + "' is " +
        (in_loop ? "part of a closed loop" : "a moving joint") +
        ": a simulated target cannot be mounted on it without changing the mechanism; add a "
        "fixed tool frame on the output link (testdata/robots/README.md)");
}

// The end-effector target (CellOptions::ee_tags, 29 cm by default).
vision::TargetSpec end_effector_spec(const CellOptions& options) {
  vision::TargetSpec ee;
  ee.kind = vision::TargetKind::kAprilTagGrid;
  ee.name = "end_effector";
  ee.cols = options.ee_tags;
  ee.rows = options.ee_tags;
  ee.tag_size = options.ee_tag_size;
  ee.tag_spacing = options.ee_tag_spacing;
  ee.first_id = 0;
  return ee;
}

// A hand-held calibration board with its own id range, so that it can never be confused with
// the end-effector target.
vision::TargetSpec calibration_spec(const vision::TargetSpec& ee) {
  vision::TargetSpec cal = ee;
  cal.name = "calibration";
  cal.cols = 7;
  cal.rows = 5;
  cal.tag_size = 0.05;
  cal.tag_spacing = 0.015;
  cal.first_id = 100;
  return cal;
}

// The working volume: where the nominal robot goes over its actuator range (200 sampled
// configurations, the tool poses of those that close, and their bounding box).
struct WorkingVolume {
  std::vector<Eigen::VectorXd> configs;
  std::vector<Eigen::Isometry3d> tool_poses;
  Eigen::Vector3d centre, extent;  // of the box, half sizes
};

WorkingVolume working_volume(const calib::Mechanism& model, const Eigen::VectorXd& nominal,
                             int target_frame, const std::string& robot_file, std::mt19937& rng) {
  WorkingVolume v;
  calib::MechanismPredictor nominal_predictor(model);
  v.configs = calib::sample_actuators(nominal_predictor, {nominal}, 200, rng);
  if (v.configs.size() < 20)
    throw calib::RobotFileError(fmt::format(
        "{}: too few reachable configurations to build a cell: the robot assembles at {} of "
        "up to 20000 random actuator readings within its limits (200 looked for, at least 20 "
        "needed): it cannot assemble over most of its actuator range; check its lengths "
        "(metres), its joint limits and home values (`robocal kin check {}`)",
        robot_file, v.configs.size(), robot_file));
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e9), hi = -lo;
  for (const auto& q : v.configs) {
    const auto fk = calib::forward_kinematics(model, nominal, q, target_frame);
    if (!fk.closure.ok()) continue;
    v.tool_poses.push_back(fk.pose);
    lo = lo.cwiseMin(fk.pose.translation());
    hi = hi.cwiseMax(fk.pose.translation());
  }
  v.centre = 0.5 * (lo + hi);
  v.extent = 0.5 * (hi - lo);
  return v;
}

// The elastic sag's law, scaled down where the robot reaches far enough to sag more than
// kMaxElasticSag by it.
double elastic_sag_law(const std::vector<Eigen::Isometry3d>& tool_poses, double elastic_sag) {
  double reach2 = 0.0;
  for (const Eigen::Isometry3d& p : tool_poses)
    reach2 = std::max(reach2, p.translation().head<2>().squaredNorm());
  return reach2 * elastic_sag > kMaxElasticSag ? kMaxElasticSag / reach2 : elastic_sag;
}

// Where the end-effector board is designed to be, at the working volume's first configuration
// (the designed mount is the nominal tool).
Eigen::Isometry3d designed_board_pose(const SimulatedCell& cell, const WorkingVolume& volume) {
  // The board is mounted 1 cm below the tool point, level, facing down at the cameras (its z
  // axis points up, away from them), centred on the tool point. On a body whose collision
  // shapes reach lower than that (the Gantry-Tau's 10 cm platform box around its tool point),
  // the board goes on the shapes' underside instead, where a camera can see it (the planner's
  // lines of sight are blocked by the robot's own shapes).
  const Eigen::Isometry3d& first = volume.tool_poses.front();
  Eigen::Isometry3d world_T_board = Eigen::Isometry3d::Identity();
  const Eigen::Vector2d c = board_centre(cell.ee_board);
  const double board_z =
      std::min(first.translation().z() - 0.01,
               lowest_rigid_shape_point(cell.model, cell.nominal, volume.configs.front(),
                                        cell.target_frame));
  world_T_board.translation() =
      Eigen::Vector3d(first.translation().x() - c.x(), first.translation().y() - c.y(), board_z);
  // A serial arm (no loops) whose task is the tool's full pose: the board goes on the flange,
  // its printed face looking out along the tool's z axis, 1 cm in front of it. Level in the
  // world at one random configuration (the rule above) would leave it at an arbitrary angle to
  // the flange, edge-on with the wrist's links in front of its face in every orientation (UR5:
  // no pose of 40 000 the planner sampled was seen whole by a camera pair).
  if (cell.model.closures.empty() && cell.model.task.type == calib::TaskType::kPose) {
    const Eigen::Isometry3d& flange = first;
    world_T_board.linear() =
        flange.linear() * Eigen::AngleAxisd(kPi, Eigen::Vector3d::UnitX()).toRotationMatrix();
    world_T_board.translation() = flange * Eigen::Vector3d(0.0, 0.0, 0.01) -
                                  world_T_board.linear() * Eigen::Vector3d(c.x(), c.y(), 0.0);
  }
  // A robot whose own joints turn the target with fewer than six actuators (the wire robot's
  // platform, pitch and yaw): the board across the tool's z axis (the last joint's), its face
  // looking out along the tool's x, 1 cm from the tool point, so that the last two joints turn
  // it as a pan-tilt head would (planner/task_sampling.hpp aims it at the cameras). Level at a
  // random configuration, its face would lie at a random angle to the yaw axis: where that angle
  // is small, the yaw only spins it about its face.
  if (planner::target_turned_by_joints(cell.model, cell.target_frame)) {
    const Eigen::Isometry3d& tool = first;
    world_T_board.linear() =
        tool.linear() * Eigen::AngleAxisd(-kPi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
    world_T_board.translation() = tool * Eigen::Vector3d(0.01, 0.0, 0.0) -
                                  world_T_board.linear() * Eigen::Vector3d(c.x(), c.y(), 0.0);
  }
  return world_T_board;
}

// The true robot: every parameter the robot file lets identification estimate, perturbed; with
// an unmodelled seed, the parameters it holds too (from their own random stream).
Eigen::VectorXd true_parameters(const calib::Mechanism& model, const Eigen::VectorXd& nominal,
                                const CellOptions& options, std::mt19937& rng) {
  const Eigen::VectorXd sigma =
      calib::tolerance_sigmas(model, options.length_sigma, options.angle_sigma);
  Eigen::VectorXd truth = calib::perturb_parameters(nominal, sigma, rng);
  if (options.unmodelled_seed != 0) {
    std::mt19937 unmodelled_rng(options.unmodelled_seed);
    const Eigen::VectorXd all =
        calib::tolerance_sigmas(model, options.length_sigma, options.angle_sigma, 0.0, true);
    const Eigen::VectorXd held = (sigma.array() == 0.0).select(all, 0.0);
    truth = calib::perturb_parameters(truth, held, unmodelled_rng);
  }
  return truth;
}

// The planner's view of the cell before calibration: two cameras with the nominal intrinsics
// (poses to be placed), the end-effector board on the tool frame.
planner::Cell planning_cell(const SimulatedCell& cell) {
  const CellOptions& options = cell.options;
  planner::Cell plan;
  plan.name = "simulated";
  plan.source = "simulated cell";
  for (int i = 0; i < 2; ++i) {
    planner::CellCamera cam;
    cam.name = "cam" + std::to_string(i);
    cam.file = "(simulated)";
    cam.model = vision::make_camera(vision::CameraKind::kPinholeRadtan, options.image_width,
                                    options.image_height, options.focal_px, options.focal_px,
                                    0.5 * (options.image_width - 1),
                                    0.5 * (options.image_height - 1), {0.0, 0.0, 0.0, 0.0, 0.0});
    plan.cameras.push_back(cam);
  }
  plan.target.board = vision::TargetBoard(cell.ee_board);  // (a copy, moved in)
  plan.target.frame = cell.model.bodies.at(static_cast<std::size_t>(cell.target_frame)).name;
  plan.target.file = "(simulated)";
  plan.visibility.min_image_size = options.min_board_image;
  return plan;
}

// A camera pair at the triangulation angle, or an array of pairs where one pair sees too little
// of the robot's range (below a quarter: the Gantry-Tau's guideways, 6 %; the modular arm's
// reach, 13 %; the four-bar's pair sees 45 % and keeps it). A six-axis arm keeps its pair: its
// wrist turns the board towards the pair anywhere in its reach, and its poses are planned that
// way (UR5: 26-38 µm held-out with 3 %). The modular arm has no wrist: with one pair its seed 3
// extrapolated to 62.5 µm, with an array of three pairs 33.6 µm.
planner::PlacementOptions placement_options(const calib::Mechanism& model,
                                            const CellOptions& options) {
  planner::PlacementOptions placement;
  placement.cameras = 2;
  placement.triangulation_angle = options.triangulation_angle;
  const bool wrist_faces_the_pair = model.closures.empty() && model.actuated.size() >= 6;
  placement.max_cameras = wrist_faces_the_pair ? 2 : options.max_cameras;
  placement.min_coverage = 0.25;
  return placement;
}

// A fixed pair 1.25 m below the volume's centre, looking up, 0.5 m apart.
planner::CameraPlacement fixed_pair_below(const Eigen::Vector3d& centre) {
  planner::CameraPlacement fixed;
  fixed.look_at = centre;
  fixed.view_direction = -Eigen::Vector3d::UnitZ();
  fixed.distance = 1.25;
  fixed.baseline = 0.5;
  for (int i = 0; i < 2; ++i)
    fixed.world_T_camera.push_back(
        vision::camera_T_board_look_at(
            centre + Eigen::Vector3d((i == 0 ? -0.25 : 0.25), 0.0, -1.25), centre,
            Eigen::Vector3d::UnitY())
            .inverse());
  return fixed;
}

// The cameras placed by the planner to see the board over the working volume (the nominal robot
// and intrinsics: what is known before calibration). Where the proposal sees none of the
// sampled reachable poses of a platform robot (a level board its own bed hides from every
// camera below it), the board goes on the platform's side instead (best_side_mount), moving the
// designed mount. Where nothing sees the board either way, the fixed pair below the volume
// (fixed_pair_below): the renderer draws the board alone, so it sees random poses, which the
// simulation then falls back to.
void place_cameras(SimulatedCell& cell, const WorkingVolume& volume,
                   const planner::PlacementOptions& placement, const std::string& robot_file) {
  try {
    cell.placement = planner::propose_cameras(cell.model, cell.nominal, cell.plan_cell, placement);
  } catch (const std::invalid_argument& e) {
    throw calib::RobotFileError(robot_file + ": no camera placement for this robot: " + e.what());
  }
  planner::CameraPlacement fixed = fixed_pair_below(cell.volume_centre);
  double proposed = placement_coverage(cell, cell.placement);
  if (proposed <= 0.0 && !cell.model.closures.empty() &&
      !planner::target_turned_by_joints(cell.model, cell.target_frame)) {
    SideMount side =
        best_side_mount(cell, volume.configs.front(), volume.tool_poses.front(), placement);
    if (side.coverage > 0.0) {
      // The true robot keeps its random draws: only the designed mount moves.
      cell.truth += side.nominal - cell.nominal;
      cell.nominal = side.nominal;
      cell.ee_board = std::move(side.board);
      cell.plan_cell.target.board = std::move(side.plan_board);
      cell.placement = side.placement;
      proposed = side.coverage;
    }
  }
  if (proposed <= 0.0) {
    const double kept = placement_coverage(cell, fixed);
    fixed.coverage = kept;
    fixed.summary =
        "the fixed pair 1.25 m below the working volume's centre, looking up, 0.5 m "
        "apart (it sees the target at " +
        std::to_string(static_cast<int>(std::lround(100 * kept))) +
        " % of sampled reachable poses; the planner's proposal " +
        std::to_string(static_cast<int>(std::lround(100 * proposed))) +
        " %: " + cell.placement.summary + ")";
    cell.placement = fixed;
  }
}

}  // namespace

CellOptions::CellOptions() {
  render.black_level = 20.0;
  render.white_level = 220.0;
  render.background_level = 60.0;
  render.blur_sigma = 0.8;
  render.read_noise = 2.0;
  render.vignetting = 0.15;
  render.lighting_gradient = Eigen::Vector2d(0.05, -0.03);
}

bool true_frame_pose(const SimulatedCell& cell, const Eigen::VectorXd& readings,
                     Eigen::Isometry3d* world_T_frame) {
  const auto fk = calib::forward_kinematics(cell.model, cell.truth, readings, cell.target_frame);
  if (!fk.closure.ok()) return false;
  *world_T_frame = elastic_deflection(fk.pose, cell.elastic_sag);
  return true;
}

int cameras_seeing_board(const SimulatedCell& cell, const Eigen::Isometry3d& world_T_board) {
  int seeing = 0;
  for (const SimulatedCamera& cam : cell.cameras) {
    const auto corners = vision::corner_truth(
        cam.model, {{cell.ee_board, cam.camera_T_world * world_T_board}}, cell.options.render);
    seeing += std::all_of(corners.begin(), corners.end(), [](const auto& t) { return t.visible; })
                  ? 1
                  : 0;
  }
  return seeing;
}

Eigen::VectorXd read_actuators(const SimulatedCell& cell, const Eigen::VectorXd& true_readings,
                               std::mt19937& rng) {
  std::normal_distribution<double> noise(0.0, cell.options.actuator_noise);
  Eigen::VectorXd read = true_readings;
  for (Eigen::Index i = 0; i < read.size(); ++i) {
    const double step = cell.options.actuator_step;
    read[i] = std::round((read[i] + noise(rng)) / step) * step;
  }
  return read;
}

CellOptions demo_cell_options(unsigned seed, bool quick, bool idealised_truth) {
  CellOptions co;
  if (quick) {
    co.image_width = 1280;
    co.image_height = 960;
    co.focal_px = 1300;
  }
  // Unmodelled error from its own stream: the idealised and the realistic truth share every
  // other draw (cameras, views, poses).
  co.unmodelled_seed = idealised_truth ? 0U : 7919U * seed + 17U;
  co.elastic_sag = idealised_truth ? 0.0 : 1e-4;  // m per m^2
  return co;
}

SimulatedCell make_simulated_cell(const std::string& robot_file, const CellOptions& options,
                                  std::mt19937& rng) {
  SimulatedCell cell;
  cell.options = options;
  cell.model = calib::load_robot_file(robot_file);
  cell.nominal = cell.model.nominal_parameters();
  cell.target_frame = cell.model.tool;
  check_mountable(cell.model, cell.target_frame, robot_file);

  const vision::TargetSpec ee = end_effector_spec(options);
  cell.ee_board = vision::build_target(ee);
  cell.calibration_board = vision::build_target(calibration_spec(ee));

  const WorkingVolume volume =
      working_volume(cell.model, cell.nominal, cell.target_frame, robot_file, rng);
  cell.volume_centre = volume.centre;
  cell.volume_extent = volume.extent;
  cell.elastic_sag = elastic_sag_law(volume.tool_poses, options.elastic_sag);
  calib::set_fixed_frame_pose(cell.model, cell.nominal, cell.target_frame, volume.configs.front(),
                              designed_board_pose(cell, volume));
  cell.truth = true_parameters(cell.model, cell.nominal, options, rng);

  cell.plan_cell = planning_cell(cell);
  place_cameras(cell, volume, placement_options(cell.model, options), robot_file);
  cell.plan_cell = planner::with_cameras(cell.plan_cell, cell.placement);
  for (std::size_t i = 0; i < cell.placement.world_T_camera.size(); ++i) {
    SimulatedCamera cam;
    cam.model = true_camera(options, rng);
    cam.camera_T_world = cell.placement.world_T_camera[i].inverse();
    cam.rays = std::make_shared<const vision::CameraRays>(vision::precompute_rays(cam.model));
    cell.cameras.push_back(std::move(cam));
  }
  return cell;
}

Eigen::VectorXd truth_spread(const SimulatedCell& cell) {
  return calib::tolerance_sigmas(cell.model, cell.options.length_sigma, cell.options.angle_sigma,
                                 0.0, cell.options.unmodelled_seed != 0);
}

std::vector<Eigen::VectorXd> plan_cell_poses(const SimulatedCell& cell, int count,
                                             std::mt19937& rng, std::string* summary) {
  planner::PlanOptions po;
  po.tolerance_sigma = truth_spread(cell);
  po.selection.count = static_cast<std::size_t>(std::max(count, 1));
  // Joint-space samples: enough for a pool of many times `count` feasible poses on the robots
  // whose cells see a small part of their range.
  po.pool = std::max<std::size_t>(4000, 60 * po.selection.count);
  po.seed = static_cast<unsigned>(rng());
  // No tour: a simulated robot moves between poses instantly, and the order changes nothing.
  po.order = false;
  planner::PlanResult res;
  try {
    // A cell that sees a small part of the robot's range: sampled again, enough for a pool of
    // about ten times `count` feasible poses (at most 40 000 samples).
    res = planner::plan_with_enough_candidates(cell.model, cell.nominal, cell.plan_cell, po);
    const std::size_t want = 10 * po.selection.count;
    // A serial arm's board, in a random orientation from joint samples, faces the camera pair
    // at the cell's incidence and size almost never (UR5: 0 of 40 000; the wire robot: 1-2 %):
    // build the candidates in task space instead (the board turned towards the cameras: IK on
    // the intended mode, or, with fewer than six actuators, as far as the joints turn it), and
    // keep whichever pool is larger. The planner's verdicts stand either way.
    if (res.pool.size() < want && res.status != planner::PlanStatus::kBadCell &&
        planner::target_turnable(cell.model, cell.target_frame)) {
      planner::PlanOptions task = po;
      task.task_space = true;
      task.pool = std::max<std::size_t>(4000, 60 * po.selection.count);
      planner::PlanResult by_task =
          planner::plan_measurements(cell.model, cell.nominal, cell.plan_cell, task);
      if (by_task.pool.size() > res.pool.size()) res = std::move(by_task);
    }
  } catch (const std::exception& e) {
    *summary = e.what();
    return {};
  }
  std::vector<Eigen::VectorXd> out;
  for (const planner::PlannedPose& p : res.poses) out.push_back(p.readings);
  if (out.empty()) {
    *summary = res.message;
    return out;
  }
  *summary = "planned " + std::to_string(out.size()) + " poses from " +
             std::to_string(res.pool.size()) + " feasible of " +
             std::to_string(res.counts.evaluated) + " sampled: " + res.selection.message;
  return out;
}

std::vector<Eigen::Isometry3d> intrinsic_view_poses(const SimulatedCell& cell, int camera,
                                                    int count, std::mt19937& rng) {
  const auto& cam = cell.cameras.at(static_cast<std::size_t>(camera)).model;
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const Eigen::Vector2d c = board_centre(cell.calibration_board);
  std::vector<Eigen::Isometry3d> views;
  // Board centres spread over a 3x3 grid of image regions (then random inside the region), so
  // the whole image is covered, as a careful operator would.
  for (int v = 0; v < count; ++v) {
    for (int attempt = 0; attempt < 100; ++attempt) {
      const int region = v % 9;
      const int region_column = region % 3, region_row = region / 3;
      const double px = (region_column + u(rng)) / 3.0 * cam.width;
      const double py = (region_row + u(rng)) / 3.0 * cam.height;
      const auto ray = vision::unproject(cam, Eigen::Vector2d(px, py));
      if (!ray) continue;
      const double distance = 0.6 + 0.5 * u(rng);
      const Eigen::Vector3d centre = *ray / ray->z() * distance;
      Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
      // One draw a statement, yaw first (robocal/core/random_draws.hpp says why).
      const double yaw = (u(rng) - 0.5) * 0.6;
      const double tilt = (10.0 + 40.0 * u(rng)) * kPi / 180.0;
      camera_T_board.linear() = random_tilt(tilt, yaw, rng);
      camera_T_board.translation() =
          centre - camera_T_board.linear() * Eigen::Vector3d(c.x(), c.y(), 0);
      if (visible_fraction(cam, cell.calibration_board, camera_T_board, cell.options.render) >=
          0.7) {
        views.push_back(camera_T_board);
        break;
      }
    }
  }
  return views;
}

std::vector<Eigen::Isometry3d> rig_view_poses(const SimulatedCell& cell, int count,
                                              std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Vector2d c = board_centre(cell.calibration_board);
  // Where the board is held: a pair's look-at point; for an array, every station's and the
  // midpoints of neighbouring stations (the views that chain one station's cameras to the
  // next's), taken in turn.
  struct Anchor {
    Eigen::Vector3d at;
    int station_a = -1, station_b = -1;  // both -1: every camera must see the board
  };
  std::vector<Anchor> anchors;
  const auto& looks = cell.placement.station_look_at;
  const int per = cell.placement.cameras_per_station;
  if (looks.size() < 2 || per < 1) {
    anchors.push_back({cell.placement.look_at, -1, -1});
  } else {
    for (std::size_t a = 0; a < looks.size(); ++a) {
      anchors.push_back({looks[a], static_cast<int>(a), static_cast<int>(a)});
      for (std::size_t b = a + 1; b < looks.size(); ++b)
        anchors.push_back({0.5 * (looks[a] + looks[b]), static_cast<int>(a), static_cast<int>(b)});
    }
  }
  auto sees = [&](std::size_t camera, const Eigen::Isometry3d& world_T_board) {
    const SimulatedCamera& cam = cell.cameras[camera];
    return visible_fraction(cam.model, cell.calibration_board, cam.camera_T_world * world_T_board,
                            cell.options.render) >= 0.5;
  };
  // Accepted: every camera sees it (a pair), or, in an array, two cameras at least, one of each
  // station the anchor joins.
  auto accepted = [&](const Anchor& anchor, const Eigen::Isometry3d& world_T_board) {
    int seeing = 0;
    bool in_a = false, in_b = false;
    for (std::size_t k = 0; k < cell.cameras.size(); ++k) {
      const bool s = sees(k, world_T_board);
      if (!s && anchor.station_a < 0) return false;
      seeing += s ? 1 : 0;
      const int station = per > 0 ? static_cast<int>(k) / per : 0;
      in_a = in_a || (s && station == anchor.station_a);
      in_b = in_b || (s && station == anchor.station_b);
    }
    return anchor.station_a < 0 || (seeing >= 2 && in_a && in_b);
  };
  // Rotation taking the board's z to the direction away from the cameras the anchor joins
  // (identity when they look straight up, as for the Delta): a pair's viewing direction; in an
  // array, the way to the joined stations' cameras. An array's stations need not look from one
  // side (the wire robot's look at its ring from several), and a board turned to the first
  // station's side is edge-on to the others.
  auto facing_for = [&](const Anchor& anchor) -> Eigen::Matrix3d {
    Eigen::Vector3d towards = cell.placement.view_direction;
    if (anchor.station_a >= 0) {
      Eigen::Vector3d eyes = Eigen::Vector3d::Zero();
      int n = 0;
      for (std::size_t k = 0; k < cell.cameras.size(); ++k) {
        const int station = static_cast<int>(k) / per;
        if (station != anchor.station_a && station != anchor.station_b) continue;
        eyes += cell.placement.world_T_camera[k].translation();
        ++n;
      }
      towards = (eyes / std::max(n, 1) - anchor.at).normalized();
    }
    return Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), -towards)
        .toRotationMatrix();
  };
  std::vector<Eigen::Isometry3d> views;
  for (int v = 0; v < count; ++v) {
    const Anchor& anchor = anchors[static_cast<std::size_t>(v) % anchors.size()];
    const Eigen::Matrix3d anchor_facing = facing_for(anchor);
    // A link between stations whose fields do not meet near the midpoint: spread wider.
    const double spread =
        anchor.station_a != anchor.station_b && anchor.station_a >= 0 ? 0.3 : 0.15;
    for (int attempt = 0; attempt < 200; ++attempt) {
      Eigen::Isometry3d world_T_board = Eigen::Isometry3d::Identity();
      // Printed face (board -z) towards the cameras, then tilted. One draw a statement, in the
      // order yaw, tilt, z, y, x (robocal/core/random_draws.hpp says why).
      const double yaw = u(rng) * kPi;
      const double tilt = std::abs(u(rng)) * 35.0 * kPi / 180.0;
      world_T_board.linear() = anchor_facing * random_tilt(tilt, yaw, rng);
      const double dz = u(rng) * 0.1;
      const double dy = u(rng) * spread;
      const double dx = u(rng) * spread;
      const Eigen::Vector3d centre = anchor.at + anchor_facing * Eigen::Vector3d(dx, dy, dz);
      world_T_board.translation() =
          centre - world_T_board.linear() * Eigen::Vector3d(c.x(), c.y(), 0);
      if (accepted(anchor, world_T_board)) {
        views.push_back(world_T_board);
        break;
      }
    }
  }
  return views;
}

}  // namespace robocal::app
