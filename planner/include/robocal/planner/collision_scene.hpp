#pragma once
// Collision model of the cell (FCL): the robot's links, posed per configuration, against the
// cell's obstacles and against each other, with clearance; and the lines of sight from a camera
// to the target.
//
// Robot link geometry:
//  - every `collision:` shape of the robot file (capsules, boxes in the body's frame);
//  - for every rod or cable (distance closure) a capsule along it of radius `derived_radius`;
//  - for every parent -> child link where neither body has a file shape, a capsule along the
//    segment between their origins (when longer than 1 cm, and not when the child is a passive
//    prismatic joint: a platform's coordinate slide is no part), so a robot file without
//    collision geometry still gets a link model derived from its mechanism.
// Self-collision is tested between shapes that are not joined directly: two shapes are exempt when
// a path of joints (tree edges and closures) connects their bodies through bodies that carry no
// shape (a joint's parts touch by design). A coordinate slide (passive prismatic joint) is no
// such path: the linear Delta's effector is checked against its bed.
//
// Lines of sight: the rays from a camera's centre to every corner of the target lie inside the
// pyramid spanned by the centre and the four extreme corners; that pyramid, stopped
// `target_standoff` short of the board (the board's own mount must not count), is tested against
// obstacles and links with FCL. Free pyramid => every corner ray is free.
#include "robocal/calib/mechanism.hpp"
#include "robocal/planner/cell.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <memory>
#include <string>
#include <vector>

namespace robocal::planner {

struct CollisionOptions {
  double clearance = 0.01;         // m, links vs obstacles
  double self_clearance = 0.002;   // m, link vs link
  double derived_radius = 0.01;    // m, capsules derived along rods and bare links
  double target_standoff = 0.005;  // m, sight pyramids stop this far before the board
};

// One link shape, for previews and independent checks.
struct LinkShape {
  enum class Kind : std::uint8_t { kCapsule, kBox } kind = Kind::kCapsule;
  std::string description;  // "body6 capsule", "rod rod_a", "link j2->j3"
  // kCapsule: segment between two points, each a point `local` in body `body` (world pose of the
  // body at the configuration). kBox: centre and rotation in body `body_a`'s frame.
  int body_a = -1, body_b = -1;
  Eigen::Vector3d point_a = Eigen::Vector3d::Zero();  // in body_a's frame
  Eigen::Vector3d point_b = Eigen::Vector3d::Zero();  // in body_b's frame
  double radius = 0.0;
  Eigen::Vector3d half_size = Eigen::Vector3d::Zero();
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  std::vector<int> anchors;  // bodies the shape is attached to
};

struct CollisionReport {
  bool free = true;
  std::string what;   // "body6 capsule vs obstacle 'fixture' (3.2 mm < 10 mm clearance)"
  bool self = false;  // the first problem is self-collision
};

class CollisionScene {
 public:
  CollisionScene(const calib::Mechanism& model, const Cell& cell, const CollisionOptions& options);
  ~CollisionScene();
  CollisionScene(CollisionScene&&) noexcept;
  CollisionScene& operator=(CollisionScene&&) noexcept;
  CollisionScene(const CollisionScene&) = delete;
  CollisionScene& operator=(const CollisionScene&) = delete;

  // Robot at the given body poses (world) vs obstacles (clearance) and itself (self clearance).
  CollisionReport check_robot(const std::vector<Eigen::Isometry3d>& body_poses) const;
  // Is the sight pyramid from `eye` to the board quad `outline` (world, 4 points) free of
  // obstacles and robot links at `body_poses`? `blocker` names the first blocker.
  bool sight_clear(const Eigen::Vector3d& eye, const std::vector<Eigen::Vector3d>& outline,
                   const std::vector<Eigen::Isometry3d>& body_poses, std::string* blocker) const;
  // Obstacles that contain a point (e.g. the robot's base, a camera centre); names, empty = none.
  std::vector<std::string> obstacles_containing(const Eigen::Vector3d& p) const;

  const std::vector<LinkShape>& link_shapes() const;
  const CollisionOptions& options() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace robocal::planner
