#pragma once
// G-code link to a printer-style controller (Marlin, RepRapFirmware) over a serial port or TCP.
//
// Actuator-space moves, in one of two modes (robotio/README.md):
// - raw-axis mode: the firmware runs one G-code axis per motor (RepRapFirmware `M669 K0`
//   Cartesian with the motors mapped to X, Y, Z, U, V, W, A, B, C; Marlin built for Cartesian
//   kinematics), so `G1 X.. Y.. Z..` positions each motor directly;
// - firmware-native delta mode: a delta printer as its owner runs it. The link reads the
//   firmware's delta geometry (Marlin `M503`, RepRapFirmware `M665`/`M666`), and sends `G1` in
//   the firmware's Cartesian frame: the firmware's forward kinematics of the requested step
//   counts, so its own inverse kinematics rounds back to exactly those counts (delta_firmware.hpp).
// Either way robocal does the robot's kinematics and confirms every move from the stepper counts
// `M114` reports.
//
// Protocol: every command carries a line number and checksum; the link waits for `ok`, accepts
// `busy:` keep-alives, resends on `Resend:`/`rs`, re-sends the same numbered line after a lost
// `ok` (the firmware's line-number check answers a duplicate with a resend request for the next
// line, so nothing executes twice), reconnects after a lost connection and checks the
// controller's position before re-issuing a move (so no motion is duplicated or lost).
#include "robocal/robotio/delta_firmware.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/native_delta.hpp"
#include "robocal/robotio/robot_link.hpp"
#include "robocal/robotio/transport.hpp"

#include <chrono>
#include <memory>
#include <string>
#include <vector>

namespace robocal::robotio {

// How actuator readings map to G-code axes: value_in_gcode_units = reading * unit_factor;
// counts = value_in_gcode_units * steps_per_unit.
struct ActuatorAxes {
  std::string letters;  // one per actuator, e.g. "XYZ"
  // reading -> G-code unit: 1000 for m -> mm, 180/pi for rad -> deg, times the encoder scale
  // for readings in counts
  std::vector<double> unit_factor;
  std::vector<double> steps_per_unit;
  int size() const { return static_cast<int>(letters.size()); }
};
// Axes for a robot: letters X Y Z U V W A B C in actuator order; prismatic actuators in mm,
// revolute in degrees. Throws std::invalid_argument for more than 9 actuators.
ActuatorAxes axes_for_robot(const calib::Mechanism& model, double steps_per_mm,
                            double steps_per_degree);
// Step counts of actuator readings (rounded to whole steps, as a firmware plans them).
std::vector<long> axis_counts(const ActuatorAxes& axes, const Eigen::VectorXd& readings);

// How the firmware is driven: one G-code axis per motor, or a delta printer in its own
// kinematics (the firmware's Cartesian G1, its geometry read from it).
// kAuto: native when the robot file says its firmware computes the robot's kinematics
// (`controller: {gcode_axes: tool}`, a linear delta) and the firmware reports delta geometry, raw
// axes otherwise (a firmware reconfigured to one axis per motor reports none).
enum class GcodeMode : std::uint8_t { kRawAxes, kNativeDelta, kAuto };
// The option words (`--gcode-mode auto|native|raw`, `--firmware-geometry
// ask|firmware|robot-file`); nullopt for any other word.
std::optional<GcodeMode> gcode_mode_from_string(const std::string& word);
std::optional<GeometryChoice> geometry_choice_from_string(const std::string& word);

struct GcodeLinkOptions {
  std::string address;  // serial device path, or tcp:HOST:PORT
  int baud = 115200;
  ActuatorAxes axes;
  std::chrono::milliseconds reply_timeout{1000};     // silence allowed before a command's ok
  std::chrono::milliseconds identify_timeout{3000};  // for the banner / M115
  int attempts = 4;            // per command: timeouts, resend requests, error replies
  int reconnect_attempts = 6;  // connection re-opened this many times, 250 ms apart
  bool accept_unknown_firmware = false;
  // Marlin's host keep-alive interval (M113 S<n>, sent on connect): `busy:` lines come this
  // often while a blocking command (M400, G28) runs.
  std::chrono::seconds keepalive{1};
  // The UR link only (make_robot_link): the operator confirmed that a protective stop may be
  // unlocked through the dashboard server.
  bool unlock_protective_stop = false;
  GcodeMode mode = GcodeMode::kRawAxes;
  GeometryChoice geometry = GeometryChoice::kAsk;
  // Native mode: a move is sent as straight Cartesian segments between points of the straight
  // actuator-space path the guard checked, at most this much joint travel apart (m), so the
  // firmware's Cartesian path stays within a few micrometres of the checked one.
  double native_segment = 5e-3;
};

class GcodeLink final : public RobotLink {
 public:
  GcodeLink(SafetyGuard& guard, const GcodeLinkOptions& options);
  // Test hook / custom transports: the link owns `transport`.
  GcodeLink(SafetyGuard& guard, GcodeLinkOptions options, std::unique_ptr<Transport> transport);
  ~GcodeLink() override;

