#pragma once
// The Universal Robots link: state and readings from RTDE (TCP 30004, rtde.hpp), motion as
// URScript `movej` on the secondary client interface (TCP 30002), robot mode, safety status,
// remote control, stop, popups and (only when the operator said so) unlocking a protective stop
// through the dashboard server (TCP 29999). Every motion passes the SafetyGuard in RobotLink.
//
// A move is settled when every joint of RTDE's actual_q is within `joint_tolerance` of the target
// and every |actual_qd| is below `speed_threshold`, for `settle_packages` data packages in a row.
// A UR in protective stop, with remote control off, not RUNNING, or with its speed slider below
// 100 % is refused before anything is sent, naming the device and what it said.
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/robot_link.hpp"
#include "robocal/robotio/rtde.hpp"
#include "robocal/robotio/transport.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace robocal::robotio {

// "ur:HOST" (the controller's standard ports) or "ur:HOST:RTDE:SECONDARY:DASHBOARD" (a simulator
// or a port-forwarded controller). Throws LinkError naming the address otherwise.
struct UrAddress {
  std::string host;
  int rtde_port = 30004;
  int secondary_port = 30002;
  int dashboard_port = 29999;
};
bool is_ur_link_address(const std::string& address);
UrAddress parse_ur_address(const std::string& address);

// The outputs robocal needs from RTDE, in this order.
const std::vector<std::string>& ur_output_names();
// Asked for after them when the controller knows it: `tcp_offset` (the active TCP, flange -> TCP,
// x y z rx ry rz), which turns actual_TCP_pose into the flange pose. A controller whose software
// predates it answers NOT_FOUND; the link then sets the recipe up without it and reports no
// flange pose.
const std::string& ur_tcp_offset_output();

// A UR pose [x, y, z, rx, ry, rz] (metres; rotation vector in radians: axis times angle) as a
// transform, and back.
Eigen::Isometry3d ur_pose_to_isometry(const Eigen::VectorXd& pose);
Eigen::Matrix<double, 6, 1> ur_pose_from_isometry(const Eigen::Isometry3d& pose);
// base -> flange from actual_TCP_pose (base -> TCP) and tcp_offset (flange -> TCP):
// base_T_tcp * inverse(flange_T_tcp).
Eigen::Isometry3d ur_flange_pose(const Eigen::VectorXd& tcp_pose,
                                 const Eigen::VectorXd& tcp_offset);

// One RTDE data package of that recipe, in SI units (rad, rad/s, m).
struct UrState {
  Eigen::VectorXd actual_q, actual_qd, target_q;
  int robot_mode = -1;          // 7 = RUNNING
  int safety_status = -1;       // 1 = NORMAL, 3 = PROTECTIVE_STOP
  int runtime_state = -1;       // 1 = STOPPED, 2 = PLAYING
  double speed_fraction = 0.0;  // target_speed_fraction: the speed slider, 0..1
  double speed_scaling = 0.0;
  Eigen::VectorXd tcp_pose;    // actual_TCP_pose: x y z rx ry rz
  Eigen::VectorXd tcp_offset;  // tcp_offset (empty when the recipe lacks it)
  double timestamp = 0.0;
};
// A data package of ur_output_names(), optionally followed by ur_tcp_offset_output().
UrState ur_state_from(const rtde::DataPackage& package, int joints);
// The UR's names for robot modes and safety statuses (RTDE guide, dashboard wording).
std::string ur_robot_mode_name(int mode);
std::string ur_safety_status_name(int status);
// The text after "Name: " in a dashboard reply ("Safetystatus: NORMAL" -> "NORMAL").
std::string ur_dashboard_value(const std::string& reply);
// Why `state` does not allow a move ("" when it does): protective stop, not running, slider.
std::string ur_motion_blocker(const UrState& state);
// The URScript line robocal sends for a joint move (rad, rad/s, rad/s^2).
std::string urscript_movej(const Eigen::VectorXd& q, double acceleration, double speed);
std::string urscript_stopj(double deceleration);

