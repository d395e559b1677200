#pragma once
// The manual link (`--link manual`): for a robot robocal cannot command at all, the operator is
// the controller. Each planned pose is shown as actuator targets (the robot file's readings, with
// the actuators' names and units); the operator moves the robot there with its own controls,
// confirms, and types the readings its controller displays. The safety guard still checks every
// target before it is shown, and a move is confirmed only when the typed readings are at the
// target (within `tolerance` of joint travel), so a pose is never recorded where the robot is not.
#include "robocal/robotio/robot_link.hpp"

#include <cstdio>
#include <optional>
#include <string>

namespace robocal::robotio {

struct ManualLinkOptions {
  int input_fd = 0;         // where the operator's answers come from (standard input)
  std::FILE* out = stdout;  // where targets and questions go
  double tolerance = 1e-4;  // joint units (m or rad) between typed reading and target
  int attempts = 3;         // answers that are not N numbers before giving up
};

class ManualLink final : public RobotLink {
 public:
  ManualLink(SafetyGuard& guard, ManualLinkOptions options);

  FirmwareInfo connect() override;
  void reconnect() override {}
  void disconnect() override { status_.state = LinkState::kDisconnected; }
  LinkStatus status() const override { return status_; }
  int actuator_count() const override;

 protected:
  void do_home() override;
  void do_move(const Eigen::VectorXd& target, const MoveSpeed& speed) override;
  void do_wait_settled(std::chrono::milliseconds timeout) override;
  ActuatorReadings do_read() override;
  void do_stop(StopKind kind) override;
  bool at_target(const ActuatorReadings& readings, const Eigen::VectorXd& target) const override;
  double expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                          const MoveSpeed& speed) const override;

 private:
  // The operator's next line. Throws LinkError when the input closes. `interruptible`: the stop
  // flag is polled while waiting, and a stop shows the stop and throws MotionInterrupted (typing
  // readings moves nothing, so that question is answered even after a stop).
  std::string answer(const std::string& question, bool interruptible);
  // Waits for "done" (or "stop", which requests a stop).
  void wait_for_done(const std::string& what);
  std::string describe(const Eigen::VectorXd& readings) const;

  ManualLinkOptions options_;
  LinkStatus status_;
  std::string pending_;  // bytes read past the last line
};

// Numbers separated by spaces or commas; nullopt when `text` is anything else or not `count`.
std::optional<Eigen::VectorXd> parse_typed_readings(const std::string& text, int count);

}  // namespace robocal::robotio
