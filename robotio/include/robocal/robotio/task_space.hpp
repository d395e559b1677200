#pragma once
// Task-space motion: a target pose/position becomes actuator readings through calib's inverse
// kinematics, then an ordinary (guarded) actuator move. The IK call and its verdict live in ONE
// function, `actuators_for_task_target`, so the assembly-mode check calib is gaining (the IK
// answer must keep the robot in the assembly mode it is calibrated in) is added in one place.
#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/mechanism.hpp"
#include "robocal/robotio/robot_link.hpp"

#include <Eigen/Core>

#include <string>

namespace robocal::robotio {

struct TaskTargetVerdict {
  bool ok = false;
  std::string reason;        // why no reachable answer ("" when ok)
  Eigen::VectorXd readings;  // actuator readings for the target (when ok)
  calib::IkResult ik;        // the solver's full answer
};

// IK at `params` (the model the operator trusts: nominal, or calibrated), warm-started from
// `current` readings when given. Rejects non-converged answers and answers outside the joint
// limits. Pure.
TaskTargetVerdict actuators_for_task_target(const calib::Mechanism& model,
                                            const Eigen::VectorXd& params,
                                            const calib::TaskTarget& target,
                                            const Eigen::VectorXd& current = Eigen::VectorXd());

// IK, then RobotLink::move_actuators (which passes the guard). Throws MotionRefused when IK has
// no acceptable answer (nothing is sent).
MoveResult move_to_task_target(RobotLink& link, const calib::Mechanism& model,
                               const Eigen::VectorXd& params, const calib::TaskTarget& target,
                               const MoveSpeed& speed);

}  // namespace robocal::robotio
