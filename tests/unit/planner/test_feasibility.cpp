// Feasibility and plans on the rotary Delta cell, checked against geometry written here (not the
// planner's functions): link capsules and the plate box from the robot file posed by calib's
// forward kinematics, distances by convex minimisation along segments, projections by vision's
// camera model.
#include "robocal/calib/assembly_mode.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/identification.hpp"
#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/planner/camera_placement.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/feasibility.hpp"
#include "robocal/planner/plan.hpp"
#include "robocal/planner/plan_output.hpp"
#include "robocal/planner/selection.hpp"
#include "robocal/planner/task_sampling.hpp"

#include "mode_sweep.hpp"

#include "independent_geometry.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <numbers>
#include <optional>
#include <random>
#include <sstream>

namespace robocal::planner {
namespace {

const std::string kData = std::string(ROBOCAL_TESTDATA_DIR);
const std::string kCells = kData + "/cells/";

// ---- independent geometry -------------------------------------------------------------------

using test::Box;
using test::convex_min;
using test::point_box;

double segment_box(const Eigen::Vector3d& a, const Eigen::Vector3d& c, const Box& b) {
  return convex_min([&](double t) { return point_box(a + t * (c - a), b); });
}
double point_segment(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const Eigen::Vector3d d = b - a;
  const double t = std::clamp((p - a).dot(d) / std::max(d.squaredNorm(), 1e-300), 0.0, 1.0);
  return (p - (a + t * d)).norm();
}
double segment_segment(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                       const Eigen::Vector3d& d) {
  return convex_min([&](double t) { return point_segment(a + t * (b - a), c, d); });
}
// Two boxes whose axes are parallel to the world axes (the Delta's plate stays level and the
// cell's fixture is axis-aligned): per-axis gaps.
double aligned_box_box(const Box& a, const Box& b) {
  const Eigen::Vector3d ha = a.rotation.cwiseAbs() * a.half, hb = b.rotation.cwiseAbs() * b.half;
  return ((a.centre - b.centre).cwiseAbs() - ha - hb).cwiseMax(0.0).norm();
}

struct Capsule {
  Eigen::Vector3d a, b;
  double radius;
  int body;
};

struct RobotGeometry {
  std::vector<Capsule> capsules;
  std::vector<Box> boxes;
  std::vector<Eigen::Isometry3d> poses;
};

// The Delta at a solved state: its robot-file shapes in the world.
RobotGeometry geometry_at(const calib::Mechanism& m, const calib::JointState& state) {
  RobotGeometry g;
  calib::body_poses(m, m.nominal_parameters(), state, g.poses);
  for (std::size_t b = 0; b < m.bodies.size(); ++b)
    for (const calib::CollisionShape& s : m.bodies[b].collision) {
      const Eigen::Isometry3d& T = g.poses[b];
      if (s.kind == calib::ShapeKind::kCapsule)
        g.capsules.push_back({T * s.a, T * s.b, s.radius, static_cast<int>(b)});
      else
        g.boxes.push_back({T * s.a, T.linear() * s.rotation, s.half_size});
    }
  return g;
}

Box obstacle_box(const Obstacle& o) {
  return {o.world_T_obstacle.translation(), o.world_T_obstacle.linear(), 0.5 * o.size};
}

// Smallest link-to-obstacle distance (surface to surface) over the cell's box obstacles.
double obstacle_distance(const RobotGeometry& g, const Cell& cell) {
  double d = 1e300;
  for (const Obstacle& o : cell.obstacles) {
    const Box ob = obstacle_box(o);
    for (const Capsule& c : g.capsules) d = std::min(d, segment_box(c.a, c.b, ob) - c.radius);
    for (const Box& b : g.boxes) d = std::min(d, aligned_box_box(b, ob));
  }
  return d;
}

// Rods of different arms (bodies 6,16 / 19,22 / 25,28): the self-collision pairs that matter.
double rod_rod_distance(const RobotGeometry& g) {
  double d = 1e300;
  for (std::size_t i = 0; i < g.capsules.size(); ++i)
    for (std::size_t j = i + 1; j < g.capsules.size(); ++j) {
      const Capsule &a = g.capsules[i], &b = g.capsules[j];
      if (a.radius > 0.02 || b.radius > 0.02) continue;  // the upper arms meet at the base
      d = std::min(d, segment_segment(a.a, a.b, b.a, b.b) - a.radius - b.radius);
    }
  return d;
}

struct Seen {
  bool visible = true;
  std::string why;
};

// The target seen by a camera: all corners inside the image with the margin, incidence, size,
// and every corner's line of sight (stopped 5 mm before the board) clear of the obstacles and
// of every link.
Seen seen_by(const Cell& cell, const CellCamera& cam, const Eigen::Isometry3d& world_T_board,
             const RobotGeometry& g) {
  Seen s;
  const Eigen::Isometry3d cTw = cam.world_T_camera.inverse();
  const Eigen::Vector3d eye = cam.world_T_camera.translation();
  Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const vision::TargetCorner& c : cell.target.board.corners) centre += world_T_board * c.point;
  centre /= static_cast<double>(cell.target.board.corners.size());
  const double incidence =
      std::acos((-world_T_board.linear().col(2)).dot((eye - centre).normalized()));
  if (incidence > cell.visibility.max_incidence) return {false, "incidence"};
  for (const vision::TargetCorner& c : cell.target.board.corners) {
    const Eigen::Vector3d p = world_T_board * c.point;
    const auto px = vision::project(cam.model, cTw * p);
    if (!px) return {false, "behind"};
    if (px->x() < -0.5 + cell.margins.image_border || px->y() < -0.5 + cell.margins.image_border ||
        px->x() > cam.model.width - 0.5 - cell.margins.image_border ||
        px->y() > cam.model.height - 0.5 - cell.margins.image_border)
      return {false, "outside image"};
    lo = lo.cwiseMin(*px);
    hi = hi.cwiseMax(*px);
    const Eigen::Vector3d end = p + 0.005 * (eye - p).normalized();
    for (const Obstacle& o : cell.obstacles)
      if (segment_box(eye, end, obstacle_box(o)) <= 0) return {false, "occluded by obstacle"};
    for (const Capsule& k : g.capsules)
      if (segment_segment(eye, end, k.a, k.b) <= k.radius) return {false, "occluded by link"};
    for (const Box& b : g.boxes)
      if (segment_box(eye, end, b) <= 0) return {false, "occluded by plate"};
  }
  // Level board facing a camera: the outline's image is close to a rectangle; its shorter side.
  if (std::min(hi.x() - lo.x(), hi.y() - lo.y()) < cell.visibility.min_image_size * 0.9)
    return {false, "small"};
  return s;
}

struct Delta {
  calib::Mechanism model = calib::load_robot_file(kData + "/robots/rotary_delta.yaml");
  Eigen::VectorXd params = model.nominal_parameters();
};

Delta& delta() {
  static Delta d;
  return d;
}

calib::JointState solve_state(const calib::Mechanism& m, const Eigen::VectorXd& readings,
                              const Eigen::VectorXd& seed = Eigen::VectorXd()) {
  const calib::ForwardResult f =
      calib::forward_kinematics(m, m.nominal_parameters(), readings, m.tool, seed);
  EXPECT_TRUE(f.closure.ok()) << calib::to_string(f.closure.status);
  return f.state;
}

// ---- tests ------------------------------------------------------------------------------------

TEST(Planner, EveryPlannedPoseAndMotionIsCollisionFreeAndVisible) {
  const Delta& d = delta();
  const Cell cell = load_cell_file(kCells + "delta_two_cameras.yaml");
  PlanOptions o;
  o.pool = 2500;
  o.selection.count = 25;
  const PlanResult plan = plan_measurements(d.model, d.params, cell, o);
  ASSERT_NE(plan.status, PlanStatus::kBadCell) << plan.message;
  ASSERT_EQ(plan.poses.size(), 25u) << plan.message;
  ASSERT_TRUE(plan.tour.complete);
  for (const PlannedPose& p : plan.poses) {
    const calib::JointState st = solve_state(d.model, p.readings);
    const RobotGeometry g = geometry_at(d.model, st);
    EXPECT_GE(obstacle_distance(g, cell), cell.margins.clearance - 1e-9) << p.id;
    EXPECT_GE(rod_rod_distance(g), cell.margins.self_clearance - 1e-9) << p.id;
    const Eigen::Isometry3d board =
        g.poses[static_cast<std::size_t>(d.model.tool)] * cell.target.frame_T_board;
    EXPECT_TRUE(
        cell.workspace.contains(g.poses[static_cast<std::size_t>(d.model.tool)].translation()));
    for (const CellCamera& cam : cell.cameras) {
      const Seen s = seen_by(cell, cam, board, g);
      EXPECT_TRUE(s.visible) << p.id << " camera " << cam.name << ": " << s.why;
    }
  }
  // Every motion of the tour, at 4x the planner's sampling density, warm-started (same mode).
  for (std::size_t k = 1; k < plan.poses.size(); ++k) {
    const Eigen::VectorXd& a = plan.poses[k - 1].readings;
    const Eigen::VectorXd& b = plan.poses[k].readings;
    const int steps = std::max(
        1, static_cast<int>(std::ceil((b - a).cwiseAbs().maxCoeff() / (o.motion_step / 4))));
    Eigen::VectorXd seed =
        calib::forward_kinematics(d.model, d.params, a, d.model.tool).closure.passive;
    for (int s = 1; s < steps; ++s) {
      const Eigen::VectorXd x = a + (b - a) * (static_cast<double>(s) / steps);
      const calib::ForwardResult f =
          calib::forward_kinematics(d.model, d.params, x, d.model.tool, seed);
      ASSERT_TRUE(f.closure.ok()) << "segment " << k << " step " << s;
      ASSERT_LT((f.closure.passive - seed).cwiseAbs().maxCoeff(), 0.2)
          << "mode jump on segment " << k;
      seed = f.closure.passive;
      const RobotGeometry g = geometry_at(d.model, f.state);
      ASSERT_GE(obstacle_distance(g, cell), cell.margins.clearance - 1e-3)
          << "segment " << k << " step " << s;  // between the planner's samples: <= 1 mm of motion
    }
  }
  // The plan file and the preview are written, the plan file names every pose.
  const std::string yaml = plan_to_yaml(d.model, cell, plan, o);
  for (const PlannedPose& p : plan.poses)
    EXPECT_NE(yaml.find("id: " + p.id + "\n"), std::string::npos);
  const std::string svg = plan_to_svg(cell, plan);
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  EXPECT_NE(svg.find("fixture"), std::string::npos);
}

TEST(Planner, ObstacleRemovesExactlyTheCandidatesThatReachIt) {
  const Delta& d = delta();
  const Cell cell = load_cell_file(kCells + "delta_two_cameras.yaml");
  const FeasibilityChecker checker(d.model, d.params, cell, d.model.tool,
                                   feasibility_options_from_cell(cell));
  std::mt19937 rng(11);
  FeasibilityCounts counts;
  int checked = 0, removed = 0, inside_region = 0;
  for (const Candidate& c : checker.sample(1500, rng, &counts)) {
    if (c.rejection != Rejection::kNone && c.rejection != Rejection::kObstacleCollision &&
        c.rejection != Rejection::kSelfCollision && c.rejection < Rejection::kFacingAway)
      continue;  // removed before the collision test (reach, workspace)
    const RobotGeometry g = geometry_at(d.model, solve_state(d.model, c.readings));
    const double dist = obstacle_distance(g, cell);
    if (std::abs(dist - cell.margins.clearance) < 1e-6) continue;  // on the boundary
    ++checked;
    const bool hit = dist < cell.margins.clearance;
    EXPECT_EQ(hit, c.rejection == Rejection::kObstacleCollision)
        << "distance " << dist << " " << c.detail;
    removed += hit ? 1 : 0;
    // The plate's centre inside the fixture's region (inflated by the clearance): always removed.
    const Box ob = obstacle_box(cell.obstacles[0]);
    if (point_box(g.poses[static_cast<std::size_t>(d.model.tool)].translation(), ob) <
        cell.margins.clearance) {
      ++inside_region;
      EXPECT_EQ(c.rejection, Rejection::kObstacleCollision);
    }
  }
  EXPECT_GT(checked, 200);
  EXPECT_GT(removed, 30);
  EXPECT_GT(inside_region, 3);
}

// One camera straight below x = -0.75 m: it sees the half of the workspace at x < 0 only.
TEST(Planner, CameraThatSeesHalfTheWorkspace) {
  const Delta& d = delta();
  const Cell cell = parse_cell_yaml(
      "cameras:\n  - {name: low, file: camera_1600x1200.yaml, pose: {position: [-0.75, 0, -2.4], "
      "look_at: [-0.75, 0, -0.9]}}\n"
      "workspace: {min: [-0.55, -0.55, -1.3], max: [0.55, 0.55, -0.5]}\n"
      "margins: {image_border: 20}\n"
      "target: {file: ../vision/apriltag_4x3.yaml, position: [0.054, -0.0735, -0.01], rpy: [0, 0, "
      "pi/2]}\n"
      "visibility: {min_image_size: 60}\n",
      "half.yaml", kCells);
  const FeasibilityChecker checker(d.model, d.params, cell, d.model.tool,
                                   feasibility_options_from_cell(cell));
  std::mt19937 rng(5);
  int left_seen = 0, left_total = 0, right_seen = 0, agree = 0;
  for (const Candidate& c : checker.sample(2500, rng, nullptr)) {
    if (c.rejection != Rejection::kNone && c.rejection < Rejection::kFacingAway) continue;
    const RobotGeometry g = geometry_at(d.model, solve_state(d.model, c.readings));
    const Eigen::Isometry3d board =
        g.poses[static_cast<std::size_t>(d.model.tool)] * cell.target.frame_T_board;
    const Seen s = seen_by(cell, cell.cameras[0], board, g);
    EXPECT_EQ(s.visible, c.feasible()) << s.why << " / " << c.detail;
    agree += s.visible == c.feasible() ? 1 : 0;
    const Eigen::Vector3d p = c.world_T_board * Eigen::Vector3d(0.0735, 0.054, 0);  // board centre
    // Image edge at depth z: x = -0.75 + (800 - 20.5) / 1600 * depth; the board half-width inside.
    const double depth = p.z() + 2.4;
    const double edge = -0.75 + (799.5 - 20) / 1600.0 * depth;
    if (c.feasible()) {
      EXPECT_LT(p.x(), edge) << "visible beyond the image edge";
    }
    if (p.x() < edge - 0.12 && std::abs(p.y()) < 0.3) {
      ++left_total;
      left_seen += c.feasible() ? 1 : 0;
    }
    if (p.x() > 0.2) right_seen += c.feasible() ? 1 : 0;
  }
  EXPECT_GT(left_total, 50);
  EXPECT_EQ(left_seen, left_total);  // well inside the image: always visible
  EXPECT_EQ(right_seen, 0);
  EXPECT_GT(agree, 100);
}

// The ball-joint cones: a candidate is removed exactly when a rod leaves its cone around the
// rod's direction at mid-range (computed here from the body poses); tighter cones remove the
// outer ring of the workspace.
TEST(Planner, BallJointConeRemovesTheOuterRing) {
  calib::Mechanism model = delta().model;
  for (calib::Body& b : model.bodies)
    if (b.limits.cone > 0) b.limits.cone = 20 * M_PI / 180;
  const Eigen::VectorXd params = model.nominal_parameters();
  const ReachChecker reach(model, params, ReachOptions{});
  ASSERT_EQ(reach.cones().size(), 5u);
  // Neutral rod directions, independently: rods at mid-range readings in the cut frames.
  const Eigen::VectorXd mid = reach.middle_readings();
  const calib::JointState mid_state = solve_state(model, mid);
  std::vector<Eigen::Isometry3d> mid_poses;
  calib::body_poses(model, params, mid_state, mid_poses);
  auto rod_in_cut = [&](const std::vector<Eigen::Isometry3d>& P, const calib::Closure& c) {
    const int rod_end = c.body_b;
    const int rod_top = model.bodies[static_cast<std::size_t>(rod_end)].parent;
    return (P[static_cast<std::size_t>(c.body_a)].linear().transpose() *
            (P[static_cast<std::size_t>(rod_end)].translation() -
             P[static_cast<std::size_t>(rod_top)].translation()))
        .normalized()
        .eval();
  };
  std::mt19937 rng(3);
  Eigen::VectorXd lo, hi;
  reach.reading_limits(lo, hi);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<double> kept_r, removed_r;
  for (int k = 0; k < 3000; ++k) {
    Eigen::VectorXd x(3);
    for (int i = 0; i < 3; ++i) x(i) = lo(i) + u(rng) * (hi(i) - lo(i));
    const ReachResult r = reach.reach_check(x);
    if (!r.ok() && r.verdict != ReachVerdict::kConeLimit) continue;
    const calib::ForwardResult f = calib::forward_kinematics(model, params, x, model.tool);
    std::vector<Eigen::Isometry3d> P;
    calib::body_poses(model, params, f.state, P);
    double worst = 0;
    for (const calib::Closure& c : model.closures)
      worst = std::max(
          worst, std::acos(std::clamp(rod_in_cut(P, c).dot(rod_in_cut(mid_poses, c)), -1.0, 1.0)));
    EXPECT_EQ(worst > 20 * M_PI / 180, r.verdict == ReachVerdict::kConeLimit) << worst * 180 / M_PI;
    const Eigen::Vector3d t = P[static_cast<std::size_t>(model.tool)].translation();
    const Eigen::Vector3d tm = mid_poses[static_cast<std::size_t>(model.tool)].translation();
    (r.ok() ? kept_r : removed_r).push_back((t - tm).norm());
  }
  ASSERT_GT(kept_r.size(), 50u);
  ASSERT_GT(removed_r.size(), 50u);
  // Outer ring: everything near the mid-range pose is kept, the removed poses lie farther out.
  std::sort(kept_r.begin(), kept_r.end());
  std::sort(removed_r.begin(), removed_r.end());
  EXPECT_GT(removed_r.front(), 0.05);
  EXPECT_GT(removed_r[removed_r.size() / 2], 1.5 * kept_r[kept_r.size() / 2]);
}

// A robot drawn within the tolerances (feasibility test 5) keeps the ball-joint sockets' neutral
// directions as built. It need not assemble at the middle of the actuator ranges, where the
// nominal checker solves them: with rod 26 shortened by 0.5 m no rod reaches the plate there, and
// solving again threw ("cannot assemble at the middle of its actuator ranges"), which would have
// stopped the planning of the nominal robot. Its reach test then answers (cannot assemble), and a
// feasibility checker whose tolerance draws include such robots is built and rejects every
// candidate as unreachable within the tolerances.
TEST(Planner, RobotsDrawnWithinTheTolerancesKeepTheNominalSocketCones) {
  const calib::Mechanism& model = delta().model;
  const Eigen::VectorXd& params = delta().params;
  const ReachChecker nominal(model, params, ReachOptions{});
  ASSERT_EQ(nominal.cones().size(), 5u);
  const int rod = model.parameter_index("body26.d1");
  ASSERT_GE(rod, 0);
  Eigen::VectorXd shortened = params;
  shortened[rod] -= 0.5;
  EXPECT_THROW(ReachChecker(model, shortened, ReachOptions{}), std::invalid_argument);
  const ReachChecker drawn = nominal.with_parameters(shortened, ReachOptions{});
  ASSERT_EQ(drawn.cones().size(), nominal.cones().size());
  for (std::size_t k = 0; k < drawn.cones().size(); ++k) {
    EXPECT_EQ(drawn.cones()[k].cut, nominal.cones()[k].cut);
    EXPECT_EQ(drawn.cones()[k].neutral, nominal.cones()[k].neutral);
  }
  EXPECT_EQ(drawn.reach_check(nominal.middle_readings()).verdict, ReachVerdict::kNoAssembly);
  EXPECT_TRUE(nominal.reach_check(nominal.middle_readings()).ok());

  Cell cell;
  FeasibilityOptions options;
  options.tolerance_sigma = Eigen::VectorXd::Zero(params.size());
  options.tolerance_sigma[rod] = 10.0;  // every draw is 0.5 m or more off (2 sigma x 10 m x |N|)
  std::optional<FeasibilityChecker> checker;
  ASSERT_NO_THROW(checker.emplace(model, params, cell, model.tool, options));
  const Candidate c = checker->evaluate(nominal.middle_readings());
  EXPECT_FALSE(c.feasible());
  EXPECT_EQ(c.rejection, Rejection::kTolerance);
}

// Every pose the planner calls reachable is on the intended assembly mode: the exact public check
// agrees, and the platform is where the Delta's closed form (tests/support/mode_sweep.hpp,
// written independently) puts it. Refusals for another or an ambiguous mode say which invariant.
TEST(Planner, ReachablePosesAreOnTheIntendedAssemblyMode) {
  const calib::Mechanism& model = delta().model;
  const Eigen::VectorXd params = model.nominal_parameters();
  const ReachChecker reach(model, params, ReachOptions{});
  Eigen::VectorXd lo, hi;
  reach.reading_limits(lo, hi);
  // Readings over the whole actuator range (beyond the reach limits), so every verdict occurs.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.6, 1.5);
  int reachable = 0;
  int mode_refusals = 0;
  for (int k = 0; k < 2000; ++k) {
    const Eigen::Vector3d x(u(rng), u(rng), u(rng));
    const ReachResult r = reach.reach_check(x);
    if (r.verdict == ReachVerdict::kModeChange ||
        (r.verdict == ReachVerdict::kSingular && r.detail.find("ambiguous") != std::string::npos)) {
      ++mode_refusals;
      EXPECT_NE(r.detail.find("assembly mode"), std::string::npos) << r.detail;
    }
    if (!r.ok()) continue;
    ++reachable;
    const calib::ModeCheck exact = calib::check_assembly_mode(model, params, r.state);
    EXPECT_EQ(exact.verdict, calib::ModeVerdict::kIntended) << exact.describe();
    const auto ref = calib::sweep::nominal_reference(model, params, x);
    ASSERT_TRUE(ref.tool.has_value()) << x.transpose();
    std::vector<Eigen::Isometry3d> P;
    calib::body_poses(model, params, r.state, P);
    EXPECT_LT((P[static_cast<std::size_t>(model.tool)].translation() - *ref.tool).norm(), 1e-9)
        << x.transpose();
  }
  EXPECT_GT(reachable, 100);
  RecordProperty("mode_refusals", mode_refusals);
}

TEST(Planner, AcceptanceTestRejectsAPlanarSet) {
  const Delta& d = delta();
  const Cell cell = load_cell_file(kCells + "delta_two_cameras.yaml");
  const FeasibilityChecker checker(d.model, d.params, cell, d.model.tool,
                                   feasibility_options_from_cell(cell));
  std::mt19937 rng(2);
  std::vector<Eigen::VectorXd> pool;
  for (const Candidate& c : checker.sample(3000, rng, nullptr))
    if (c.feasible()) pool.push_back(c.readings);
  ASSERT_GT(pool.size(), 60u);
  // 40 poses in the plane z = -0.9 by inverse kinematics.
  std::vector<std::size_t> planar;
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 5; ++j) {
      calib::TaskTarget t;
      t.pose.translation() = Eigen::Vector3d(-0.25 + 0.07 * i, -0.2 + 0.1 * j, -0.9);
      const calib::IkResult ik = calib::solve_ik(d.model, d.params, t);
      ASSERT_TRUE(ik.ok());
      planar.push_back(pool.size());
      pool.push_back(ik.actuator_readings);
    }
  const calib::MechanismPredictor pred(d.model, d.model.tool);
  const ObservabilityModel obs = build_observability_model(pred, d.params, pool);
  const IndexValues planar_values = evaluate_set(obs, planar);
  const SelectionOptions defaults;
  EXPECT_GT(planar_values.condition_number, defaults.max_condition);
  // The planner's own selection of 40 from the 3-D pool passes the same test.
  SelectionOptions so;
  so.count = 40;
  const Selection sel = select_poses(obs, so);
  EXPECT_TRUE(sel.accepted) << sel.message;
  EXPECT_LE(sel.values.condition_number, defaults.max_condition);
  EXPECT_GT(sel.values.o[0], planar_values.o[0]);
}

