// Collision model of the cell with FCL (see collision_scene.hpp).
#include "robocal/planner/collision_scene.hpp"

#include "robocal/calib/kinematics.hpp"

#include <fcl/fcl.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <queue>
#include <set>
#include <sstream>

namespace robocal::planner {

namespace {

// A passive prismatic joint: the model's coordinate of a platform (the linear Delta's effector
// translates by passive eff_x/eff_y/eff_z), not a part of the robot.
bool is_coordinate_slide(const calib::Mechanism& model, std::size_t body) {
  return model.bodies[body].joint == calib::JointType::kPrismatic &&
         std::find(model.actuated.begin(), model.actuated.end(), static_cast<int>(body)) ==
             model.actuated.end();
}

using GeometryPtr = std::shared_ptr<fcl::CollisionGeometryd>;

struct ObstacleGeometry {
  std::string name;
  GeometryPtr geometry;
  fcl::Transform3d pose = fcl::Transform3d::Identity();
  Eigen::Vector3d aabb_min, aabb_max;  // world
};

// World AABB of a geometry's local AABB under a pose (a cheap pre-filter before FCL's exact
// distance; never a verdict on its own).
void world_aabb(const fcl::CollisionGeometryd& g, const fcl::Transform3d& tf, Eigen::Vector3d& lo,
                Eigen::Vector3d& hi) {
  const Eigen::Vector3d c = 0.5 * (g.aabb_local.min_ + g.aabb_local.max_);
  const Eigen::Vector3d h = 0.5 * (g.aabb_local.max_ - g.aabb_local.min_);
  const Eigen::Vector3d wc = tf * c;
  const Eigen::Vector3d wh = tf.linear().cwiseAbs() * h;
  lo = wc - wh;
  hi = wc + wh;
}

bool aabb_apart(const Eigen::Vector3d& alo, const Eigen::Vector3d& ahi, const Eigen::Vector3d& blo,
                const Eigen::Vector3d& bhi, double gap) {
  return ((alo.array() - gap) > bhi.array()).any() || ((blo.array() - gap) > ahi.array()).any();
}

std::string mm(double m) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f mm", m * 1e3);
  return buf;
}

}  // namespace

struct CollisionScene::Impl {
  CollisionOptions options;
  std::vector<ObstacleGeometry> obstacles;
  std::vector<LinkShape> links;
  std::vector<GeometryPtr> link_geometry;  // capsule geometry per link shape (unit-posed)
  std::vector<std::pair<int, int>> self_pairs;

  // World pose of a link shape at the given body poses (capsule: axis z, centred).
  fcl::Transform3d link_pose(const LinkShape& s, const std::vector<Eigen::Isometry3d>& poses,
                             double* length) const {
    fcl::Transform3d tf = fcl::Transform3d::Identity();
    if (s.kind == LinkShape::Kind::kBox) {
      const Eigen::Isometry3d& B = poses[static_cast<std::size_t>(s.body_a)];
      tf.linear() = B.linear() * s.rotation;
      tf.translation() = B * s.point_a;
      return tf;
    }
    const Eigen::Vector3d a = poses[static_cast<std::size_t>(s.body_a)] * s.point_a;
    const Eigen::Vector3d b = poses[static_cast<std::size_t>(s.body_b)] * s.point_b;
    const Eigen::Vector3d d = b - a;
    *length = d.norm();
    tf.translation() = 0.5 * (a + b);
    if (*length > 1e-12)
      tf.linear() = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), d / *length)
                        .toRotationMatrix();
    return tf;
  }

  // Geometry for a link shape at a pose: boxes are fixed; capsules between two bodies change
  // length with the configuration (rods between ball joints do not, but derived links may).
  GeometryPtr link_geometry_at(std::size_t i, double length) const {
    const LinkShape& s = links[i];
    if (s.kind == LinkShape::Kind::kBox) return link_geometry[i];
    auto cap = std::static_pointer_cast<fcl::Capsuled>(link_geometry[i]);
    if (std::abs(cap->lz - length) < 1e-9) return link_geometry[i];
    auto g = std::make_shared<fcl::Capsuled>(s.radius, std::max(length, 1e-9));
    g->computeLocalAABB();
    return g;
  }
};

