// Self-collision model of the planner (collision_scene.hpp) on the linear Delta, checked with
// geometry written here: the robot file's boxes and the rods/rails as segments posed by calib's
// forward kinematics, distances by convex minimisation along the segments.
#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/collision_scene.hpp"
#include "robocal/planner/reach.hpp"

#include "independent_geometry.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace robocal::planner {
namespace {

using test::Box;
using test::convex_min;
using test::point_box;
struct Segment {
  Eigen::Vector3d a, b;
  double radius;
};

double segment_box(const Segment& s, const Box& box) {
  return convex_min([&](double t) { return point_box(s.a + t * (s.b - s.a), box); }) - s.radius;
}
double segment_segment(const Segment& s, const Segment& r) {
  return convex_min([&](double u) {
           const Eigen::Vector3d p = s.a + u * (s.b - s.a);
           return convex_min([&](double t) { return (p - (r.a + t * (r.b - r.a))).norm(); });
         }) -
         s.radius - r.radius;
}

class LinearDelta : public ::testing::Test {
 protected:
  LinearDelta()
      : model(calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) +
                                     "/robots/linear_delta.yaml")),
        params(model.nominal_parameters()) {}
  int body(const std::string& name) const {
    for (std::size_t b = 0; b < model.bodies.size(); ++b)
      if (model.bodies[b].name == name) return static_cast<int>(b);
    ADD_FAILURE() << name;
    return 0;
  }
  Box box_of(const std::string& name, const std::vector<Eigen::Isometry3d>& poses) const {
    const int b = body(name);
    const calib::CollisionShape& cs = model.bodies[static_cast<std::size_t>(b)].collision.at(0);
    const Eigen::Isometry3d& P = poses[static_cast<std::size_t>(b)];
    return {P * cs.a, P.linear() * cs.rotation, cs.half_size};
  }
  Eigen::Vector3d at(const std::string& name, const std::vector<Eigen::Isometry3d>& poses) const {
    return poses[static_cast<std::size_t>(body(name))].translation();
  }
  calib::Mechanism model;
  Eigen::VectorXd params;
};

// Home (carriages at 0.3 m, effector centred 0.0665 m above the bed): by the geometry here the
// robot is clear of itself by centimetres, and the space under the effector's centre, between
// the bed and the effector, holds no part: a line of sight from just above the bed to a small
// square under the effector is clear. The old model stood a capsule along the effector's passive
// slides (eff_y -> eff_z: from the bed to the effector's centre), which blocked it.
TEST_F(LinearDelta, HomeIsFreeAndTheSpaceUnderTheEffectorIsEmpty) {
  ReachChecker reach(model, params, ReachOptions{});
  const ReachResult r = reach.reach_check(Eigen::Vector3d(0.3, 0.3, 0.3));
  ASSERT_TRUE(r.ok()) << r.detail;
  const auto& P = r.body_poses;
  const Box bed = box_of("base", P), effector = box_of("effector", P);
  const double clearance = CollisionOptions{}.self_clearance;
  const double rod_r = CollisionOptions{}.derived_radius;
  // Independent clearances of the pairs that share no joint.
  EXPECT_GT(effector.centre.z() - effector.half.z() - (bed.centre.z() + bed.half.z()), 0.05);
  std::vector<Segment> rods, rails;
  for (const char* t : {"a", "b", "c"}) {
    rods.push_back(
        {at(std::string("carriage_") + t, P), at(std::string("eff_joint_") + t, P), rod_r});
    rails.push_back({at(std::string("tower_") + t, P), at(std::string("carriage_") + t, P), rod_r});
  }
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_GT(segment_box(rods[i], bed), clearance);
    EXPECT_GT(segment_box(rails[i], effector), clearance);
    for (std::size_t j = 0; j < 3; ++j) {
      if (i == j) continue;
      EXPECT_GT(segment_segment(rods[i], rods[j]), clearance);
      EXPECT_GT(segment_segment(rods[i], rails[j]), clearance);
    }
  }
  const CollisionScene scene(model, Cell{}, CollisionOptions{});
  const CollisionReport report = scene.check_robot(P);
  EXPECT_TRUE(report.free) << report.what;
  // Nothing between the bed and the effector's underside near its centre (rods leave the
  // effector 34 mm out and rise outwards; rails stand 174 mm out).
  const Eigen::Vector3d c = effector.centre;
  const double z_top = c.z() - effector.half.z() - 0.01;
  const std::vector<Eigen::Vector3d> square = {{c.x() - 0.01, c.y() - 0.01, z_top},
                                               {c.x() + 0.01, c.y() - 0.01, z_top},
                                               {c.x() + 0.01, c.y() + 0.01, z_top},
                                               {c.x() - 0.01, c.y() + 0.01, z_top}};
  std::string blocker;
  EXPECT_TRUE(scene.sight_clear(Eigen::Vector3d(c.x(), c.y(), 0.01), square, P, &blocker))
      << "blocked by " << blocker;
  for (const LinkShape& s : scene.link_shapes())
    EXPECT_EQ(s.description.find("eff_"), std::string::npos) << s.description;
}

