#pragma once
// Reach of a candidate pose: can the robot assemble at these actuator readings on its intended
// assembly mode, inside every joint limit (with margin), ball-joint cone and away from
// singularities? ONE function, reach_check(), is the planner's only way to the closure solver,
// so the assembly-mode verdict of calib slots in here.
//
// The intended mode: the closure solver is cold-started from the robot's closed-form seed
// (rotary/linear delta, Gantry-Tau: the closed form picks the intended branch) or from the robot
// file's home values, and the answer's assembly-mode verdict (calib/assembly_mode.hpp: the robot
// file's invariants) must be `intended`: `other` is refused as a mode change naming the flipped
// invariant, `ambiguous` as singular. A robot file that declares no invariants falls back to
// continuity with the seed (no passive joint more than `max_branch_jump` away from it: a Newton
// step that lands on another branch moves some joint by ~1 rad or more). The constraint Jacobian
// must keep σ_min/σ_max >= `min_relative_sigma` (0.01, the margin sample_actuators uses to keep
// the Delta clear of its singularities).
//
// Ball-joint cones: a spherical cut body with `cone:` in the robot file limits the angle between
// the rod it holds and the rod's direction at the reference configuration (actuators at the
// middle of their limits), measured in the cut body's own frame. The robot file gives the cone
// half-angle; the reference direction is the socket's neutral axis.
#include "robocal/calib/closure.hpp"
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <string>
#include <vector>

namespace robocal::planner {

enum class ReachVerdict : std::uint8_t {
  kReachable,
  kActuatorLimit,  // an actuated joint outside its limits minus the margin
  kNoAssembly,     // closure does not converge (loop cannot close)
  kModeChange,     // closes, but on another assembly mode than the intended one
  kSingular,       // too close to a singular configuration
  kPassiveLimit,   // a passive joint outside its limits minus the margin
  kConeLimit,      // a ball joint beyond its cone
};
const char* to_string(ReachVerdict verdict);

struct ReachOptions {
  double joint_margin_angle = 0.0;   // rad kept from revolute limits and cones
  double joint_margin_length = 0.0;  // m kept from prismatic limits
  double min_relative_sigma = 0.01;  // σ_min/σ_max of the constraint Jacobian
  double max_branch_jump = 0.5;      // rad (or m) between the seed and the solution
};

// Ball-joint cone of one spherical cut: body `cut` holds the end of the link whose far end is
// `partner_base` -> `partner` (closure partner and its parent), with neutral direction `neutral`
// in the cut body's frame.
struct BallCone {
  int cut = -1;
  int partner = -1;
  int partner_base = -1;
  double half_angle = 0.0;
  Eigen::Vector3d neutral = Eigen::Vector3d::UnitZ();
};

struct ReachResult {
  ReachVerdict verdict = ReachVerdict::kNoAssembly;
  std::string detail;  // which joint / cone, by how much
  Eigen::VectorXd passive;
  calib::JointState state;
  std::vector<Eigen::Isometry3d> body_poses;  // world pose of every body (when assembled)
  bool ok() const { return verdict == ReachVerdict::kReachable; }
};

// Prepared reach test of one robot at fixed parameters (holds a closure solver; copy it per
// thread). The model must outlive it.
class ReachChecker {
 public:
  ReachChecker(const calib::Mechanism& model, const Eigen::VectorXd& params,
               const ReachOptions& options);
  // The test. `warm_seed` (optional): a nearby solved passive vector, e.g. the previous step of
  // an interpolated motion; the branch test then compares against it.
  ReachResult reach_check(const Eigen::VectorXd& readings,
                          const Eigen::VectorXd& warm_seed = Eigen::VectorXd()) const;
  // The same robot at other parameters (a robot drawn within the tolerances): its ball-joint
  // cones keep this checker's neutral directions, those of the sockets as built, instead of being
  // solved again at the middle of the actuator ranges, where a drawn robot need not assemble.
  ReachChecker with_parameters(const Eigen::VectorXd& params, const ReachOptions& options) const;
  const std::vector<BallCone>& cones() const { return cones_; }
  const calib::Mechanism& model() const { return *model_; }
  const Eigen::VectorXd& params() const { return params_; }
  // Actuator readings at the middle of every actuated joint's limits (±1 where a limit is open).
  Eigen::VectorXd middle_readings() const;
  // Actuator reading ranges with the joint margin applied (lower, upper per actuator).
  void reading_limits(Eigen::VectorXd& lower, Eigen::VectorXd& upper) const;
  // The same configuration with every revolute actuator turned by whole turns to within half a
  // turn of its home value, where its limits (with margin) allow: a joint with more than a turn
  // of range (the UR5's +-2 pi) reaches a pose from either side, and a straight motion from home
  // to the far one sweeps through singular configurations (the UR5's wrist at 0) on the way.
  Eigen::VectorXd nearest_turn_to_home(const Eigen::VectorXd& readings) const;

 private:
  struct SharedCones {};  // with_parameters' constructor: the cones are copied, not solved
  ReachChecker(const calib::Mechanism& model, const Eigen::VectorXd& params,
               const ReachOptions& options, SharedCones /*tag*/);
  const calib::Mechanism* model_;
  Eigen::VectorXd params_;
  ReachOptions options_;
  calib::ClosureSolver solver_;
  std::vector<BallCone> cones_;
};

}  // namespace robocal::planner