// ---- bad input: a clear explanation, no plan -------------------------------------------------

std::string plan_error(const std::string& cell_text) {
  const Delta& d = delta();
  const Cell cell = parse_cell_yaml(cell_text, "bad.yaml", kCells);
  PlanOptions o;
  o.pool = 300;
  o.selection.count = 10;
  const PlanResult r = plan_measurements(d.model, d.params, cell, o);
  EXPECT_EQ(r.status, PlanStatus::kBadCell) << r.message;
  EXPECT_TRUE(r.poses.empty());
  return r.message;
}

const char* kTarget =
    "target: {file: ../vision/apriltag_4x3.yaml, position: [0.054, -0.0735, -0.01], rpy: [0, 0, "
    "pi/2]}\n";

TEST(PlannerBadInput, CameraThatCannotSeeTheWorkspace) {
  const std::string msg = plan_error(
      "cameras:\n  - {name: up, file: camera_1600x1200.yaml, pose: {position: [0, 0, 1.0], "
      "look_at: [0, 0, 3.0]}}\n" +
      std::string(kTarget));
  EXPECT_NE(msg.find("bad.yaml:2:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("camera 'up' cannot see the robot's working volume at all"), std::string::npos)
      << msg;
}

TEST(PlannerBadInput, ObstacleEnclosingTheBase) {
  const std::string msg = plan_error(
      "cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: {position: [0, 0, -2.4], "
      "look_at: [0, 0, -0.9]}}\n" +
      std::string(kTarget) +
      "obstacles:\n  - {name: cabinet, box: {center: [0, 0, 0], size: [1, 1, 0.4]}}\n");
  EXPECT_NE(msg.find("bad.yaml:5:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("obstacle 'cabinet' encloses the robot's base"), std::string::npos) << msg;
}

TEST(PlannerBadInput, MillimetresInAMetreFile) {
  const std::string msg = plan_error(
      "cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: {position: [0, 0, -2400], "
      "look_at: [0, 0, -900]}}\n" +
      std::string(kTarget));
  EXPECT_NE(msg.find("bad.yaml:2:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("look like millimetres"), std::string::npos) << msg;
  const std::string ws = plan_error(
      "cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: {position: [0, 0, -2.4], "
      "look_at: [0, 0, -0.9]}}\n" +
      std::string(kTarget) + "workspace: {min: [-550, -550, -1300], max: [550, 550, -500]}\n");
  EXPECT_NE(ws.find("bad.yaml:4:"), std::string::npos) << ws;
  EXPECT_NE(ws.find("look like millimetres"), std::string::npos) << ws;
}

TEST(PlannerBadInput, UnknownTargetFrame) {
  const std::string msg = plan_error(
      "cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: {position: [0, 0, -2.4], "
      "look_at: [0, 0, -0.9]}}\n"
      "target: {file: ../vision/apriltag_4x3.yaml, frame: flange}\n");
  EXPECT_NE(msg.find("'flange' is not a body"), std::string::npos) << msg;
}

TEST(PlannerBadInput, NothingFeasibleSaysWhichConstraintRemovedHowMany) {
  const Delta& d = delta();
  // Visible only at an incidence of at most 1 degree: practically nothing passes.
  const Cell cell = parse_cell_yaml(
      "cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: {position: [0.9, 0.9, -2.4], "
      "look_at: [0, 0, -0.9]}}\n" +
          std::string(kTarget) + "visibility: {max_incidence: deg(1)}\n",
      "tight.yaml", kCells);
  PlanOptions o;
  o.pool = 400;
  o.selection.count = 10;
  const PlanResult r = plan_measurements(d.model, d.params, cell, o);
  EXPECT_EQ(r.status, PlanStatus::kInfeasible);
  EXPECT_TRUE(r.poses.empty());
  EXPECT_NE(r.message.find("of 400 candidates"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("target turned away from a required camera"), std::string::npos)
      << r.message;
  std::size_t total = r.counts.feasible;
  for (const auto& [why, n] : r.counts.removed) total += n;
  EXPECT_EQ(total, 400u);
}

}  // namespace
}  // namespace robocal::planner

namespace robocal::planner {
namespace {

// The same cell in millimetres plans the same poses; a roughly known camera narrows the set.
TEST(PlannerCells, MillimetreCellPlansTheSameAndRoughCameraIsStricter) {
  const Delta& d = delta();
  const Cell m = load_cell_file(kCells + "delta_two_cameras.yaml");
  const Cell mm = load_cell_file(kCells + "delta_mm.yaml");
  const Cell rough = load_cell_file(kCells + "delta_unknown_camera.yaml");
  const FeasibilityChecker cm(d.model, d.params, m, d.model.tool, feasibility_options_from_cell(m));
  const FeasibilityChecker cmm(d.model, d.params, mm, d.model.tool,
                               feasibility_options_from_cell(mm));
  const FeasibilityChecker crough(d.model, d.params, rough, d.model.tool,
                                  feasibility_options_from_cell(rough));
  std::mt19937 r1(9), r2(9), r3(9);
  const auto a = cm.sample(800, r1, nullptr);
  const auto b = cmm.sample(800, r2, nullptr);
  const auto c = crough.sample(800, r3, nullptr);
  int feasible = 0, rough_feasible = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].rejection, b[i].rejection) << i;
    feasible += a[i].feasible() ? 1 : 0;
    rough_feasible += c[i].feasible() ? 1 : 0;
    if (c[i].feasible()) {
      EXPECT_TRUE(a[i].feasible()) << "rough camera accepted a pose the known one rejects";
    }
  }
  EXPECT_GT(feasible, 10);
  EXPECT_LE(rough_feasible, feasible);
}

// Camera placement: the proposal sees most of the reachable working volume, checked here by
// projecting the target's outline at reachable poses into each proposed camera.
TEST(PlannerCells, ProposedCamerasSeeTheWorkingVolume) {
  const Delta& d = delta();
  const Cell cell = load_cell_file(kCells + "delta_two_cameras.yaml");
  const CameraPlacement p = propose_cameras(d.model, d.params, cell);
  ASSERT_EQ(p.world_T_camera.size(), 2u);
  EXPECT_GE(p.coverage, 0.5) << p.summary;
  EXPECT_GT(p.baseline, 0.1);
  const Cell placed = with_cameras(cell, p);
  // Independent: the outline of the board at reachable poses, projected.
  const FeasibilityChecker reach_only(d.model, d.params, placed, d.model.tool,
                                      feasibility_options_from_cell(placed));
  std::mt19937 rng(12);
  int reachable = 0, seen = 0;
  for (const Candidate& c : reach_only.sample(1500, rng, nullptr)) {
    if (c.rejection != Rejection::kNone && c.rejection < Rejection::kFacingAway) continue;
    ++reachable;
    const RobotGeometry g = geometry_at(d.model, solve_state(d.model, c.readings));
    const Eigen::Isometry3d board =
        g.poses[static_cast<std::size_t>(d.model.tool)] * placed.target.frame_T_board;
    bool all = true;
    for (const CellCamera& cam : placed.cameras)
      all = all && seen_by(placed, cam, board, g).visible;
    seen += all ? 1 : 0;
  }
  ASSERT_GT(reachable, 30);
  EXPECT_GE(static_cast<double>(seen) / reachable, 0.5);
}

}  // namespace
}  // namespace robocal::planner

namespace robocal::planner {
namespace {

// A serial arm whose board sweeps a ring around its base, larger than one view: the cameras
// must look at a part of the ring (the mean of the reachable positions is near the base, where
// the tool never is). Checked by the independent geometry above on fresh samples.
TEST(PlannerCells, ProposedCamerasSeePartOfAnArmsRing) {
  const calib::Mechanism arm = calib::load_robot_file(kData + "/robots/modular_arm.yaml");
  const Cell cell = parse_cell_yaml(
      "cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: {position: [0, 0, 3], "
      "look_at: [0, 0, 0]}}\n"
      "target: {file: ../vision/apriltag_4x3.yaml, position: [0, 0, 0.01]}\n"
      "visibility: {min_image_size: 150}\n",
      "arm.yaml", kCells);
  const CameraPlacement p = propose_cameras(arm, arm.nominal_parameters(), cell);
  ASSERT_EQ(p.world_T_camera.size(), 2u);
  // (Looking only at the mean reachable position, the simulated cell of `robocal simulate
  // --robot modular_arm` saw 0 % of the ring.)
  EXPECT_GE(p.coverage, 0.05) << p.summary;
  const Cell placed = with_cameras(cell, p);
  const FeasibilityChecker reach_only(arm, arm.nominal_parameters(), placed, arm.tool,
                                      feasibility_options_from_cell(placed));
  std::mt19937 rng(13);
  int reachable = 0, seen = 0;
  for (const Candidate& c : reach_only.sample(1500, rng, nullptr)) {
    if (c.rejection != Rejection::kNone && c.rejection < Rejection::kFacingAway) continue;
    ++reachable;
    const RobotGeometry g = geometry_at(arm, solve_state(arm, c.readings));
    const Eigen::Isometry3d board =
        g.poses[static_cast<std::size_t>(arm.tool)] * placed.target.frame_T_board;
    bool all = true;
    for (const CellCamera& cam : placed.cameras)
      all = all && seen_by(placed, cam, board, g).visible;
    seen += all ? 1 : 0;
  }
  ASSERT_GT(reachable, 100);
  // The independent count agrees with the placement's own (different samples: within 4 %).
  EXPECT_GE(static_cast<double>(seen) / reachable, 0.05) << seen << " of " << reachable;
  EXPECT_NEAR(static_cast<double>(seen) / reachable, p.coverage, 0.04)
      << seen << " of " << reachable;
}

}  // namespace
}  // namespace robocal::planner

namespace robocal::planner {
namespace {

// A Gantry-Tau cell: the board under the platform's 10 cm box, facing down; one camera below.
Cell gantry_cell(const std::string& extra) {
  return parse_cell_yaml(
      "cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: {position: [1.5, -0.5, -2], "
      "look_at: [1.5, -0.5, 0]}}\n"
      "target: {file: ../vision/apriltag_4x3.yaml, position: [0, 0, -0.06]}\n" +
          extra,
      "gantry.yaml", kCells);
}

// A Gantry-Tau's platform travels 3 m along its guideways: one camera pair sees a small part of
// the range, so the placement grows an array of pairs whose fields tile it (two cameras, any
// two, see each covered pose) and whose stations share views, through which the rig's board
// views chain. Checked with the independent geometry above on fresh samples.
TEST(PlannerCells, AnArrayOfPairsTilesARangeOnePairCannotSee) {
  const calib::Mechanism gantry = calib::load_robot_file(kData + "/robots/gantry_tau.yaml");
  const Eigen::VectorXd params = gantry.nominal_parameters();
  const Cell cell = gantry_cell("visibility: {min_image_size: 150}\n");
  PlacementOptions one;
  const CameraPlacement pair = propose_cameras(gantry, params, cell, one);
  ASSERT_EQ(pair.world_T_camera.size(), 2u);
  ASSERT_LT(pair.coverage, one.min_coverage) << pair.summary;
  PlacementOptions up_to_six = one;
  up_to_six.max_cameras = 6;
  const CameraPlacement array = propose_cameras(gantry, params, cell, up_to_six);
  ASSERT_GE(array.world_T_camera.size(), 4u) << array.summary;
  ASSERT_LE(array.world_T_camera.size(), 6u);
  EXPECT_EQ(array.cameras_per_station, 2);
  EXPECT_EQ(array.station_look_at.size() * 2, array.world_T_camera.size());
  EXPECT_EQ(array.min_cameras, 2);
  const Cell placed = with_cameras(cell, array);
  EXPECT_EQ(placed.cameras_needed(), 2);

  const FeasibilityChecker checker(gantry, params, placed, gantry.tool,
                                   feasibility_options_from_cell(placed));
  std::mt19937 rng(21);
  int reachable = 0, by_pair = 0, by_array = 0;
  const auto stations = static_cast<int>(array.station_look_at.size());
  // shared[a][b]: a pose seen by a camera of station a and one of station b.
  std::vector<std::vector<char>> shared(static_cast<std::size_t>(stations),
                                        std::vector<char>(static_cast<std::size_t>(stations), 0));
  const Cell pair_cell = with_cameras(cell, pair);
  for (const Candidate& c : checker.sample(1500, rng, nullptr)) {
    if (c.rejection != Rejection::kNone && c.rejection < Rejection::kFacingAway) continue;
    ++reachable;
    const RobotGeometry g = geometry_at(gantry, solve_state(gantry, c.readings));
    const Eigen::Isometry3d board =
        g.poses[static_cast<std::size_t>(gantry.tool)] * placed.target.frame_T_board;
    std::vector<int> seeing;
    for (std::size_t k = 0; k < placed.cameras.size(); ++k)
      if (seen_by(placed, placed.cameras[k], board, g).visible)
        seeing.push_back(static_cast<int>(k));
    // The planner never claims a pose fewer than two cameras see.
    if (c.feasible()) {
      EXPECT_GE(seeing.size(), 2u) << "readings " << c.readings.transpose();
    }
    by_array += seeing.size() >= 2 ? 1 : 0;
    for (const int a : seeing)
      for (const int b : seeing)
        shared[static_cast<std::size_t>(a / 2)][static_cast<std::size_t>(b / 2)] = 1;
    bool both = true;
    for (const CellCamera& cam : pair_cell.cameras)
      both = both && seen_by(pair_cell, cam, board, g).visible;
    by_pair += both ? 1 : 0;
  }
  ASSERT_GT(reachable, 300);
  // The array sees at least twice as much of the range as the pair.
  EXPECT_GE(by_array, 2 * std::max(by_pair, 1))
      << by_pair << " / " << by_array << " of " << reachable << "; " << array.summary;
  // Every station is chained to the first through shared views (a connected graph).
  std::vector<char> reached(static_cast<std::size_t>(stations), 0);
  reached.at(0) = 1;
  for (int round = 0; round < stations; ++round)
    for (int a = 0; a < stations; ++a)
      for (int b = 0; b < stations; ++b)
        if (reached[static_cast<std::size_t>(a)] &&
            shared[static_cast<std::size_t>(a)][static_cast<std::size_t>(b)])
          reached[static_cast<std::size_t>(b)] = 1;
  for (int s = 0; s < stations; ++s) EXPECT_TRUE(reached[static_cast<std::size_t>(s)]) << s;
}

// visibility.min_cameras: how many of the required cameras must see the target; more than the
// cell has is a load error naming the line.
TEST(PlannerBadInput, MinCamerasBeyondTheCellsCameras) {
  const std::string text =
      "cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: {position: [0, 0, -2], "
      "look_at: [0, 0, 0]}}\n"
      "target: {file: ../vision/apriltag_4x3.yaml}\n"
      "visibility:\n  min_cameras: 2\n";
  try {
    parse_cell_yaml(text, "few.yaml", kCells);
    FAIL() << "no error";
  } catch (const CellFileError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("few.yaml:5"), std::string::npos) << what;
    EXPECT_NE(what.find("min_cameras is 2 but only 1"), std::string::npos) << what;
  }
}

// A serial arm has no passive joints to carry from one step of a motion to the next: the check
// that the motion arrives on the pose's own mode has nothing to compare (it read an empty vector's
// largest entry, and the modular arm's live demo crashed in its tour). Its motions are checked for
// collision like any other: a motion from home to a pose a little away is free, and one whose end
// leaves the actuator limits is refused with the reason.
TEST(Planner, SerialArmMotionsAreCheckedWithoutPassiveJoints) {
  const calib::Mechanism m = calib::load_robot_file(kData + "/robots/modular_arm.yaml");
  ASSERT_TRUE(m.passive.empty());
  const Eigen::VectorXd p = m.nominal_parameters();
  const Cell cell = parse_cell_yaml(
      "cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: {position: [1.2, 0, 0.6], "
      "look_at: [0.4, 0, 0.2]}}\n" +
          std::string(kTarget),
      "serial.yaml", kCells);
  const FeasibilityChecker checker(m, p, cell, m.tool, feasibility_options_from_cell(cell));
  const Eigen::VectorXd home = m.home_actuated();
  Eigen::VectorXd near = home;
  near[0] += 0.3;
  std::string why;
  EXPECT_TRUE(checker.segment_free(calib::readings_from_joint_values(m, p, home),
                                   calib::readings_from_joint_values(m, p, near), 0.01, &why))
      << why;
  Eigen::VectorXd beyond = home;
  beyond[0] = m.bodies[m.actuated[0]].limits.upper + 0.2;
  EXPECT_FALSE(checker.segment_free(calib::readings_from_joint_values(m, p, home),
                                    calib::readings_from_joint_values(m, p, beyond), 0.01, &why));
  EXPECT_FALSE(why.empty());
}

// A pool too small for the poses asked is sampled again at the size its feasible rate says holds
// ten times as many: with the half-seeing camera and a 300-sample pool, the second pool's size is
// the closed form min(40000, 10 n / rate) and it holds about ten times n feasible poses.
TEST(Planner, TooSmallAPoolIsSampledAgainAtTheSizeItsRateAsks) {
  const Delta& d = delta();
  const Cell cell = parse_cell_yaml(
      "cameras:\n  - {name: low, file: camera_1600x1200.yaml, pose: {position: [-0.75, 0, -2.4], "
      "look_at: [-0.75, 0, -0.9]}}\n" +
          std::string(kTarget),
      "half.yaml", kCells);
  PlanOptions o;
  o.pool = 300;
  o.order = false;
  o.selection.count = 20;
  const PlanResult first = plan_measurements(d.model, d.params, cell, o);
  ASSERT_LT(first.pool.size(), 200u) << "the first pool already holds enough";
  ASSERT_GT(first.pool.size(), 0u);
  const double rate = static_cast<double>(first.pool.size()) / first.counts.evaluated;
  const PlanResult again = plan_with_enough_candidates(d.model, d.params, cell, o);
  EXPECT_EQ(o.pool, static_cast<std::size_t>(std::min(40000.0, 200.0 / rate)));
  EXPECT_EQ(again.counts.evaluated, o.pool);
  // Binomial: 200 expected feasible, 4 standard deviations either way.
  EXPECT_NEAR(static_cast<double>(again.pool.size()), 200.0, 4.0 * std::sqrt(200.0));
  EXPECT_EQ(again.poses.size(), 20u);
}

// A joint with more than a turn of range reaches a pose from either side: candidates are taken
// within half a turn of home (the UR5's straight motion from home to a wrist value a turn away
// swept through the wrist singularity), the pose unchanged. The Delta's arms, with less than a
// turn, are left as they are.
TEST(Planner, RevoluteActuatorsAreTakenWithinHalfATurnOfHome) {
  const calib::Mechanism ur5 = calib::load_robot_file(kData + "/robots/ur5.yaml");
  const Eigen::VectorXd p = ur5.nominal_parameters();
  const ReachChecker reach(ur5, p, ReachOptions{});
  Eigen::VectorXd lo, hi;
  reach.reading_limits(lo, hi);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int turned = 0;
  for (int t = 0; t < 200; ++t) {
    Eigen::VectorXd x(lo.size());
    for (Eigen::Index k = 0; k < lo.size(); ++k) x(k) = lo(k) + u(rng) * (hi(k) - lo(k));
    const Eigen::VectorXd y = reach.nearest_turn_to_home(x);
    for (Eigen::Index k = 0; k < x.size(); ++k) {
      const double home = ur5.bodies[static_cast<std::size_t>(ur5.actuated[k])].home;
      // Within half a turn of home, unless that value is outside the joint's limits (the
      // elbow's +-pi): then left where it was.
      const double turns = (x(k) - y(k)) / (2.0 * std::numbers::pi);
      EXPECT_NEAR(turns, std::round(turns), 1e-12) << "not whole turns";
      if (std::abs(y(k) - home) > std::numbers::pi + 1e-12) {
        EXPECT_EQ(y(k), x(k)) << "joint " << k;
        const double window = home + std::remainder(x(k) - home, 2.0 * std::numbers::pi);
        EXPECT_TRUE(window < lo(k) || window > hi(k)) << "joint " << k;
      }
    }
    turned += (x - y).norm() > 0.0 ? 1 : 0;
    const Eigen::Isometry3d a = calib::forward_kinematics(ur5, p, x, ur5.tool).pose;
    const Eigen::Isometry3d b = calib::forward_kinematics(ur5, p, y, ur5.tool).pose;
    EXPECT_LT((a.matrix() - b.matrix()).cwiseAbs().maxCoeff(), 1e-9);
  }
  EXPECT_GT(turned, 100);
  const Delta& d = delta();
  const ReachChecker delta_reach(d.model, d.params, ReachOptions{});
  delta_reach.reading_limits(lo, hi);
  for (int t = 0; t < 50; ++t) {
    Eigen::VectorXd x(lo.size());
    for (Eigen::Index k = 0; k < lo.size(); ++k) x(k) = lo(k) + u(rng) * (hi(k) - lo(k));
    EXPECT_EQ(delta_reach.nearest_turn_to_home(x), x);
  }
}

// The planner plans on the nominal robot; the real one is millimetres away. Gantry-Tau poses are
// sampled over the whole range, and robots drawn at the robot file's tolerances (1 sigma per free
// parameter, another seed than the planner's) assemble by calib's forward kinematics, or not, at
// each candidate. Next to the reach edge (the carts' plane) a nominal-only plan puts poses the
// real robot cannot reach; with feasibility's tolerance test they are gone.
TEST(Planner, PosesNearTheReachEdgeAreReachedByRobotsWithinTheirTolerances) {
  const calib::Mechanism gantry = calib::load_robot_file(kData + "/robots/gantry_tau.yaml");
  const Eigen::VectorXd params = gantry.nominal_parameters();
  const Cell cell = gantry_cell("");
  FeasibilityOptions nominal_only = feasibility_options_from_cell(cell);
  nominal_only.check_visibility = false;  // reach is the question here
  nominal_only.tolerance_draws = 0;
  FeasibilityOptions within = nominal_only;
  within.tolerance_draws = FeasibilityOptions{}.tolerance_draws;
  ASSERT_GT(within.tolerance_draws, 0);
  const FeasibilityChecker plain(gantry, params, cell, gantry.tool, nominal_only);
  const FeasibilityChecker robust(gantry, params, cell, gantry.tool, within);

  Eigen::VectorXd sigma = Eigen::VectorXd::Zero(params.size());
  for (std::size_t i = 0; i < gantry.parameters.size(); ++i)
    if (gantry.parameters[i].free && !gantry.parameters[i].exact)
      sigma(static_cast<Eigen::Index>(i)) = gantry.parameters[i].sigma;
  std::mt19937 truth_rng(4242);
  std::vector<Eigen::VectorXd> truths;
  for (int k = 0; k < 20; ++k)
    truths.push_back(calib::perturb_parameters(params, sigma, truth_rng));
  auto unreached_by = [&](const Candidate& c) {
    int n = 0;
    for (const Eigen::VectorXd& t : truths) {
      const calib::ForwardResult f =
          calib::forward_kinematics(gantry, t, c.readings, gantry.tool, c.passive);
      n += f.closure.ok() && f.closure.mode.verdict != calib::ModeVerdict::kOther ? 0 : 1;
    }
    return n;
  };

  std::mt19937 rng_a(5), rng_b(5);
  const std::vector<Candidate> a = plain.sample(3000, rng_a, nullptr);
  const std::vector<Candidate> b = robust.sample(3000, rng_b, nullptr);
  ASSERT_EQ(a.size(), b.size());
  int plain_poses = 0, plain_misses = 0, robust_poses = 0, robust_misses = 0, removed = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_TRUE(a[i].readings.isApprox(b[i].readings));
    if (!a[i].feasible()) {
      // The tolerance test only ever removes more.
      EXPECT_FALSE(b[i].feasible()) << a[i].readings.transpose();
      continue;
    }
    const int misses = unreached_by(a[i]);
    ++plain_poses;
    plain_misses += misses;
    if (b[i].feasible()) {
      ++robust_poses;
      robust_misses += misses;
    } else {
      EXPECT_EQ(b[i].rejection, Rejection::kTolerance) << b[i].detail;
      ++removed;
    }
  }
  const auto pairs = [&](int poses) { return static_cast<double>(poses * truths.size()); };
  const double plain_rate = plain_misses / pairs(plain_poses);
  const double robust_rate = robust_misses / pairs(robust_poses);
  // The closed form of feasibility.hpp: at most 4 in 1000 at the edge itself, fewer inside.
  EXPECT_LE(robust_rate, 4e-3) << robust_misses << " of " << pairs(robust_poses);
  EXPECT_GT(plain_misses, 10 * std::max(robust_misses, 1))
      << plain_misses << " of " << pairs(plain_poses);
  // It removes the edge band, not the range: most of the nominal robot's poses stay.
  EXPECT_GT(robust_poses, plain_poses * 3 / 4) << removed << " removed";
  std::cout << "Gantry-Tau, " << truths.size() << " robots at 1 sigma: nominal-only poses "
            << plain_poses << " (" << 100 * plain_rate << " % unreached), with the tolerance test "
            << robust_poses << " (" << 100 * robust_rate << " % unreached)\n";
}

}  // namespace
}  // namespace robocal::planner

