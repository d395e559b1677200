#pragma once
// The cell's collision check for the safety guard: the guard (robotio) takes clearance as an
// injected function because robotio may not depend on the planner; the app wires it here to the
// planner's FCL model, so every motion sample is checked against the same obstacles, clearances
// and self-collision rules the plan was made with.
#include "robocal/calib/mechanism.hpp"
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

}  // namespace robocal::app