namespace {

// An obstacle of the cell as an FCL geometry at its pose, with its world bounding box.
ObstacleGeometry obstacle_geometry(const Obstacle& ob) {
  ObstacleGeometry g;
  g.name = ob.name;
  switch (ob.kind) {
    case ObstacleKind::kBox:
      g.geometry = std::make_shared<fcl::Boxd>(ob.size.x(), ob.size.y(), ob.size.z());
      break;
    case ObstacleKind::kCylinder:
      g.geometry = std::make_shared<fcl::Cylinderd>(ob.radius, ob.length);
      break;
    case ObstacleKind::kSphere:
      g.geometry = std::make_shared<fcl::Sphered>(ob.radius);
      break;
    case ObstacleKind::kMesh: {
      auto mesh = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
      std::vector<fcl::Triangle> tris;
      tris.reserve(ob.triangles.size());
      for (const Eigen::Vector3i& t : ob.triangles)
        tris.emplace_back(static_cast<std::size_t>(t.x()), static_cast<std::size_t>(t.y()),
                          static_cast<std::size_t>(t.z()));
      mesh->beginModel();
      mesh->addSubModel(ob.vertices, tris);
      mesh->endModel();
      g.geometry = mesh;
      break;
    }
  }
  g.geometry->computeLocalAABB();
  g.pose = ob.world_T_obstacle;
  world_aabb(*g.geometry, g.pose, g.aabb_min, g.aabb_max);
  return g;
}

// The pairs of link shapes checked against each other: all but those joined through bodies
// without a shape of their own.
std::vector<std::pair<int, int>> self_collision_pairs(const calib::Mechanism& model,
                                                      const std::vector<LinkShape>& links) {
  std::vector<std::pair<int, int>> pairs;
  const std::size_t nb = model.bodies.size();
  std::vector<std::vector<int>> graph(nb);
  for (std::size_t bi = 0; bi < nb; ++bi) {
    const int p = model.bodies[bi].parent;
    // A coordinate slide joins no parts: the linear Delta's effector is not held by its bed
    // through eff_x/eff_y/eff_z, and must not pass through it.
    if (p >= 0 && !is_coordinate_slide(model, bi)) {
      graph[bi].push_back(p);
      graph[static_cast<std::size_t>(p)].push_back(static_cast<int>(bi));
    }
  }
  for (const calib::Closure& c : model.closures) {
    graph[static_cast<std::size_t>(c.body_a)].push_back(c.body_b);
    graph[static_cast<std::size_t>(c.body_b)].push_back(c.body_a);
  }
  std::vector<bool> carries(nb, false);
  for (const LinkShape& s : links)
    for (const int a : s.anchors) carries[static_cast<std::size_t>(a)] = true;
  // reach[b] = bodies with geometry reachable from b through bodies without geometry.
  std::vector<std::set<int>> reach(nb);
  for (std::size_t start = 0; start < nb; ++start) {
    if (!carries[start]) continue;
    std::vector<bool> seen(nb, false);
    std::queue<int> q;
    q.push(static_cast<int>(start));
    seen[start] = true;
    while (!q.empty()) {
      const int u = q.front();
      q.pop();
      reach[start].insert(u);
      if (u != static_cast<int>(start) && carries[static_cast<std::size_t>(u)]) continue;
      for (const int v : graph[static_cast<std::size_t>(u)])
        if (!seen[static_cast<std::size_t>(v)]) {
          seen[static_cast<std::size_t>(v)] = true;
          q.push(v);
        }
    }
  }
  for (std::size_t i = 0; i < links.size(); ++i)
    for (std::size_t j = i + 1; j < links.size(); ++j) {
      bool joined = false;
      for (const int a : links[i].anchors)
        for (const int b : links[j].anchors)
          joined = joined || reach[static_cast<std::size_t>(a)].count(b) > 0;
      if (!joined) pairs.emplace_back(static_cast<int>(i), static_cast<int>(j));
    }
  return pairs;
}

}  // namespace

