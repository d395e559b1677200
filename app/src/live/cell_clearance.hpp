#pragma once
// The cell's collision check for the safety guard: the guard (robotio) takes clearance as an
// injected function because robotio may not depend on the planner; the app wires it here to the
// planner's FCL model, so every motion sample is checked against the same obstacles, clearances
// and self-collision rules the plan was made with.
#include "robocal/calib/mechanism.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/collision_scene.hpp"
#include "robocal/robotio/safety_guard.hpp"

#include <Eigen/Core>

namespace robocal::app {

// `model`, `params` (the nominal robot the guard evaluates paths on) and `scene` must outlive
// the returned check. A sample is refused with the scene's own words ("rod rod_a vs obstacle
// 'post' (4.1 mm < 10 mm clearance)").
robotio::ClearanceCheck cell_clearance_check(const calib::Mechanism& model,
                                             const Eigen::VectorXd& params,
                                             const planner::CollisionScene& scene);

// The guard every motion in a cell passes: the robot's limits, the cell's declared workspace,
// the speed and acceleration given, and the clearance to the cell's obstacles and to the robot
// itself (the cell's margins), evaluated on the robot file's nominal model. The clearance check
// reads the parameters and the scene, which live beside the guard; `model` must outlive it.
struct CellGuard {
  CellGuard(const calib::Mechanism& model, const planner::Cell& cell,
            const robotio::MoveSpeed& speed);
  CellGuard(const CellGuard&) = delete;
  CellGuard& operator=(const CellGuard&) = delete;
  CellGuard(CellGuard&&) = delete;
  CellGuard& operator=(CellGuard&&) = delete;
  ~CellGuard() = default;

  Eigen::VectorXd params;
  planner::CollisionScene scene;
  robotio::SafetyGuard guard;
};

}  // namespace robocal::app