struct UrLinkOptions {
  std::string address;                            // ur:HOST[:RTDE:SECONDARY:DASHBOARD]
  std::chrono::milliseconds reply_timeout{1000};  // RTDE setup replies, dashboard replies
  // Silence on the RTDE stream longer than this while streaming is a lost connection.
  std::chrono::milliseconds package_timeout{1000};
  int attempts = 3;                // a movej sent again when the robot did not take it
  int reconnect_attempts = 6;      // 250 ms apart
  double frequency = 125.0;        // RTDE output frequency, Hz (CB3: at most 125; e-Series: 500)
  double joint_tolerance = 1e-4;   // rad, settled and at-target test
  double speed_threshold = 1e-3;   // rad/s, "not moving"
  int settle_packages = 3;         // data packages in a row that must be settled
  double stop_deceleration = 2.0;  // rad/s^2 of stopj
  // The operator confirmed that a protective stop may be unlocked from here (after inspecting
  // its cause). Without it a protective stop is refused. With it, the unlock happens only before
  // a move the guard passed (never on connect).
  bool unlock_protective_stop = false;
};

class UrLink final : public RobotLink {
 public:
  UrLink(SafetyGuard& guard, UrLinkOptions options);
  ~UrLink() override;

  FirmwareInfo connect() override;
  void reconnect() override;
  void disconnect() override;
  LinkStatus status() const override { return status_; }
  int actuator_count() const override { return static_cast<int>(scale_.size()); }
  // The latest data package (for tests and the wizard's probe).
  const UrState& last_state() const { return state_; }
  // A dashboard command and its one-line answer.
  std::string dashboard(const std::string& command);

 protected:
  void do_home() override {}  // a UR keeps its own absolute encoders: nothing to home
  void do_move(const Eigen::VectorXd& target, const MoveSpeed& speed) override;
  void do_wait_settled(std::chrono::milliseconds timeout) override;
  ActuatorReadings do_read() override;
  void do_stop(StopKind kind) override;
  bool at_target(const ActuatorReadings& readings, const Eigen::VectorXd& target) const override;
  double expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                          const MoveSpeed& speed) const override;

 private:
  [[noreturn]] void fail(const std::string& problem, const std::string& said = "");
  void open_all();
  void close_all();
  void check_dashboard_state();
  void rtde_handshake();
  rtde::Package rtde_reply(rtde::PackageType type);
  void rtde_send(const std::string& bytes);
  void start_stream();
  void pause_stream();
  // Reads packages until a data package arrives or `deadline` passes (false then).
  bool next_state(Clock::time_point deadline);
  // A fresh data package, streaming started if it was not; reconnects once when the stream
  // is gone.
  const UrState& fresh_state();
  void require_motion_allowed();
  void unlock_protective_stop();
  void send_script(const std::string& line);
  // Reads what the secondary interface sent since (robot state, robot messages; never waits) and
  // keeps the robot messages that matter (ur_primary.hpp) as the controller's word.
  void poll_secondary();
  // "; the controller said: …" when it said something since the last script, else "".
  std::string controller_said() const;
  bool settled_at(const Eigen::VectorXd& target_si) const;
  void stop_for(const std::string& why);
  enum class Wait : std::uint8_t { kSettled, kNotStarted, kLost, kProtectiveStop };
  Wait watch_move(Clock::time_point deadline, Clock::time_point start_deadline);
  Eigen::VectorXd to_si(const Eigen::VectorXd& readings) const;

  UrLinkOptions options_;
  UrAddress where_;
  std::string device_;
  TcpTransport rtde_, secondary_, dashboard_;
  std::string rtde_buffer_;
  std::string secondary_buffer_;
  std::string controller_said_;  // the last robot message that matters, since the last script
  rtde::OutputRecipe recipe_;
  bool streaming_ = false;
  bool has_tcp_offset_ = false;  // the recipe carries tcp_offset: readings carry the flange pose
  UrState state_;
  int settled_run_ = 0;
  bool move_started_ = false;
  bool settled_state_ = false;  // state_ is the settle's last package, not yet read
  Eigen::VectorXd scale_;  // SI joint units per reading (the robot file's nominal encoder scale)
  Eigen::VectorXd target_si_;
  std::string last_script_;
  LinkStatus status_;
  mutable double expected_move_seconds_ = 0.0;
};

}  // namespace robocal::robotio
