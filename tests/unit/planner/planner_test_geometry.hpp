#pragma once
// What the planner tests check plans against, written here rather than taken from the planner:
// link capsules and the plate box from the robot file posed by calib's forward kinematics,
// distances by convex minimisation along segments, projections by vision's camera model; the
// library rotary Delta and the target line its cells use.
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

inline const std::string kData = std::string(ROBOCAL_TESTDATA_DIR);
inline const std::string kCells = kData + "/cells/";

// ---- independent geometry -------------------------------------------------------------------

using test::Box;
using test::convex_min;
using test::point_box;

inline double segment_box(const Eigen::Vector3d& a, const Eigen::Vector3d& c, const Box& b) {
  return convex_min([&](double t) { return point_box(a + t * (c - a), b); });
}
inline double point_segment(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                            const Eigen::Vector3d& b) {
  const Eigen::Vector3d d = b - a;
  const double t = std::clamp((p - a).dot(d) / std::max(d.squaredNorm(), 1e-300), 0.0, 1.0);
  return (p - (a + t * d)).norm();
}
inline double segment_segment(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                              const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  return convex_min([&](double t) { return point_segment(a + t * (b - a), c, d); });
}
// Two boxes whose axes are parallel to the world axes (the Delta's plate stays level and the
// cell's fixture is axis-aligned): per-axis gaps.
inline double aligned_box_box(const Box& a, const Box& b) {
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
inline RobotGeometry geometry_at(const calib::Mechanism& m, const calib::JointState& state) {
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

inline Box obstacle_box(const Obstacle& o) {
  return {o.world_T_obstacle.translation(), o.world_T_obstacle.linear(), 0.5 * o.size};
}

// Smallest link-to-obstacle distance (surface to surface) over the cell's box obstacles.
inline double obstacle_distance(const RobotGeometry& g, const Cell& cell) {
  double d = 1e300;
  for (const Obstacle& o : cell.obstacles) {
    const Box ob = obstacle_box(o);
    for (const Capsule& c : g.capsules) d = std::min(d, segment_box(c.a, c.b, ob) - c.radius);
    for (const Box& b : g.boxes) d = std::min(d, aligned_box_box(b, ob));
  }
  return d;
}

// Rods of different arms (bodies 6,16 / 19,22 / 25,28): the self-collision pairs that matter.
inline double rod_rod_distance(const RobotGeometry& g) {
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
inline Seen seen_by(const Cell& cell, const CellCamera& cam, const Eigen::Isometry3d& world_T_board,
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

inline Delta& delta() {
  static Delta d;
  return d;
}

inline calib::JointState solve_state(const calib::Mechanism& m, const Eigen::VectorXd& readings,
                                     const Eigen::VectorXd& seed = Eigen::VectorXd()) {
  const calib::ForwardResult f =
      calib::forward_kinematics(m, m.nominal_parameters(), readings, m.tool, seed);
  EXPECT_TRUE(f.closure.ok()) << calib::to_string(f.closure.status);
  return f.state;
}

// The end-effector target of the Delta's cells (a cell file's line).
inline constexpr const char* kTarget =
    "target: {file: ../vision/apriltag_4x3.yaml, position: [0.054, -0.0735, -0.01], rpy: [0, 0, "
    "pi/2]}\n";

}  // namespace robocal::planner
