// Feasibility and plans on the rotary Delta cell, checked against geometry written here (not the
// planner's functions, planner_test_geometry.hpp): collisions, visibility, the ball-joint cones,
// the assembly mode, the acceptance test and bad cell files.
#include "planner_test_geometry.hpp"

#include "mode_sweep.hpp"
#include "robocal/core/random_draws.hpp"

#include <gtest/gtest.h>

namespace robocal::planner {
namespace {

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
    const Eigen::Vector3d x = core::draw_vector3(u, rng);
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