namespace robocal::planner {
namespace {

// The wire robot's branch has four actuators for a pose task: it cannot put its board at an
// arbitrary pose, and joint samples leave the board at random angles, so a camera pair sees it
// at a few of them. Candidates whose face is turned towards the cameras by the robot's own
// joints (task_sampling.hpp) must be seen far more often, and each one called feasible must be
// seen by both cameras under the independent geometry above (incidence, image, size, lines of
// sight), on the intended assembly mode, within the actuator limits.
TEST(PlannerCells, AFourAxisRobotTurnsItsBoardTowardsTheCameras) {
  const calib::Mechanism wire = calib::load_robot_file(kData + "/robots/wire_robot_branch.yaml");
  const Eigen::VectorXd params = wire.nominal_parameters();
  // A pair 1.8 m from the near side of the robot's reach, 0.6 m up, looking at it. The board
  // is mounted across the platform's yaw axis (z): the platform's pitch and yaw turn it.
  const Cell cell = parse_cell_yaml(
      "cameras:\n"
      "  - {name: a, file: camera_1600x1200.yaml, pose: {position: [2.6, -0.4, 0.6], "
      "look_at: [0.9, 0, 0]}}\n"
      "  - {name: b, file: camera_1600x1200.yaml, pose: {position: [2.6, 0.4, 0.6], "
      "look_at: [0.9, 0, 0]}}\n"
      "target: {file: ../vision/apriltag_4x3.yaml, position: [0, 0, 0.02], rpy: [0, pi/2, 0]}\n"
      "visibility: {min_image_size: 60}\n",
      "wire.yaml", kCells);
  const FeasibilityChecker checker(wire, params, cell, wire.tool,
                                   feasibility_options_from_cell(cell));
  ASSERT_TRUE(task_space_sampling_applies(checker));

  // The independent verdict: both cameras see the board at these readings.
  const auto seen_by_both = [&](const Eigen::VectorXd& readings) {
    const RobotGeometry g = geometry_at(wire, solve_state(wire, readings));
    const Eigen::Isometry3d board =
        g.poses[static_cast<std::size_t>(wire.tool)] * cell.target.frame_T_board;
    for (const CellCamera& cam : cell.cameras)
      if (!seen_by(cell, cam, board, g).visible) return false;
    return true;
  };

  std::mt19937 joint_rng(5);
  int joint_seen = 0;
  const std::vector<Candidate> joint = checker.sample(600, joint_rng, nullptr);
  for (const Candidate& c : joint) joint_seen += c.feasible() && seen_by_both(c.readings) ? 1 : 0;

  std::mt19937 aim_rng(5);
  FeasibilityCounts counts;
  const std::vector<Candidate> aimed = sample_facing_cameras(checker, 600, aim_rng, &counts);
  ASSERT_EQ(aimed.size(), 600u);
  Eigen::VectorXd lo, hi;
  checker.reach().reading_limits(lo, hi);
  int aimed_feasible = 0;
  for (const Candidate& c : aimed) {
    if (!c.feasible()) continue;
    ++aimed_feasible;
    EXPECT_TRUE(seen_by_both(c.readings)) << "a candidate called visible is not";
    const ReachResult r = checker.reach().reach_check(c.readings);
    EXPECT_TRUE(r.ok()) << to_string(r.verdict);
    EXPECT_TRUE(((c.readings - lo).array() >= -1e-9).all() &&
                ((hi - c.readings).array() >= -1e-9).all());
  }
  // The same joint samples, each turned towards the cameras without random tilt (the camera
  // placement's coverage test): the positions stay, the board turns.
  ASSERT_TRUE(target_turned_by_joints(wire, wire.tool));
  int turned_seen = 0;
  for (const Candidate& j : joint) {
    const Candidate c = evaluate_turned_towards_cameras(checker, j.readings);
    if (!c.feasible()) continue;
    EXPECT_TRUE(seen_by_both(c.readings)) << "a turned sample called visible is not";
    ++turned_seen;
  }
  std::cout << "board seen by both cameras: " << joint_seen << " of 600 joint samples, "
            << turned_seen << " of them turned towards the cameras, " << aimed_feasible
            << " of 600 candidates turned towards the cameras\n"
            << counts.summary() << "\n";
  EXPECT_LE(joint_seen, 60);  // the problem: a few percent at most
  EXPECT_GE(aimed_feasible, 5 * std::max(joint_seen, 20));
  EXPECT_GE(turned_seen, 2 * std::max(joint_seen, 10));
}

}  // namespace
}  // namespace robocal::planner
