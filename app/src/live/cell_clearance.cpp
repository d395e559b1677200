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

}  // namespace robocal::app
