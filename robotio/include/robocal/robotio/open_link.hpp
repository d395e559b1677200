#pragma once
// The open link: robocal's protocol for robots whose controller has no standard interface (a
// Gantry-Tau, a modular arm, a wire robot, a Delta on a custom board). JSON lines over TCP,
// specified in robotio/OPEN_LINK.md; a lab implements it in an adapter beside its controller
// (robotio/adapters/open_link_adapter.py is the reference) and checks it with
// `robocal link-check`.
//
// OpenLinkClient is the protocol itself (ids, framing, deadlines, a lost reply asked for again
// under the same id); OpenLink is the RobotLink on top of it, with the G-code link's settle,
// verify and recovery rules: a move is confirmed by the controller's counts (or its position to
// half a resolution step), a lost connection is re-established and the position checked before
// a move is re-sent, a move that does not settle is stopped.
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/robot_link.hpp"
#include "robocal/robotio/transport.hpp"

#include <nlohmann/json.hpp>

#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace robocal::robotio {

inline constexpr const char* kOpenLinkProtocol = "robocal-open-link";
inline constexpr int kOpenLinkMajor = 1;
inline constexpr int kOpenLinkMinor = 0;

struct OpenLinkActuator {
  std::string name;
  std::string unit;         // "m" or "rad"
  double resolution = 0.0;  // smallest position step, in `unit`
};

// What a controller says in its `hello` reply.
struct OpenLinkHello {
  std::string protocol;
  int major = 0, minor = 0;
  std::string controller;
  std::vector<std::string> capabilities;
  std::vector<OpenLinkActuator> actuators;
  double keepalive_s = 0.0;
  bool has(const std::string& capability) const;
};
// Reads a successful hello reply. Throws std::invalid_argument naming the first missing or
// malformed field.
OpenLinkHello parse_open_hello(const nlohmann::json& reply);
// "" when the controller's actuators fit the robot file (count, and units by joint type);
// otherwise what differs, naming both sides.
std::string open_hello_mismatch(const OpenLinkHello& hello, const calib::Mechanism& model);

// The `flange_pose` of a read reply (capability `flange_pose`): {"position": [x, y, z] in metres,
// "quaternion_xyzw": [x, y, z, w] of a unit quaternion}, base -> flange. nullopt and `problem`
// (naming the field) when it is missing or malformed.
std::optional<Eigen::Isometry3d> parse_open_flange_pose(const nlohmann::json& reply,
                                                        std::string& problem);

// An error reply's code and message; code 0 for a success.
struct OpenLinkFailure {
  int code = 0;
  std::string message;
};
OpenLinkFailure open_reply_failure(const nlohmann::json& reply);

// No reply within the total deadline (a stalled move, a controller that stopped answering).
class OpenLinkTimeout : public LinkError {
 public:
  using LinkError::LinkError;
};

class OpenLinkClient {
 public:
  // `device`: how messages name the controller ("open link 10.0.0.5:7001").
  OpenLinkClient(std::unique_ptr<Transport> transport, std::string device);
  void open();
  void close() { transport_->close(); }
  bool is_open() const { return transport_->is_open(); }
  const std::string& device() const { return device_; }
  // Request ids start again at 1 (a new connection).
  void restart_ids() { next_id_ = 1; }

  // Sends `request` with the next id and returns the reply carrying that id (success or error).
  // Silence longer than `silence` sends the same line again (same id: a controller that already
  // executed it repeats its reply), at most `attempts` sends in all; `busy` notifications and
  // any other line extend the silence; nothing is suspicious before `quiet_until`. `tick` runs
  // at least every 50 ms while waiting (it may throw). Throws OpenLinkTimeout past `total`,
  // LinkError when the attempts are used up or the connection is lost.
  nlohmann::json request(nlohmann::json request, std::chrono::milliseconds silence,
                         std::chrono::milliseconds total, int attempts,
                         const std::function<void()>& tick = {},
                         Clock::time_point quiet_until = {});
  // Conformance checks: a raw line, and the next JSON object line (notifications included).
  void write_raw(const std::string& line) { transport_->write_line(line); }
  std::optional<nlohmann::json> read_json(Clock::time_point deadline);

  const std::string& last_line() const { return last_line_; }
  long garbage() const { return garbage_; }  // lines that were not JSON objects
  long repeats() const { return repeats_; }  // requests sent again after silence
  long stale() const { return stale_; }      // replies to other ids (after a repeat)
  long notifications() const { return notifications_; }
  // The last `settled` notification (null when none came).
  const nlohmann::json& last_settled() const { return last_settled_; }

 private:
  std::unique_ptr<Transport> transport_;
  std::string device_;
  long next_id_ = 1;
  std::string last_line_;
  long garbage_ = 0, repeats_ = 0, stale_ = 0, notifications_ = 0;
  nlohmann::json last_settled_;
};

struct OpenLinkOptions {
  std::string address;  // open:HOST:PORT
  std::chrono::milliseconds reply_timeout{1000};
  int attempts = 4;            // per request: sends after silence; repeats of a refusal (200)
  int reconnect_attempts = 6;  // 250 ms apart
};

// "open:HOST:PORT" (robocal's --link form). Throws LinkError naming the address otherwise.
bool is_open_link_address(const std::string& address);
std::unique_ptr<Transport> open_link_transport(const std::string& address);

class OpenLink final : public RobotLink {
 public:
  OpenLink(SafetyGuard& guard, const OpenLinkOptions& options);
  // Test hook / custom transports: the link owns `transport`.
  OpenLink(SafetyGuard& guard, OpenLinkOptions options, std::unique_ptr<Transport> transport);

  FirmwareInfo connect() override;
  void reconnect() override;
  void disconnect() override;
  LinkStatus status() const override;
  int actuator_count() const override { return static_cast<int>(scale_.size()); }
  bool reports_flange_pose() const override { return hello_.has("flange_pose"); }
  const OpenLinkHello& hello() const { return hello_; }
  // The controller's counts at `readings` (what it reports at that target).
  std::vector<long> counts_for(const Eigen::VectorXd& readings) const;

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
  void handshake();
  // Throws LinkError when no hello was answered yet (nothing is known of the actuators).
  void require_hello() const;
  [[noreturn]] void fail(const std::string& problem);
  // One request; a refusal for now (200) is repeated as a new request, any other error throws
  // LinkError with the controller's code and message.
  nlohmann::json call(const nlohmann::json& request, std::chrono::milliseconds silence,
                      std::chrono::milliseconds total, bool interruptible,
                      Clock::time_point quiet_until = {});
  void wait_until_settled(std::chrono::milliseconds total, Clock::time_point motion_end);
  std::chrono::milliseconds wait_silence(std::chrono::milliseconds total) const;
  void send_stop_during_wait();
  Eigen::VectorXd to_si(const Eigen::VectorXd& readings) const;
  ActuatorReadings readings_from(const nlohmann::json& reply) const;

  OpenLinkOptions options_;
  OpenLinkClient client_;
  Eigen::VectorXd scale_;  // SI joint units per reading (the robot file's nominal encoder scale)
  OpenLinkHello hello_;
  LinkStatus status_;
  mutable double expected_move_seconds_ = 0.0;
};

}  // namespace robocal::robotio
