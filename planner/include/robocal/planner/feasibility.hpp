#pragma once
// Feasibility of a candidate measurement pose, in this order (the first failed test is the
// candidate's rejection, so a summary can say which constraint removed how many candidates):
//  1. reach (reach.hpp): actuator limits with margin, assembly on the intended mode, away from
//     singularities, passive limits, ball-joint cones;
//  2. the declared safe workspace contains the measured frame's origin and the target's outline;
//  3. collision (collision_scene.hpp, FCL): links vs obstacles with clearance, links vs links;
//  4. visibility for every required camera (or at least visibility.min_cameras of them): the
//  target's printed face turned towards the camera
//     within the maximum incidence, every required corner projecting inside the image with the
//     border margin, the target's image at least `min_image_size` px on its shortest side, and
//     the lines of sight free of obstacles and links;
//  5. reach within the robot's tolerances: a candidate that passed 1-4 on the nominal model must
//     also assemble on the intended mode for robots drawn within the robot file's parameter
//     tolerances (each free parameter's sigma; the soft keep-outs of 1, singular band and
//     margins, are the nominal model's alone). The planner plans on the nominal model, but the
//     robot that moves is the real one, millimetres away: a pose a few hundredths from where its
//     rods stop reaching (the Gantry-Tau's carts' plane is both its mode boundary and its reach
//     edge) is out of reach of the real robot as often as not, and the collection stops there.
//     Interior poses are unaffected; the band along the reach and singular boundaries grows by
//     about the tolerance.
#include "robocal/calib/mechanism.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/collision_scene.hpp"
#include "robocal/planner/reach.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <map>
#include <random>
#include <string>
#include <vector>

namespace robocal::planner {

enum class Rejection : std::uint8_t {
  kNone,
  kActuatorLimit,
  kNoAssembly,
  kModeChange,
  kSingular,
  kPassiveLimit,
  kConeLimit,
  kOutsideWorkspace,
  kObstacleCollision,
  kSelfCollision,
  kFacingAway,    // printed face turned away or beyond the maximum incidence
  kOutsideImage,  // a required corner outside the image (with border margin) or behind
  kTooSmall,      // target image smaller than min_image_size
  kOccluded,      // a line of sight blocked by an obstacle or a link
  kTolerance,     // reachable by the nominal robot only, not by one within its tolerances
};
const char* to_string(Rejection r);
Rejection rejection_of(ReachVerdict v);

// What one camera sees of the target at a candidate.
struct CameraView {
  bool visible = false;
  Rejection problem = Rejection::kNone;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  // pixel of the board's outline centre
  std::array<Eigen::Vector2d, 4> outline{};          // pixels of the outline corners
  double image_size = 0.0;                           // px, shortest outline side
  double incidence = 0.0;                            // rad
};

struct Candidate {
  Eigen::VectorXd readings;
  Eigen::VectorXd passive;
  Eigen::Isometry3d world_T_frame = Eigen::Isometry3d::Identity();  // measured frame
  Eigen::Isometry3d world_T_board = Eigen::Isometry3d::Identity();
  std::vector<CameraView> views;  // one per cell camera
  Rejection rejection = Rejection::kNone;
  std::string detail;  // why, for the first failed test
  bool feasible() const { return rejection == Rejection::kNone; }
};

// How many candidates each constraint removed.
struct FeasibilityCounts {
  std::size_t evaluated = 0;
  std::size_t feasible = 0;
  std::map<Rejection, std::size_t> removed;
  std::map<Rejection, std::string> example;  // one detail per constraint
  void add(const Candidate& c);
  // "of 5000 candidates 1210 are feasible; removed: 1800 cannot assemble, 900 collide with an
  // obstacle (e.g. ...), ..."
  // How many candidates each constraint removed; with `examples`, one case of each (an expert's
  // detail: the joint, the margin, the invariant that decided).
  std::string summary(bool examples = true) const;
};

struct FeasibilityOptions {
  ReachOptions reach;
  CollisionOptions collision;
  bool check_visibility = true;
  // Test 5: `tolerance_draws` antithetic pairs of parameter deviations (each parameter
  // N(0, (tolerance_scale * sigma)^2), fixed seed, so a plan is reproducible), 2 * draws
  // assemblies per otherwise feasible candidate. 0 = the nominal model only. Near a reach edge
  // what matters is the deviation along the one direction that moves that edge most: at scale 2
  // the largest of eight pairs' deviations along it is below 2 sigma for 5 % of such candidates
  // (P(|N| < 1)^8), and a robot drawn at the tolerances misses 4 in 1000 poses planned right at
  // the edge this leaves (E[Q(2 max|N|)]), fewer inside it. More draws or a larger scale cost
  // range: with the rotary Delta file's own sigmas (1 mm, 5 mrad) this removes 8 % of the
  // nominal robot's poses (plate tilted past its 10 deg bound on a drawn robot), at scale 3 25 %.
  int tolerance_draws = 8;
  double tolerance_scale = 2.0;
  // How far the real robot may be from nominal, per parameter (1 sigma): empty = the robot
  // file's `sigma` of every free parameter. A simulation passes the spread its truth is drawn
  // from.
  Eigen::VectorXd tolerance_sigma;
};

// Options from the cell's margins (joint margins, clearances).
FeasibilityOptions feasibility_options_from_cell(const Cell& cell);

class FeasibilityChecker {
 public:
  // `frame` = measured body (the target's frame). The model and cell must outlive the checker.
  FeasibilityChecker(const calib::Mechanism& model, const Eigen::VectorXd& params, const Cell& cell,
                     int frame, const FeasibilityOptions& options);

  Candidate evaluate(const Eigen::VectorXd& readings) const;
  // Straight-line motion in actuator space between two feasible candidates, sampled every
  // `step` joint units (rad or m) on the largest move: every intermediate configuration must
  // assemble on the same mode (warm-started from the previous step) and be collision-free.
  bool segment_free(const Eigen::VectorXd& from, const Eigen::VectorXd& to, double step,
                    std::string* why) const;
  // Uniform joint-space samples within the actuator limits (with margin), each evaluated.
  std::vector<Candidate> sample(std::size_t count, std::mt19937& rng,
                                FeasibilityCounts* counts) const;

  const ReachChecker& reach() const { return reach_; }
  const CollisionScene& scene() const { return scene_; }
  const Cell& cell() const { return *cell_; }
  int frame() const { return frame_; }

 private:
  const Cell* cell_;
  int frame_;
  FeasibilityOptions options_;
  ReachChecker reach_;
  std::vector<ReachChecker> within_tolerance_;  // test 5: robots drawn within the tolerances
  CollisionScene scene_;
  std::vector<Eigen::Vector3d> corners_;  // required corners, board frame
  std::vector<Eigen::Vector3d> outline_;  // board frame
  std::vector<int> required_;             // camera indices
  int needed_ = 0;                        // how many of them must see the target
};

}  // namespace robocal::planner
