#include "robocal/robotio/task_space.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/robotio/link_error.hpp"

namespace robocal::robotio {

TaskTargetVerdict actuators_for_task_target(const calib::Mechanism& model,
                                            const Eigen::VectorXd& params,
                                            const calib::TaskTarget& target,
                                            const Eigen::VectorXd& current) {
  TaskTargetVerdict v;
  calib::IkSeed seed;
  if (current.size() == static_cast<Eigen::Index>(model.actuated.size())) {
    // Warm start in joint units (the encoder model applied to the readings).
    seed.actuator_q.resize(current.size());
    for (std::size_t i = 0; i < model.actuated.size(); ++i) {
      const calib::Body& b = model.bodies[model.actuated[i]];
      const auto k = static_cast<Eigen::Index>(i);
      seed.actuator_q[k] =
          params[b.encoder_scale_param] * current[k] + params[b.encoder_offset_param];
    }
  }
  calib::IkOptions options;
  options.respect_limits = true;
  v.ik = calib::solve_ik(model, params, target, seed, options);
  // The single verdict point: a target is driven to only on the robot file's assembly mode. IK
  // already refuses answers on another mode (kOtherMode); an answer next to a singularity where
  // modes meet (kAmbiguous) is refused too, since a small error there can flip the branch.
  if (!v.ik.ok()) {
    v.reason = std::string("inverse kinematics: ") + calib::to_string(v.ik.status);
    v.reason += v.ik.status == calib::SolveStatus::kOtherMode
                    ? " (" + v.ik.mode.describe() + ")"
                    : " (target unreachable, outside the joint limits, or singular)";
    return v;
  }
  if (v.ik.mode.verdict == calib::ModeVerdict::kAmbiguous) {
    v.reason = "inverse kinematics: the answer is at a singularity where assembly modes meet (" +
               v.ik.mode.describe() + ")";
    return v;
  }
  v.ok = true;
  v.readings = v.ik.actuator_readings;
  return v;
}

MoveResult move_to_task_target(RobotLink& link, const calib::Mechanism& model,
                               const Eigen::VectorXd& params, const calib::TaskTarget& target,
                               const MoveSpeed& speed) {
  const TaskTargetVerdict v = actuators_for_task_target(model, params, target, link.last_known());
  if (!v.ok) throw MotionRefused("move refused: " + v.reason);
  return link.move_actuators(v.readings, speed);
}

}  // namespace robocal::robotio
