#pragma once
// Inverse kinematics ("implementation"): actuator readings that bring the task frame to a target
// in the robot's task coordinates (Mechanism::task): position (3-DOF translational robots), full
// pose (serial arms; least squares for robots with fewer DOF), or one joint value (four-bar
// output angle). Generic for any model, including calibrated ones: unknowns are the actuated and
// passive joints, equations are the closure residual plus the task residual, solved by damped
// Gauss-Newton with exact Jacobians. Seeds: warm start, closed form (Delta, linear delta,
// Gantry-Tau), or home. The answer carries the assembly-mode verdict (assembly_mode.hpp): the
// branch is the robot file's declared one (serial arms: shoulder/elbow/wrist configuration;
// parallel robots: elbow side, parallelograms, platform side). When the first answer lies on
// another mode, the solver restarts from the home configuration and then from `multi_start`
// deterministic seeds spread over the joint limits, keeping the first answer on an acceptable mode;
// failing that, the status is kOtherMode and `mode` names the flipped invariant.
#include "robocal/calib/closure.hpp"
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <memory>

namespace robocal::calib {

// A target in task coordinates. Which fields count depends on Mechanism::task.type:
// kPosition -> pose.translation(); kPose -> pose; kJoint -> joint_value.
struct TaskTarget {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  double joint_value = 0.0;
};

struct IkOptions {
  int max_iterations = 100;
  double tolerance = 1e-12;     // max |residual| (closure + task rows; m, rad)
  bool respect_limits = false;  // report kNoSolution when the answer violates joint limits
  bool enforce_mode = true;     // re-seed / refuse answers on another assembly mode
  int multi_start = 64;         // extra seeds tried after home when the mode is wrong
};

struct IkSeed {
  Eigen::VectorXd actuator_q;  // actuated joint values (joint units); empty -> closed form/home
  Eigen::VectorXd passive;     // passive joint values; empty -> closed form/home
};

struct IkResult {
  SolveStatus status = SolveStatus::kInvalidInput;
  Eigen::VectorXd actuator_readings;  // encoder units (inverse encoder model applied)
  Eigen::VectorXd actuator_q;         // joint units
  Eigen::VectorXd passive;
  double residual = 0.0;  // max |closure or task residual|
  int iterations = 0;
  ModeCheck mode;  // verdict of the returned state
  bool ok() const { return status == SolveStatus::kConverged; }
};

IkResult solve_ik(const Mechanism& model, const Eigen::VectorXd& params, const TaskTarget& target,
                  const IkSeed& seed = {}, const IkOptions& options = {});

// The same solver for many targets of one model (a path, a planner's candidates, compensation):
// what depends only on the model and its parameters is built once, and along a path of warm
// solves the closure's conditioning is carried from answer to answer instead of recomputed. Each
// answer is the one solve_ik gives for the same target and seed. `model` must outlive the solver.
class IkSolver {
 public:
  IkSolver(const Mechanism& model, const Eigen::VectorXd& params, IkOptions options = {});
  ~IkSolver();
  IkSolver(IkSolver&&) noexcept;
  IkSolver& operator=(IkSolver&&) noexcept;
  IkSolver(const IkSolver&) = delete;
  IkSolver& operator=(const IkSolver&) = delete;

  IkResult solve(const TaskTarget& target, const IkSeed& seed = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace robocal::calib
