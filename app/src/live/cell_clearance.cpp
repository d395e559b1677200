#include "live/cell_clearance.hpp"

#include "robocal/calib/kinematics.hpp"

#include <string>
#include <vector>

namespace robocal::app {

robotio::ClearanceCheck cell_clearance_check(const calib::Mechanism& model,
                                             const Eigen::VectorXd& params,
                                             const planner::CollisionScene& scene) {
  return
      [&model, &params, &scene](const robotio::PathSample& sample) -> std::optional<std::string> {
        std::vector<Eigen::Isometry3d> poses;
        calib::body_poses(model, params, sample.state, poses);
        const planner::CollisionReport report = scene.check_robot(poses);
        if (report.free) {
          return std::nullopt;
        }
        return (report.self ? "self-collision: " : "collision: ") + report.what;
      };
}

namespace {

robotio::SafetyLimits cell_limits(const planner::Cell& cell, const robotio::MoveSpeed& speed) {
  robotio::SafetyLimits l;
  if (cell.workspace.declared) {
    l.workspace_min = cell.workspace.min;
    l.workspace_max = cell.workspace.max;
  }
  l.max_speed = speed.speed;
  l.max_acceleration = speed.acceleration;
  return l;
}

planner::CollisionOptions cell_margins(const planner::Cell& cell) {
  planner::CollisionOptions co;
  co.clearance = cell.margins.clearance;
  co.self_clearance = cell.margins.self_clearance;
  return co;
}

}  // namespace

CellGuard::CellGuard(const calib::Mechanism& model, const planner::Cell& cell,
                     const robotio::MoveSpeed& speed)
    : params(model.nominal_parameters()),
      scene(model, cell, cell_margins(cell)),
      guard(model, params, cell_limits(cell, speed)) {
  guard.set_clearance_check(cell_clearance_check(model, params, scene));
}

}  // namespace robocal::app
