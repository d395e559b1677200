#pragma once
// The simulated controller's inside, shared by its parts (not installed, not used outside
// robotio/src/sim):
//   sim_server.cpp  the sockets and the pty, the poll loop, the true-pose channel;
//   sim_motion.cpp  the true robot: motion queue, trapezoid timing, backlash, noise, the log;
//   sim_faults.cpp  fault plans and the per-command draw;
//   sim_gcode.cpp   the G-code firmware (Marlin / RepRapFirmware dialects);
//   sim_open.cpp    the open link protocol (robotio/OPEN_LINK.md);
//   sim_ur.cpp      a Universal Robots controller: RTDE, URScript on the secondary interface,
//                   the dashboard server;
//   sim_moonraker.cpp  a Klipper delta printer behind Moonraker's WebSocket JSON-RPC API.
// A further protocol is one more file with its receive/process pair, dispatched in run().
#include "robocal/robotio/sim_controller.hpp"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <deque>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace robocal::robotio {

// Steady-clock seconds (the simulator's time base).
double now_seconds();
// A listening TCP socket on 127.0.0.1 (`port` 0 = any free one, reported in `bound_port`). Throws
// std::runtime_error.
int listen_loopback(int port, int* bound_port);
// Writes all of `data` to a non-blocking descriptor; a peer that went away is left to the read
// side to notice.
void write_all(int fd, const std::string& data);

// A queued or running move of the simulated firmware.
struct Motion {
  long id = 0;
  long line = -1;
  std::string channel;
  std::vector<long> from, to;  // counts
  double length = 0.0;         // G-code units (axis space)
  double feed = 0.0;           // units/s
  double acceleration = 0.0;   // units/s^2
  double start = -1.0;         // s (steady clock); < 0 = not started
  double duration = 0.0;
  bool stall = false;
  bool homing = false;
};

// One received line waiting to be processed.
struct Pending {
  std::string text;
  bool rolled = false;
  std::optional<FaultKind> fault;
};

struct Channel {
  explicit Channel(std::string channel_name) : name(std::move(channel_name)) {}
  std::string name;  // "tcp" or "pty"
  int fd = -1;
  int slave = -1;  // pty only: kept open so the master never sees a hang-up between clients
  std::string inbuf;
  std::deque<Pending> pending;
  long last_n = 0;
  bool blocked = false;  // M400/G28 waiting for the motion queue
  bool blocked_lost_ok = false;
  double next_busy = 0.0;
  double hold_until = 0.0;
  double next_temperature = 0.0;
  // Open protocol: the last request answered (a repeated id gets this reply again) and the
  // blocking request (wait_settled, home) being waited for.
  nlohmann::json last_id;
  std::string last_reply;
  nlohmann::json wait_id;
  std::string wait_cmd;
  long notified_motion = 0;  // motions whose "settled" event was sent
  // Moonraker: the WebSocket upgrade done, and the G-code script being run (its remaining lines
  // and the request it answers).
  bool upgraded = false;
  std::deque<std::string> script;
  nlohmann::json script_id;
  bool script_lost = false;  // fault: the script runs, its answer is lost with the connection
  bool open() const { return fd >= 0; }
};

// The simulated UR controller's state beside the motion (sim_ur.cpp). The RTDE client is the
// `tcp` channel; URScript and the dashboard have channels of their own.
struct SimUr {
  int secondary_listen = -1, secondary_port = -1;
  int dashboard_listen = -1, dashboard_port = -1;
  Channel secondary{"secondary"};
  Channel dashboard{"dashboard"};
  // RTDE session of the connected client.
  int protocol = 1;  // until a client asks for version 2
  std::vector<std::string> names, types;
  std::uint8_t recipe_id = 0;
  bool streaming = false;
  double period = 1.0 / 125.0;
  double next_package = 0.0;
  double late_until = 0.0;     // fault: packages held back until then, then sent at once
  std::string late_packages;   // what was held back
  double missing_until = 0.0;  // fault: no packages until then
  // The controller.
  bool remote = true;
  double speed_fraction = 1.0;
  int robot_mode = 7;      // RUNNING
  int safety = 1;          // NORMAL
  double pstop_at = -1e9;  // when the last protective stop happened
  long pstop_motion = 0;   // fault: the motion that ends in a protective stop
};

struct SimController::Impl {
  SimRobot robot;
  SimOptions options;
  SimCounters counters;
  std::mt19937 noise_rng;
  std::mt19937 fault_rng;
  std::mt19937 flange_rng;  // its own stream: the actuator noise is the same with or without it
  std::FILE* log = nullptr;
  double t0 = now_seconds();

  int tcp_listen = -1, tcp_port = -1;
  int pose_listen = -1, pose_port = -1;
  Channel tcp{"tcp"};
  Channel pty{"pty"};
  std::vector<int> pose_clients;
  std::vector<std::string> pose_buffers;
  std::string pty_path;

  // Firmware state.
  std::vector<long> counts;  // where the steppers are (updated as motions run)
  std::deque<Motion> queue;  // front = running
  long motion_ids = 0;
  double feed;  // units/s
  double acceleration;
  double busy_interval;
  bool halted = false;
  bool stopped_by_request = false;  // open protocol: a controlled stop ended the last motion
  long commands_received = 0;       // numbered commands (fault script index)
  Eigen::VectorXd physical_offset;  // backlash + repeatability of the current position
  std::vector<int> last_direction;

  Impl(SimRobot r, SimOptions o);
  ~Impl();
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  double t() const { return now_seconds() - t0; }

