#pragma once
// Capture's robot side over a real controller link: each pose is a guarded actuator move
// (RobotLink::move_actuators, so the SafetyGuard checks every motion), settled when the
// controller confirms it; a stop (camera lost, capture failure) is the controller's controlled
// stop and a stop request on the guard, so nothing moves again until the operator confirms.
#include "robocal/robotio/capture.hpp"
#include "robocal/robotio/robot_link.hpp"

namespace robocal::robotio {

class LinkCaptureRobot final : public CaptureRobot {
 public:
  // `link` must be connected (and homed where the controller needs it); it must outlive this.
  LinkCaptureRobot(RobotLink& link, MoveSpeed speed) : link_(&link), speed_(speed) {}

  // Throws MotionRefused (guard), MotionInterrupted (Ctrl-C), LinkError, or std::runtime_error
  // when the controller did not confirm the move (its reason).
  Eigen::VectorXd move_and_settle(const Eigen::VectorXd& target) override;
  Eigen::VectorXd read_actuators() override;
  void stop(const std::string& reason) override;
  std::optional<Eigen::Isometry3d> flange_pose() const override { return flange_; }

 private:
  RobotLink* link_;
  MoveSpeed speed_;
  std::optional<Eigen::Isometry3d> flange_;
};

}  // namespace robocal::robotio
