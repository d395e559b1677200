#pragma once
// The robot link: what robocal needs from any robot controller, whatever its protocol. A link
// moves in actuator space (readings, the robot file's encoder units) and reads actuator
// positions back; task-space moves go through calib's inverse kinematics (task_space.hpp), so a
// link never needs the robot's geometry. Every motion goes through the SafetyGuard here, in the
// base class, before the protocol-specific code runs: a link implementation cannot bypass it.
//
// Implementations: GcodeLink (Marlin / RepRapFirmware over serial or TCP), OpenLink (the open
// link protocol, robotio/OPEN_LINK.md, for controllers without a standard interface), UrLink
// (Universal Robots: RTDE, URScript on the secondary interface, the dashboard server), KlipperLink
// (a Klipper delta printer through Moonraker) and
// ManualLink (the operator); make_robot_link (link_factory.hpp) picks one from the --link
// address. robotio/README.md shows how ABB (EGM/RWS) and KUKA (RSI) links plug in.
#include "robocal/robotio/gcode_dialect.hpp"
#include "robocal/robotio/safety_guard.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <chrono>
#include <optional>
#include <string>
#include <vector>

namespace robocal::robotio {

// Actuator positions as the controller reports them.
struct ActuatorReadings {
  std::vector<long> counts;  // raw: stepper microsteps / encoder counts (empty if none)
  Eigen::VectorXd values;    // converted: robot-file reading units (m, rad)
  // The base -> flange pose the controller computes with its own kinematics (an industrial
  // controller's calibrated model), read together with the positions; empty when the controller
  // does not report one (G-code firmwares, an open link controller without `flange_pose`). A
  // hand-eye calibration uses it instead of robocal's nominal model.
  std::optional<Eigen::Isometry3d> base_T_flange;
};

enum class LinkState : std::uint8_t { kDisconnected, kIdle, kMoving, kStopped, kFault };
const char* to_string(LinkState state);

struct LinkStatus {
  LinkState state = LinkState::kDisconnected;
  FirmwareInfo firmware;
  std::string device;
  std::string last_error;  // the last controller error or link failure, "" if none
  // Counters over the link's life (reported by benches and the wizard's summary).
  long commands = 0, resends = 0, timeouts = 0, reconnects = 0, busy_lines = 0, errors = 0,
       unsolicited = 0, garbage = 0;
};

// Outcome of one motion: confirmed at its target, or not (with the reason). Failures that leave
// the link unusable throw LinkError instead; refusals throw MotionRefused; stops throw
// MotionInterrupted.
struct MoveResult {
  bool confirmed = false;
  bool dry_run = false;
  std::string reason;         // why not confirmed
  ActuatorReadings readings;  // read back after settling (the target in a dry run)
  double seconds = 0.0;       // wall time from issue to readings parsed
};

// The robot file's nominal scale from each actuator's reading to its joint
// (calib::encoder_scales of the guard's model): what a link converts the controller's values with.
Eigen::VectorXd nominal_encoder_scales(const SafetyGuard& guard);

class RobotLink {
 public:
  explicit RobotLink(SafetyGuard& guard) : guard_(&guard) {}
  virtual ~RobotLink() = default;
  RobotLink(const RobotLink&) = delete;
  RobotLink& operator=(const RobotLink&) = delete;

  // Connects and identifies the controller. Throws LinkError (device, what it said).
  virtual FirmwareInfo connect() = 0;
  // Re-establishes a lost connection (retries); the controller's state is re-read.
  virtual void reconnect() = 0;
  virtual void disconnect() = 0;
  virtual LinkStatus status() const = 0;
  virtual int actuator_count() const = 0;
  // Whether the readings carry the controller's base -> flange pose
  // (ActuatorReadings::base_T_flange); known once connected.
  virtual bool reports_flange_pose() const { return false; }

  // Motion: guard first, then the protocol. Throws MotionRefused before anything is sent.
  void home();
  MoveResult move_actuators(const Eigen::VectorXd& target, const MoveSpeed& speed);
  // Actuator positions now (raw counts and converted values).
  // Also becomes the start of the next path the guard checks.
  ActuatorReadings read_actuators();
  // Controlled stop (motion halts, controller stays up) or emergency stop (controller halts and
  // needs a reset). Never refused by the guard.
  enum class StopKind : std::uint8_t { kControlled, kEmergency };
  void stop(StopKind kind) { do_stop(kind); }

  SafetyGuard& guard() { return *guard_; }
  const SafetyGuard& guard() const { return *guard_; }
  // Where the guard takes a path's start from: the last readings confirmed by the controller.
  const Eigen::VectorXd& last_known() const { return last_known_; }

 protected:
  // Protocol hooks. do_move issues the motion and returns once the controller accepted it;
  // do_wait_settled returns when it finished (or throws); both must poll guard().stop_requested()
  // at least every 50 ms and stop the robot and throw MotionInterrupted when it is set.
  virtual void do_home() = 0;
  virtual void do_move(const Eigen::VectorXd& target, const MoveSpeed& speed) = 0;
  virtual void do_wait_settled(std::chrono::milliseconds timeout) = 0;
  virtual ActuatorReadings do_read() = 0;
  virtual void do_stop(StopKind kind) = 0;
  // Whether `readings` are at `target` to the controller's resolution.
  virtual bool at_target(const ActuatorReadings& readings, const Eigen::VectorXd& target) const = 0;
  // Expected duration of a move (for the settle timeout); the link knows its controller's
  // motion profile.
  virtual double expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                                  const MoveSpeed& speed) const = 0;

  void set_last_known(const Eigen::VectorXd& readings) { last_known_ = readings; }
  // Throws MotionInterrupted after the stop was sent.
  [[noreturn]] void interrupted(const std::string& what);

 private:
  SafetyGuard* guard_;
  Eigen::VectorXd last_known_;
};

}  // namespace robocal::robotio
