#pragma once
// A measurement plan end to end: check the cell against the robot, sample a candidate pool in
// joint space, keep the feasible candidates (feasibility.hpp), select N by observability
// (selection.hpp), order them into a collision-free tour (tour.hpp), and report what each
// camera should see at each pose and the predicted accuracy. Plan files and SVG previews are
// written by plan_output.hpp.
#include "robocal/calib/mechanism.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/feasibility.hpp"
#include "robocal/planner/selection.hpp"
#include "robocal/planner/tour.hpp"

#include <Eigen/Core>

#include <functional>
#include <string>
#include <vector>

namespace robocal::planner {

struct PlanOptions {
  std::size_t pool = 3000;  // candidates sampled
  // Task-space candidates (task_sampling.hpp: the target turned towards the cameras, then IK on
  // the intended mode) instead of joint-space ones, where it applies (a robot whose task is the
  // measured frame's full pose: serial arms); joint space elsewhere.
  bool task_space = false;
  unsigned seed = 1;
  SelectionOptions selection;
  ObservabilityOptions observability;
  double motion_step = 0.02;  // joint units (rad / m) between collision checks along a motion
  // The tour's motions are checked again at the safety guard's path step (robotio's
  // SafetyLimits::path_step default), so that no planned motion is one the guard refuses.
  double guard_step = 1e-3;
  bool order = true;  // plan the tour
  // Sequential mode: actuator readings already measured; the plan proposes the next best poses.
  std::vector<Eigen::VectorXd> measured;
  Eigen::VectorXd start;  // current readings (tour start), optional
  // How far the real robot may be from nominal (FeasibilityOptions::tolerance_sigma): empty = the
  // robot file's sigmas.
  Eigen::VectorXd tolerance_sigma;
  std::function<void(const std::string&)> progress;  // optional, one line per stage
  // Optional: readings the controller can command. A candidate it refuses is not feasible, so the
  // selection and the tour are made of commandable poses only (a delta printer's firmware cannot
  // hold a carriage below the nozzle).
  std::function<bool(const Eigen::VectorXd&)> admissible;
};

struct PlannedPose {
  std::string id;
  Eigen::VectorXd readings;
  Candidate candidate;  // measured frame, board pose, per-camera views
};

enum class PlanStatus : std::uint8_t {
  kOk,
  kNotAccepted,  // a plan exists but fails the condition-number acceptance test
  kInfeasible,   // nothing (or too little) feasible: see `counts`
  kBadCell,      // the cell contradicts the robot (units, enclosed base, unknown frame, ...)
};

struct PlanResult {
  PlanStatus status = PlanStatus::kBadCell;
  std::string message;
  FeasibilityCounts counts;
  std::vector<Candidate> pool;        // feasible candidates only
  std::vector<PlannedPose> poses;     // in tour order
  std::vector<PlannedPose> measured;  // sequential mode: the given poses
  Selection selection;
  Tour tour;
  std::vector<std::string> identifiability;  // base-set messages
  std::vector<std::string> warnings;
  int frame = -1;
  double plan_seconds = 0.0;
};

// Checks the cell against the robot before planning; empty = consistent, else the problem:
// the target frame is not a body; a length that only makes sense in millimetres (the workspace,
// a camera or an obstacle 100x beyond the robot's reach); an obstacle enclosing the robot's base;
// a camera inside an obstacle; a required camera that cannot see any of the robot's reachable
// region.
std::string check_cell(const calib::Mechanism& model, const Eigen::VectorXd& params,
                       const Cell& cell);

// The body the target is mounted on (cell target.frame, default the tool); -1 if unknown.
int target_frame(const calib::Mechanism& model, const Cell& cell);

PlanResult plan_measurements(const calib::Mechanism& model, const Eigen::VectorXd& params,
                             const Cell& cell, const PlanOptions& options);

// plan_measurements, sampled again where the cell sees a small part of the robot's range: when
// the feasible pool holds fewer than `enough` candidates (0: ten times the poses asked), the pool
// is resampled at the size that the first pass's feasible rate says holds ten times the poses
// asked (at most `max_pool` samples). `options.pool` becomes the size used.
PlanResult plan_with_enough_candidates(const calib::Mechanism& model, const Eigen::VectorXd& params,
                                       const Cell& cell, PlanOptions& options,
                                       std::size_t enough = 0, std::size_t max_pool = 40000);

}  // namespace robocal::planner