// Every self-collision the scene reports over the actuator range is one the geometry here
// confirms (a pair closer than the self clearance), and every configuration it calls free is
// clear by that geometry for the pairs that share no joint.
TEST_F(LinearDelta, EverySelfCollisionIsReal) {
  ReachChecker reach(model, params, ReachOptions{});
  const CollisionOptions options;
  const CollisionScene scene(model, Cell{}, options);
  Eigen::VectorXd lo, hi;
  reach.reading_limits(lo, hi);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int reached = 0, colliding = 0;
  for (int i = 0; i < 400; ++i) {
    Eigen::VectorXd x(lo.size());
    for (Eigen::Index k = 0; k < x.size(); ++k) x(k) = lo(k) + u(rng) * (hi(k) - lo(k));
    const ReachResult r = reach.reach_check(x);
    if (!r.ok()) continue;
    ++reached;
    const auto& P = r.body_poses;
    const Box bed = box_of("base", P), effector = box_of("effector", P);
    double nearest = 1e300;
    // Level boxes (the effector keeps its orientation): the gap along z decides bed vs effector
    // when their footprints overlap (the bed's 0.45 m square holds the effector's whole range).
    nearest = std::min(nearest,
                       effector.centre.z() - effector.half.z() - (bed.centre.z() + bed.half.z()));
    for (const char* t : {"a", "b", "c"}) {
      const Segment rod{at(std::string("carriage_") + t, P), at(std::string("eff_joint_") + t, P),
                        options.derived_radius};
      const Segment rail{at(std::string("tower_") + t, P), at(std::string("carriage_") + t, P),
                         options.derived_radius};
      nearest = std::min({nearest, segment_box(rod, bed), segment_box(rail, effector)});
      for (const char* o : {"a", "b", "c"}) {
        if (std::string(o) == t) continue;
        const Segment other_rod{at(std::string("carriage_") + o, P),
                                at(std::string("eff_joint_") + o, P), options.derived_radius};
        const Segment other_rail{at(std::string("tower_") + o, P),
                                 at(std::string("carriage_") + o, P), options.derived_radius};
        nearest =
            std::min({nearest, segment_segment(rod, other_rod), segment_segment(rod, other_rail)});
      }
    }
    const CollisionReport report = scene.check_robot(P);
    if (!report.free) {
      ++colliding;
      EXPECT_LT(nearest, options.self_clearance + 1e-6) << report.what;
    } else {
      EXPECT_GE(nearest, options.self_clearance - 1e-6);
    }
  }
  EXPECT_GT(reached, 300);
  EXPECT_GT(colliding, 0);  // the range does reach the bed and the rails
}

}  // namespace
}  // namespace robocal::planner
