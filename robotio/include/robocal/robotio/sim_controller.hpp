#pragma once
// The simulated controller behind `robocal sim-controller`: a G-code firmware (Marlin or
// RepRapFirmware dialect) or an open-link controller (robotio/OPEN_LINK.md) driving a "true" robot
// — the robot file with perturbed geometry, stepper quantisation, backlash, actuator noise and
// trapezoidal move times — served on a loopback TCP port and on a pseudo-terminal, with a JSONL log
// of every line received and every motion executed (the independent record the safety tests read),
// fault injection, and the true end-effector pose on a separate TCP channel that only simulated
// cameras read (protocol in robotio/README.md).
#include "robocal/calib/mechanism.hpp"
#include "robocal/robotio/delta_firmware.hpp"
#include "robocal/robotio/gcode_dialect.hpp"
#include "robocal/robotio/gcode_link.hpp"

#include <Eigen/Core>

#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>

namespace robocal::robotio {

enum class FaultKind : std::uint8_t {
  kDrop,     // the connection drops (after executing the line, or before, at random)
  kBusy,     // extra "busy:" keep-alives before the reply
  kError,    // "Error:" reply; the line is not executed
  kStall,    // a move stops halfway and never finishes (until a stop command)
  kCorrupt,  // the line arrives corrupted on the wire (checksum mismatch -> resend request)
  kLostOk,   // the line executes, its "ok" is lost
  kResend,   // a resend request although the line arrived intact
  kSlow,     // the reply comes late (slow_seconds)
  kGarbage,  // noise bytes (control characters) precede the reply
  kPartial,  // an M114 report is cut short (no stepper counts)
};
constexpr int kFaultKindCount = 10;
const char* to_string(FaultKind kind);
std::optional<FaultKind> fault_kind_from_string(const std::string& name);

struct FaultPlan {
  std::array<double, kFaultKindCount> rate{};  // probability per numbered command, per kind
  std::map<long, FaultKind> script;            // numbered command index received (1-based) -> fault
  std::uint32_t seed = 1;
  double slow_seconds = 0.25;
  int busy_lines = 2;
};
// "drop=0.05,busy=0.02" or "all=0.05". Throws std::invalid_argument naming the bad item.
FaultPlan parse_fault_spec(const std::string& spec);
// Script file: one "<command index> <kind>" per line, '#' comments. Throws std::invalid_argument
// with "file:line: problem".
void load_fault_script(const std::string& path, FaultPlan& plan);

struct SimRobot {
  calib::Mechanism model;
  Eigen::VectorXd truth;  // the true parameters (never sent to the link)
  ActuatorAxes axes;
  Eigen::VectorXd home_readings;  // where G28 puts the actuators (endstops), readings
  double noise_sigma = 0.0;       // actuator repeatability per move, readings
  double backlash = 0.0;          // lost motion on a reversal, readings
};

// What the TCP port speaks: G-code (and the pty), or the open link protocol (robotio/OPEN_LINK.md,
// TCP only).
enum class SimProtocol : std::uint8_t { kGcode, kOpen };

struct SimOptions {
  SimProtocol protocol = SimProtocol::kGcode;
  Firmware dialect = Firmware::kMarlin;
  // Open protocol: the version the controller speaks and announces in `hello` (tests of version
  // negotiation set an older one).
  int open_major = 1, open_minor = 0;
  std::string firmware_name;  // overrides the M115 name (unknown-firmware tests)
  bool mute = false;          // accept connections, never answer (a dead controller)
  int tcp_port = 0;           // 0 = any free port, -1 = no TCP
  bool pty = true;
  std::string pty_link;               // stable symlink to the current pty (like /dev/serial/by-id)
  int pose_port = 0;                  // 0 = any free port, -1 = none
  std::string log_path;               // JSONL; "" = no log
  double busy_interval = 2.0;         // Marlin's default host keep-alive (M113 changes it)
  double temperature_interval = 0.0;  // auto-report temperatures every N s (0 = off)
  double feed = 3000.0;               // default feed, G-code units/min
  double acceleration = 1000.0;       // default, G-code units/s^2
  double max_seconds = 0.0;           // exit after this long (0 = until stopped)
  // Exit when standard input closes: the process that started it (holding the pipe's other end)
  // ended, even by a crash or SIGKILL, so no simulator is left serving.
  bool exit_with_parent = false;
  std::uint32_t seed = 1;  // actuator noise
  FaultPlan faults;
  // G-code only: the firmware runs delta kinematics with this geometry (its own M665/M666, which
  // may differ from the true robot's) and maps its carriage coordinates to the true robot's
  // readings as the frame says; unset = raw-axis mode (one axis per motor).
  std::optional<CarriageFrame> delta;
};

// Counts of what happened (also in the log).
struct SimCounters {
  std::array<long, kFaultKindCount> faults{};
  long lines = 0, motions = 0, stops = 0, connections = 0;
};

class SimController {
 public:
  SimController(SimRobot robot, SimOptions options);
  ~SimController();
  SimController(const SimController&) = delete;
  SimController& operator=(const SimController&) = delete;

  // Binds the ports and opens the pty. Throws std::runtime_error.
  void start();
  std::string tcp_address() const;   // "127.0.0.1:PORT" ("" if off)
  std::string pty_path() const;      // current pty slave ("" if off)
  std::string pose_address() const;  // "127.0.0.1:PORT" ("" if off)

  // Serves until `stop` becomes true (or max_seconds pass).
  void run(const std::atomic<bool>& stop);
  SimCounters counters() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// The true end-effector pose reply of the pose channel for true actuator readings (JSON line).
std::string pose_channel_reply(const SimRobot& robot, const Eigen::VectorXd& true_readings,
                               double t, bool moving, long motion);

}  // namespace robocal::robotio