  FirmwareInfo connect() override;
  void reconnect() override;
  void disconnect() override;
  LinkStatus status() const override { return status_; }
  int actuator_count() const override { return options_.axes.size(); }

  // Sends one command and returns the lines received before its ok (position reports, echo).
  // Public for tools (`robocal sim-controller` tests, the wizard's console).
  std::vector<std::string> command(const std::string& gcode,
                                   std::chrono::milliseconds silence_timeout,
                                   std::chrono::milliseconds total_timeout);

  // Counts a reading vector converts to (what the firmware will count at that target).
  std::vector<long> counts_for(const Eigen::VectorXd& readings) const;
  // Native mode, once connected: the firmware's delta geometry and how its carriage coordinates
  // map to readings; the differences from the robot file the operator accepted (plain words).
  // Empty in raw-axis mode (also when kAuto found no delta).
  const std::optional<CarriageFrame>& native_frame() const { return native_; }
  const std::vector<std::string>& geometry_disagreements() const { return disagreements_; }

 protected:
  void do_home() override;
  void do_move(const Eigen::VectorXd& target, const MoveSpeed& speed) override;
  void do_wait_settled(std::chrono::milliseconds timeout) override;
  std::chrono::milliseconds settle_silence() const;
  ActuatorReadings do_read() override;
  void do_stop(StopKind kind) override;
  bool at_target(const ActuatorReadings& readings, const Eigen::VectorXd& target) const override;
  double expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                          const MoveSpeed& speed) const override;

 private:
  struct Sent;
  std::vector<std::string> exchange(const std::string& gcode,
                                    std::chrono::milliseconds silence_timeout,
                                    std::chrono::milliseconds total_timeout, bool interruptible,
                                    Clock::time_point quiet_until = {});
  void handshake();
  FirmwareInfo identify();
  void send_stop_during_wait();
  std::string move_gcode(const Eigen::VectorXd& target, const MoveSpeed& speed,
                         double gcode_per_joint) const;
  // G-code path length per joint-space length of the straight move `from` -> `to`.
  double gcode_per_joint_unit(const Eigen::VectorXd& from, const Eigen::VectorXd& to) const;
  ActuatorReadings parse_readings(const std::vector<std::string>& lines) const;
  // Native mode: the firmware's delta geometry, checked against the robot file (throws
  // LinkError for a printer that is not a delta or a disagreement nobody chose on).
  void read_native_geometry();
  // nullopt when the firmware reports no delta geometry (`said`: its last words on it).
  std::optional<DeltaGeometry> query_delta_geometry(std::string& said);

  GcodeLinkOptions options_;
  std::unique_ptr<Transport> transport_;
  LinkStatus status_;
  long line_number_ = 0;
  int stale_oks_ = 0;  // oks still owed for lines the firmware rejected
  double acceleration_sent_ = -1.0;
  mutable double expected_move_seconds_ = 0.0;  // of the move being waited for
  std::string last_line_;                       // last line received (for error messages)
  std::optional<CarriageFrame> native_;         // native mode, after connect
  std::vector<std::string> disagreements_;
};

}  // namespace robocal::robotio
