#include "robocal/robotio/robot_link.hpp"

#include "robocal/calib/mechanism.hpp"
#include "robocal/robotio/link_error.hpp"

#include <chrono>

namespace robocal::robotio {

Eigen::VectorXd nominal_encoder_scales(const SafetyGuard& guard) {
  return calib::encoder_scales(guard.model(), guard.model().nominal_parameters());
}

const char* to_string(LinkState state) {
  switch (state) {
    case LinkState::kDisconnected:
      return "disconnected";
    case LinkState::kIdle:
      return "idle";
    case LinkState::kMoving:
      return "moving";
    case LinkState::kStopped:
      return "stopped";
    case LinkState::kFault:
      return "fault";
  }
  return "?";
}

void RobotLink::home() {
  const GuardVerdict v = guard_->check_home();
  if (!v.allowed) throw MotionRefused("home refused: " + v.reason);
  if (guard_->dry_run()) return;
  do_home();
  set_last_known(do_read().values);
}

MoveResult RobotLink::move_actuators(const Eigen::VectorXd& target, const MoveSpeed& speed) {
  const auto t0 = std::chrono::steady_clock::now();
  const GuardVerdict v = guard_->check_move(last_known_, target, speed);
  if (!v.allowed) throw MotionRefused("move refused: " + v.reason);
  MoveResult r;
  if (guard_->dry_run()) {
    r.dry_run = true;
    r.confirmed = true;
    r.readings.values = target;
    last_known_ = target;
    return r;
  }
  const Eigen::VectorXd from = last_known_.size() == target.size() ? last_known_ : target;
  // Unknown start (first move after connect): at most the whole range, so the timeout is
  // generous rather than wrong.
  const double expect = expected_seconds(from, target, speed);
  const auto timeout = std::chrono::milliseconds(static_cast<long>(1000 * (2.0 * expect + 2.0)));
  try {
    do_move(target, speed);
    do_wait_settled(timeout);
  } catch (const MotionInterrupted&) {
    // Where the stop left the robot is where the next (resumed) path starts.
    try {
      last_known_ = do_read().values;
    } catch (const LinkError&) {
      last_known_.resize(0);  // unknown: the guard then checks the next target alone
    }
    throw;
  }
  r.readings = do_read();
  last_known_ = r.readings.values;
  r.confirmed = at_target(r.readings, target);
  if (!r.confirmed) r.reason = "settled away from the target (controller position differs)";
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

ActuatorReadings RobotLink::read_actuators() {
  ActuatorReadings r = do_read();
  if (r.values.size() > 0) last_known_ = r.values;
  return r;
}

void RobotLink::interrupted(const std::string& what) {
  throw MotionInterrupted(what + ": stopped on request (" + guard_->stop_reason() +
                          "); confirmed moves stand, resume to continue");
}

}  // namespace robocal::robotio
