#pragma once
// A Klipper delta printer through Moonraker (address "moonraker:HOST[:PORT]", port 7125 by
// default): the printer as its owner runs it, in Klipper's own delta kinematics.
//
// connect: `server.info` and `printer.info` (Klippy must be ready: a shutdown or a startup is
// named with Klipper's own message, nothing moves), the delta section of the configuration Klipper
// loaded (`printer.objects.query` configfile.settings; a printer that is not a delta is refused),
// checked against the robot file as the G-code link checks Marlin's and RRF's (native_delta.hpp).
// Moves: `printer.gcode.script` "G1 X.. Y.. Z.. F..\nM400" per segment of the checked path, each
// target the forward kinematics of the wanted step counts in Klipper's model, so its inverse
// kinematics lands every carriage on them; confirmed by GET_POSITION's microcontroller counts
// (relative to the count at the endstop, klipper.hpp). Stops: `printer.emergency_stop` (Klippy
// shuts down; FIRMWARE_RESTART and homing bring it back). A lost connection is re-opened and the
// position read before a move is re-issued, so none is lost or done twice; Klippy shutting down
// meanwhile is reported with its message.
#include "robocal/robotio/gcode_link.hpp"
#include "robocal/robotio/klipper.hpp"
#include "robocal/robotio/moonraker.hpp"
#include "robocal/robotio/robot_link.hpp"

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace robocal::robotio {

// Whether `address` names a Moonraker endpoint ("moonraker:HOST" or "moonraker:HOST:PORT").
bool is_moonraker_address(const std::string& address);

class KlipperLink final : public RobotLink {
 public:
  // `options.address` is "moonraker:HOST[:PORT]"; its timeouts, attempts and geometry choice
  // apply. Throws LinkError for a malformed address.
  KlipperLink(SafetyGuard& guard, const GcodeLinkOptions& options);

  FirmwareInfo connect() override;
  void reconnect() override;
  void disconnect() override;
  LinkStatus status() const override { return status_; }
  int actuator_count() const override { return 3; }

  const std::optional<CarriageFrame>& native_frame() const { return frame_; }
  const std::vector<std::string>& geometry_disagreements() const { return disagreements_; }

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
  // Runs a G-code script; returns the G-code responses it printed. Throws LinkError with
  // Klipper's message for an error; `interruptible`: stops the printer and throws
  // MotionInterrupted when a stop is requested meanwhile.
  std::vector<std::string> script(const std::string& gcode, std::chrono::milliseconds timeout,
                                  bool interruptible);
  // Klippy's state from server.info and printer.info: "" when ready, else the problem in words.
  std::string klippy_problem();
  void open_and_check();
  std::optional<KlipperPosition> get_position();
  // A notification Klippy sent about itself (shutdown, disconnect) ends the link's trust.
  void check_notifications(std::vector<std::string>* responses);

  GcodeLinkOptions options_;
  std::string host_;
  int port_ = 7125;
  std::unique_ptr<MoonrakerClient> client_;
  LinkStatus status_;
  std::optional<CarriageFrame> frame_;
  std::vector<std::string> disagreements_;
  std::optional<std::array<long, 3>> mcu_at_endstop_;  // known once homed
  std::string klippy_said_;                            // the last shutdown or disconnect notice
};

}  // namespace robocal::robotio
