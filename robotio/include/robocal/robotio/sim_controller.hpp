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
#include <Eigen/Geometry>

#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

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
  // Universal Robots only (--protocol ur):
  kProtectiveStop,  // the arm halts partway with a protective stop
  kMissing,         // RTDE data packages are not sent for a while (slow_seconds)
  // Klipper behind Moonraker only (--protocol moonraker):
  kShutdown,  // Klippy shuts down (an MCU error) instead of running the script
};
constexpr int kFaultKindCount = 13;
// The kinds the G-code and open protocols draw, and the UR protocol's (Moonraker draws all).
constexpr int kLineFaultKindCount = 10;
constexpr int kUrFaultKindCount = 12;
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

// What the TCP port speaks: G-code (and the pty), the open link protocol (robotio/OPEN_LINK.md,
// TCP only), or a Universal Robots controller (RTDE on the TCP port, URScript on a secondary
// client port, the dashboard server on a third; robotio/README.md).
// kMoonraker: a Klipper delta printer behind Moonraker's JSON-RPC API on a WebSocket (TCP only;
// `delta` must be set, with the Klipper firmware).
enum class SimProtocol : std::uint8_t { kGcode, kOpen, kUr, kMoonraker };

// The Universal Robots controller's own state and ports (--protocol ur).
struct SimUrOptions {
  int secondary_port = 0;        // URScript (30002 on a real UR); 0 = any free port
  int dashboard_port = 0;        // dashboard server (29999); 0 = any free port
  bool remote_control = true;    // false: "is in remote control" says false, URScript is ignored
  double speed_fraction = 1.0;   // the pendant's speed slider (RTDE target_speed_fraction)
  bool protective_stop = false;  // start in a protective stop
  double unlock_delay = 5.0;     // s after a protective stop before it may be unlocked
  double max_frequency = 500.0;  // RTDE output frequency limit (e-Series)
  // Outputs this controller's software predates: answered NOT_FOUND like any unknown name.
  std::vector<std::string> unknown_outputs;
  // The active TCP, flange -> TCP, as the pendant sets it: x y z (m), rx ry rz (rotation vector,
  // rad). RTDE's actual_TCP_pose is the true flange pose times this; tcp_offset reports it.
  std::array<double, 6> tcp_offset{};
};

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
  // Open protocol: announce the `flange_pose` capability and report the true robot's base ->
  // flange pose with every `read` (what an accurate industrial controller reports), with
  // Gaussian noise per reading (1 sigma per axis: metres, radians of a rotation vector).
  bool flange_pose = true;
  double flange_noise_m = 0.0;
  double flange_noise_rad = 0.0;
  FaultPlan faults;
  SimUrOptions ur;
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
  // --protocol ur: the link address of all three ports, "ur:127.0.0.1:RTDE:SECONDARY:DASHBOARD".
  std::string ur_address() const;

  // Serves until `stop` becomes true (or max_seconds pass).
  void run(const std::atomic<bool>& stop);
  SimCounters counters() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// The frames a controller reports its flange pose between (capability `flange_pose`): the
// flange is the body the robot file's tool frame is mounted on (the tool is a fixed auxiliary
// frame: where the board sits on the flange), or the tool frame itself when it is a moving body;
// the base is the root body when it is a fixed frame (where the robot stands in the world),
// otherwise the world (-1).
struct FlangeFrames {
  int base = -1;
  int flange = -1;
};
FlangeFrames flange_frames(const calib::Mechanism& model);

// The true robot's base -> flange pose for true actuator readings, as an accurate controller
// computes it; nullopt where the true robot cannot assemble.
std::optional<Eigen::Isometry3d> true_flange_pose(const SimRobot& robot,
                                                  const Eigen::VectorXd& true_readings);

// The true end-effector pose reply of the pose channel for true actuator readings (JSON line).
std::string pose_channel_reply(const SimRobot& robot, const Eigen::VectorXd& true_readings,
                               double t, bool moving, long motion);

}  // namespace robocal::robotio