CollisionScene::CollisionScene(const calib::Mechanism& model, const Cell& cell,
                               const CollisionOptions& options)
    : impl_(std::make_unique<Impl>()) {
  Impl& I = *impl_;
  I.options = options;
  // Obstacles.
  for (const Obstacle& ob : cell.obstacles) I.obstacles.push_back(obstacle_geometry(ob));

  // Robot link shapes.
  std::vector<bool> has_file_shape(model.bodies.size(), false);
  for (std::size_t bi = 0; bi < model.bodies.size(); ++bi) {
    const calib::Body& b = model.bodies[bi];
    for (std::size_t k = 0; k < b.collision.size(); ++k) {
      const calib::CollisionShape& cs = b.collision[k];
      LinkShape s;
      s.body_a = s.body_b = static_cast<int>(bi);
      s.anchors = {static_cast<int>(bi)};
      if (cs.kind == calib::ShapeKind::kBox) {
        s.kind = LinkShape::Kind::kBox;
        s.point_a = cs.a;
        s.half_size = cs.half_size;
        s.rotation = cs.rotation;
        s.description = b.name + " box";
      } else {
        s.kind = LinkShape::Kind::kCapsule;
        s.point_a = cs.a;
        s.point_b = cs.b;
        s.radius = cs.radius;
        s.description = b.name + " capsule";
      }
      I.links.push_back(s);
      has_file_shape[bi] = true;
    }
  }
  for (const calib::Closure& c : model.closures) {
    if (c.type != calib::ClosureType::kDistance) continue;
    LinkShape s;
    s.body_a = c.body_a;
    s.body_b = c.body_b;
    s.radius = options.derived_radius;
    s.anchors = {c.body_a, c.body_b};
    s.description = "rod " + c.name;
    I.links.push_back(s);
  }
  // Bare links: a capsule between parent and child origins when neither has a file shape. The
  // segment's length at the home configuration decides whether it is a link at all.
  {
    calib::JointState home;
    home.q = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(model.bodies.size()));
    for (std::size_t bi = 0; bi < model.bodies.size(); ++bi)
      home.q(static_cast<Eigen::Index>(bi)) = model.bodies[bi].home;
    std::vector<Eigen::Isometry3d> poses;
    calib::body_poses(model, model.nominal_parameters(), home, poses);
    for (std::size_t bi = 0; bi < model.bodies.size(); ++bi) {
      const int p = model.bodies[bi].parent;
      if (p < 0 || has_file_shape[bi] || has_file_shape[static_cast<std::size_t>(p)]) continue;
      // A capsule along a coordinate slide would stand from the bed to the effector's centre,
      // through the lines of sight to the board under it.
      if (is_coordinate_slide(model, bi)) continue;
      if ((poses[bi].translation() - poses[static_cast<std::size_t>(p)].translation()).norm() <
          0.01)
        continue;
      LinkShape s;
      s.body_a = p;
      s.body_b = static_cast<int>(bi);
      s.radius = options.derived_radius;
      s.anchors = {p, static_cast<int>(bi)};
      s.description =
          "link " + model.bodies[static_cast<std::size_t>(p)].name + "->" + model.bodies[bi].name;
      I.links.push_back(s);
    }
  }
  for (const LinkShape& s : I.links) {
    GeometryPtr g;
    if (s.kind == LinkShape::Kind::kBox)
      g = std::make_shared<fcl::Boxd>(2 * s.half_size.x(), 2 * s.half_size.y(),
                                      2 * s.half_size.z());
    else
      g = std::make_shared<fcl::Capsuled>(s.radius, 1e-9);
    g->computeLocalAABB();
    I.link_geometry.push_back(g);
  }

  // Self-collision pairs: exempt shapes joined through shapeless bodies.
  I.self_pairs = self_collision_pairs(model, I.links);
}

CollisionScene::~CollisionScene() = default;
CollisionScene::CollisionScene(CollisionScene&&) noexcept = default;
CollisionScene& CollisionScene::operator=(CollisionScene&&) noexcept = default;

const std::vector<LinkShape>& CollisionScene::link_shapes() const {
  return impl_->links;
}
const CollisionOptions& CollisionScene::options() const {
  return impl_->options;
}

CollisionReport CollisionScene::check_robot(
    const std::vector<Eigen::Isometry3d>& body_poses) const {
  const Impl& I = *impl_;
  CollisionReport report;
  const std::size_t n = I.links.size();
  std::vector<GeometryPtr> geo(n);
  std::vector<fcl::Transform3d> tf(n);
  std::vector<Eigen::Vector3d> lo(n), hi(n);
  for (std::size_t i = 0; i < n; ++i) {
    double length = 0.0;
    tf[i] = I.link_pose(I.links[i], body_poses, &length);
    geo[i] = I.link_geometry_at(i, length);
    world_aabb(*geo[i], tf[i], lo[i], hi[i]);
  }
  fcl::DistanceRequestd request;
  for (std::size_t i = 0; i < n; ++i) {
    for (const ObstacleGeometry& ob : I.obstacles) {
      if (aabb_apart(lo[i], hi[i], ob.aabb_min, ob.aabb_max, I.options.clearance)) continue;
      fcl::DistanceResultd result;
      const double d =
          fcl::distance(geo[i].get(), tf[i], ob.geometry.get(), ob.pose, request, result);
      if (d < I.options.clearance) {
        report.free = false;
        report.what = I.links[i].description + " vs obstacle '" + ob.name + "' (" +
                      (d <= 0 ? std::string("touching") : mm(d)) + " < " + mm(I.options.clearance) +
                      " clearance)";
        return report;
      }
    }
  }
  for (const auto& [i, j] : I.self_pairs) {
    const auto a = static_cast<std::size_t>(i), b = static_cast<std::size_t>(j);
    if (aabb_apart(lo[a], hi[a], lo[b], hi[b], I.options.self_clearance)) continue;
    fcl::DistanceResultd result;
    const double d = fcl::distance(geo[a].get(), tf[a], geo[b].get(), tf[b], request, result);
    if (d < I.options.self_clearance) {
      report.free = false;
      report.self = true;
      report.what = I.links[a].description + " vs " + I.links[b].description + " (" +
                    (d <= 0 ? std::string("touching") : mm(d)) + ")";
      return report;
    }
  }
  return report;
}

