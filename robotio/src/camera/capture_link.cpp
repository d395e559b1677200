#include "robocal/robotio/capture_link.hpp"

#include <stdexcept>

namespace robocal::robotio {

Eigen::VectorXd LinkCaptureRobot::move_and_settle(const Eigen::VectorXd& target) {
  const MoveResult moved = link_->move_actuators(target, speed_);
  if (!moved.confirmed && !moved.dry_run) {
    throw std::runtime_error("the controller did not confirm the move: " + moved.reason);
  }
  flange_ = moved.readings.base_T_flange;
  return moved.readings.values;
}

Eigen::VectorXd LinkCaptureRobot::read_actuators() {
  ActuatorReadings readings = link_->read_actuators();
  flange_ = readings.base_T_flange;
  return readings.values;
}

void LinkCaptureRobot::stop(const std::string& reason) {
  // The guard first: even if the controller's stop fails, no further motion passes the guard
  // until the operator resumes and confirms again.
  link_->guard().request_stop(reason);
  link_->stop(RobotLink::StopKind::kControlled);
}

}  // namespace robocal::robotio
