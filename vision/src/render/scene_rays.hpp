#pragma once
// Camera rays meeting the targets' papers, and the occluders painted over them (internal to the
// renderer; inline: every ray of every frame goes through them).
#include "robocal/vision/renderer.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <limits>
#include <vector>

namespace robocal::vision::detail {

struct TargetGeometry {
  Eigen::Matrix3d board_R_camera;
  Eigen::Vector3d camera_in_board;
  bool faces_camera = false;  // the camera is on the printed side (z < 0 in the board frame)
};

inline TargetGeometry geometry_of(const RenderTarget& t) {
  const Eigen::Isometry3d board_T_camera = t.camera_T_board.inverse();
  TargetGeometry g;
  g.board_R_camera = board_T_camera.linear();
  g.camera_in_board = board_T_camera.translation();
  g.faces_camera = g.camera_in_board.z() < 0.0;
  return g;
}

// Intersection of a camera ray with a target's paper: distance along the ray (in units of the
// ray's length) and the board point, or false.
inline bool intersect(const TargetGeometry& g, const TargetBoard& board, const Eigen::Vector3d& ray,
                      double* t, Eigen::Vector2d* xy) {
  if (!g.faces_camera) return false;
  const Eigen::Vector3d d = g.board_R_camera * ray;
  if (!(d.z() > 0.0)) return false;
  *t = -g.camera_in_board.z() / d.z();
  const double x = g.camera_in_board.x() + *t * d.x();
  const double y = g.camera_in_board.y() + *t * d.y();
  if (!on_board(board, x, y)) return false;
  *xy = Eigen::Vector2d(x, y);
  return true;
}

// Board point where a camera ray (any length) meets a target's plane; the caller knows it does.
inline Eigen::Vector2d plane_point(const TargetGeometry& g, const Eigen::Vector3d& ray) {
  const Eigen::Vector3d d = g.board_R_camera * ray;
  const double t = -g.camera_in_board.z() / d.z();
  return {g.camera_in_board.x() + t * d.x(), g.camera_in_board.y() + t * d.y()};
}

struct CornerHit {
  int target = -1;  // -1: no target, -2: invalid ray
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();
  std::int64_t module = -1;  // PatternIndex::module_at(xy) on the target (render_scene's corners)
};

inline CornerHit nearest_hit(const std::vector<TargetGeometry>& geo,
                             const std::vector<RenderTarget>& targets, const Eigen::Vector3d& ray) {
  CornerHit hit;
  if (!ray.allFinite()) {
    hit.target = -2;
    return hit;
  }
  double best = std::numeric_limits<double>::infinity();
  for (int k = 0; k < static_cast<int>(targets.size()); ++k) {
    double t;
    Eigen::Vector2d xy;
    if (intersect(geo[static_cast<size_t>(k)], targets[static_cast<size_t>(k)].board, ray, &t,
                  &xy) &&
        t < best) {
      best = t;
      hit.target = k;
      hit.xy = xy;
    }
  }
  return hit;
}

inline bool inside_occluder(const Occluder& o, const Eigen::Vector2d& p, double grow) {
  if (o.shape == Occluder::Shape::kDisc) return (p - o.center).norm() <= o.radius + grow;
  const Eigen::Vector2d d = (p - o.center).cwiseAbs();
  return d.x() <= o.half_size.x() + grow && d.y() <= o.half_size.y() + grow;
}

}  // namespace robocal::vision::detail