bool CollisionScene::sight_clear(const Eigen::Vector3d& eye,
                                 const std::vector<Eigen::Vector3d>& outline,
                                 const std::vector<Eigen::Isometry3d>& body_poses,
                                 std::string* blocker) const {
  const Impl& I = *impl_;
  // Pyramid: apex at the eye, base = the outline pulled back towards the eye by the standoff.
  auto verts = std::make_shared<std::vector<Eigen::Vector3d>>();
  verts->push_back(eye);
  for (const Eigen::Vector3d& c : outline) {
    const Eigen::Vector3d d = c - eye;
    const double len = d.norm();
    verts->push_back(eye + d * std::max(0.0, (len - I.options.target_standoff) / len));
  }
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& v : *verts) centroid += v;
  centroid /= static_cast<double>(verts->size());
  std::vector<std::vector<int>> faces = {{1, 2, 3, 4}, {0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {0, 4, 1}};
  auto encoded = std::make_shared<std::vector<int>>();
  for (std::vector<int>& f : faces) {
    // Outward normals (counter-clockwise seen from outside), as FCL's Convex expects.
    const Eigen::Vector3d& a = (*verts)[static_cast<std::size_t>(f[0])];
    const Eigen::Vector3d& b = (*verts)[static_cast<std::size_t>(f[1])];
    const Eigen::Vector3d& c = (*verts)[static_cast<std::size_t>(f[2])];
    if ((b - a).cross(c - a).dot(a - centroid) < 0) std::reverse(f.begin(), f.end());
    encoded->push_back(static_cast<int>(f.size()));
    encoded->insert(encoded->end(), f.begin(), f.end());
  }
  fcl::Convexd pyramid(verts, 5, encoded);
  pyramid.computeLocalAABB();
  const fcl::Transform3d identity = fcl::Transform3d::Identity();
  Eigen::Vector3d plo, phi;
  world_aabb(pyramid, identity, plo, phi);
  fcl::CollisionRequestd request;
  for (const ObstacleGeometry& ob : I.obstacles) {
    if (aabb_apart(plo, phi, ob.aabb_min, ob.aabb_max, 0.0)) continue;
    fcl::CollisionResultd result;
    if (fcl::collide(&pyramid, identity, ob.geometry.get(), ob.pose, request, result) > 0) {
      if (blocker != nullptr) *blocker = "obstacle '" + ob.name + "'";
      return false;
    }
  }
  for (std::size_t i = 0; i < I.links.size(); ++i) {
    double length = 0.0;
    const fcl::Transform3d tf = I.link_pose(I.links[i], body_poses, &length);
    const GeometryPtr g = I.link_geometry_at(i, length);
    Eigen::Vector3d lo, hi;
    world_aabb(*g, tf, lo, hi);
    if (aabb_apart(plo, phi, lo, hi, 0.0)) continue;
    fcl::CollisionResultd result;
    if (fcl::collide(&pyramid, identity, g.get(), tf, request, result) > 0) {
      if (blocker != nullptr) *blocker = I.links[i].description;
      return false;
    }
  }
  return true;
}

std::vector<std::string> CollisionScene::obstacles_containing(const Eigen::Vector3d& p) const {
  std::vector<std::string> out;
  fcl::Sphered probe(1e-4);
  probe.computeLocalAABB();
  fcl::Transform3d at = fcl::Transform3d::Identity();
  at.translation() = p;
  fcl::CollisionRequestd request;
  for (const ObstacleGeometry& ob : impl_->obstacles) {
    fcl::CollisionResultd result;
    if (fcl::collide(&probe, at, ob.geometry.get(), ob.pose, request, result) > 0)
      out.push_back(ob.name);
  }
  return out;
}

}  // namespace robocal::planner
