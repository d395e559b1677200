#pragma once
// The safety guard: one object every motion command passes before anything reaches a controller
// (RobotLink calls it; links cannot send a move without it). It checks, in this order:
//   1. a stop was requested (Ctrl-C, lost camera, operator) -> refused until resumed;
//   2. armed: the operator has confirmed (dry runs need no confirmation: they move nothing);
//   3. speed and acceleration within the declared limits;
//   4. the target and every sample of the interpolated path inside the actuator limits;
//   5. the task frame inside the declared workspace box at every sample;
//   6. the injected clearance check (the cell's collision model; the app wires the planner's
//      check here, robotio itself knows no obstacles) at every sample.
// The path is the straight line in actuator space that a G-code firmware in raw-axis mode
// executes; its samples are solved by forward kinematics on the nominal model.
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <atomic>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace robocal::robotio {

// Speed and acceleration along the actuator-space path, in joint units per second (m/s for
// prismatic, rad/s for revolute actuators, whatever the readings' units: encoder counts are
// converted by the robot file's encoder scale) and per second squared. The path's length is the
// norm of its joint-value change.
struct MoveSpeed {
  double speed = 0.0;
  double acceleration = 0.0;
};

// One point of a checked path.
struct PathSample {
  double fraction = 0.0;        // 0 = start, 1 = target
  Eigen::VectorXd readings;     // actuator readings
  calib::JointState state;      // every joint (closure solved), for a collision model
  Eigen::Isometry3d tool_pose;  // task frame in the robot's world frame
};

// Returns a reason ("effector within 3 mm of obstacle 'camera stand', needs 10 mm") when the
// sample collides or violates a margin, nullopt when clear.
using ClearanceCheck = std::function<std::optional<std::string>(const PathSample& sample)>;

struct SafetyLimits {
  Eigen::VectorXd actuator_lower, actuator_upper;  // readings; default: robot file joint limits
  Eigen::Vector3d workspace_min = Eigen::Vector3d::Constant(-1e300);  // task-frame position, m
  Eigen::Vector3d workspace_max = Eigen::Vector3d::Constant(1e300);
  double max_speed = 0.0;         // joint units/s (MoveSpeed); must be set (> 0)
  double max_acceleration = 0.0;  // joint units/s^2; must be set (> 0)
  // Largest joint change between two checked samples along a path, in joint units (rad or m),
  // not readings: a robot read in encoder counts (the wire robot's 268,000 per turn) would
  // otherwise be checked at tens of millions of samples per move.
  double path_step = 1e-3;
};

// The guard's decision for one move (also what dry runs report).
struct GuardVerdict {
  bool allowed = false;
  std::string reason;  // empty when allowed
  // The path's first and last samples (start and target). The samples between are checked and
  // dropped: a long move has thousands of them, each with the robot's full joint state.
  std::vector<PathSample> path;
  int samples = 0;  // samples checked, path_step of joint travel apart
};

class SafetyGuard {
 public:
  // `model`/`params`: the nominal robot the path is evaluated on (must outlive the guard).
  SafetyGuard(const calib::Mechanism& model, Eigen::VectorXd params, SafetyLimits limits);

  // Joint limits of the robot file converted to readings (encoder model at `params`).
  static void default_actuator_limits(const calib::Mechanism& model, const Eigen::VectorXd& params,
                                      SafetyLimits& limits);

  void set_clearance_check(ClearanceCheck check) { clearance_ = std::move(check); }
  const SafetyLimits& limits() const { return limits_; }

  // Operator confirmation: nothing moves until this is called with the operator's words (kept
  // for the session record). `disarm()` after a stop; resuming needs a new confirmation.
  void arm(const std::string& operator_confirmation);
  void disarm();
  bool armed() const { return armed_.load(); }
  std::string confirmation() const;

  // Dry run: every check runs, nothing is sent.
  void set_dry_run(bool dry) { dry_run_ = dry; }
  bool dry_run() const { return dry_run_; }

  // Stop requests. `request_stop` from any thread; `request_stop_from_signal` is
  // async-signal-safe (only sets flags). `camera_lost` is request_stop with the camera named.
  void request_stop(const std::string& reason);
  void request_stop_from_signal() noexcept;
  void camera_lost(const std::string& camera) { request_stop("camera " + camera + " lost"); }
  bool stop_requested() const { return stop_.load(); }
  std::string stop_reason() const;
  // Clears the stop request and disarms: the operator must confirm again before motion resumes.
  void resume();

  // Checks a move from `from` to `to` (readings). Pure apart from reading the flags.
  GuardVerdict check_move(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                          const MoveSpeed& speed) const;
  // Homing moves to the firmware's endstops: only the stop and arming checks apply.
  GuardVerdict check_home() const;

  const calib::Mechanism& model() const { return *model_; }
  const Eigen::VectorXd& params() const { return params_; }
  // Joint units (rad or m) per reading unit of each actuator: |encoder scale| at params().
  const Eigen::VectorXd& joint_per_reading() const { return joint_per_reading_; }

 private:
  std::optional<std::string> check_flags() const;

  const calib::Mechanism* model_;
  Eigen::VectorXd params_;
  Eigen::VectorXd joint_per_reading_;  // |encoder scale| of each actuator at params_
  SafetyLimits limits_;
  ClearanceCheck clearance_;
  bool dry_run_ = false;
  std::atomic<bool> armed_{false};
  std::atomic<bool> stop_{false};
  std::atomic<bool> stop_from_signal_{false};
  mutable std::mutex mutex_;
  std::string confirmation_;
  std::string stop_reason_;
};

}  // namespace robocal::robotio