  // ---- the true robot and its log (sim_motion.cpp) -------------------------------------------
  std::vector<long> counts_of(const Eigen::VectorXd& readings) const;
  double units_of(long count, int axis) const;
  // Delta firmware: the nozzle (mm, the firmware's frame) at step counts.
  Eigen::Vector3d nozzle_of(const std::vector<long>& c) const;
  void write_log(nlohmann::json j);
  void start_next_motion(double now);
  std::vector<double> readings_of(const std::vector<long>& c) const;
  std::vector<long> interpolate(const Motion& m, double now) const;
  void finish_motion(const Motion& m, const std::vector<long>& reached, bool stopped);
  void advance_motion(double now);
  void quick_stop(const std::string& how);
  Eigen::VectorXd true_readings(double now) const;

  // ---- channels and the pose channel (sim_server.cpp) ----------------------------------------
  void open_pty();
  void reset_channel(Channel& c);
  void close_channel(Channel& c, bool reopen);
  void send(Channel& c, const std::string& line);
  double next_event(double now) const;
  void serve_pose(std::size_t i);
  void accept_on(int listen_fd, Channel* channel);

  void on_connect(Channel& c);
  // Appends the bytes waiting on the channel to its input; false when none came (closed: the
  // channel is closed too).
  bool read_input(Channel& c);
  void receive_any(Channel& c);
  void process_any(Channel& c, double now);

  // ---- faults (sim_faults.cpp) ---------------------------------------------------------------
  // The fault drawn for the next received command (script or rates), before any filtering.
  std::optional<FaultKind> draw_fault();
  std::optional<FaultKind> roll_fault(const std::string& cmd);
  void void_fault(Channel& c, std::optional<FaultKind> fault);

  // ---- the G-code firmware (sim_gcode.cpp) ---------------------------------------------------
  void greet(Channel& c);
  std::string position_report(bool partial) const;
  std::string firmware_report() const;
  void reply_ok(Channel& c, bool lost);
  void block(Channel& c, bool lost_ok);
  void execute(Channel& c, const std::string& cmd, long line, std::optional<FaultKind> fault);
  // G0/G1: the target counts (raw axes, or the delta firmware's inverse kinematics); nullopt
  // when the delta cannot reach the target.
  std::optional<std::vector<long>> move_target(const std::string& cmd) const;
  // M503, M665, M666: the firmware's settings reports.
  bool report_settings(Channel& c, const std::string& code, bool lost);
  void handle_line(Channel& c, Pending& item);
  void receive(Channel& c);
  void process(Channel& c, double now);

  // ---- the open link protocol (sim_open.cpp) -------------------------------------------------
  void open_receive(Channel& c);
  void open_process(Channel& c, double now);
  void open_handle(Channel& c, Pending& item);
  // Executes one request; returns the reply, or nullopt when it blocks (wait_settled, home).
  std::optional<nlohmann::json> open_execute(Channel& c, const nlohmann::json& request,
                                             std::optional<FaultKind> fault);
  void open_reply(Channel& c, const nlohmann::json& id, nlohmann::json reply, bool lost);
  nlohmann::json open_position() const;
  // The `flange_pose` field of a read reply: the true robot's pose where it stands, with the
  // configured noise; null where the true robot cannot assemble.
  nlohmann::json open_flange_pose();
  // A stop acts on receipt, even while a wait_settled blocks the request queue.
  void open_stop(Channel& c, const std::string& kind);
  std::optional<FaultKind> open_roll_fault(const std::string& cmd);

  // ---- Universal Robots (sim_ur.cpp) ---------------------------------------------------------
  SimUr ur;
  void ur_start();
  void ur_close();
  void ur_on_connect(Channel& c);
  void ur_receive(Channel& c);
  void ur_process(Channel& c, double now);
  void ur_rtde_package(Channel& c, std::uint8_t type, const std::string& payload);
  std::string ur_data_package(double now) const;
  void ur_send_packages(Channel& c, double now);
  void ur_script(Channel& c, const std::string& line);
  void ur_movej(Channel& c, const std::vector<double>& q, double a, double v,
                std::optional<FaultKind> fault);
  std::string ur_dashboard_reply(Channel& c, const std::string& command);
  void ur_script_exception(Channel& c, const std::string& text);
  void ur_protective_stop(const std::string& why);
  std::optional<FaultKind> ur_roll_fault(const std::string& cmd);

  // ---- Klipper behind Moonraker (sim_moonraker.cpp) ------------------------------------------
  std::string klippy_state = "ready";  // ready, shutdown (emergency stop, a fault)
  std::string klippy_message = "Printer is ready";
  bool klipper_homed = false;
  // Replies of the G-code engine while a Moonraker script runs (G-code lines are not sent).
  std::vector<std::string>* gcode_capture = nullptr;
  void moonraker_receive(Channel& c);
  void moonraker_process(Channel& c, double now);
  void moonraker_request(Channel& c, const nlohmann::json& request, std::optional<FaultKind> fault);
  void moonraker_send(Channel& c, const nlohmann::json& message);
  void moonraker_answer(Channel& c, const nlohmann::json& id, const nlohmann::json& result);
  void moonraker_error(Channel& c, const nlohmann::json& id, int code, const std::string& message);
  void moonraker_notify(Channel& c, const std::string& method, nlohmann::json params);
  // Runs the script's lines until one blocks (G28, M400) or all ran; answers the request then.
  void moonraker_run_script(Channel& c);
  // Klippy halts (emergency stop or an injected shutdown): motion stops, clients are told.
  void klippy_shutdown(Channel& c, const std::string& why);
  std::string klipper_get_position() const;
  std::optional<FaultKind> moonraker_roll_fault(const std::string& method);
};

}  // namespace robocal::robotio
