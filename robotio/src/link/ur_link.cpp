// The Universal Robots link (ur_link.hpp): RTDE for state and readings, URScript on the secondary
// client interface for motion, the dashboard server for modes, stops and the operator-approved
// protective-stop unlock. RTDE streams only while the link is watching (start ... pause), so no
// package piles up in the socket while the cameras take their pictures.
#include "robocal/robotio/ur_link.hpp"

#include "robocal/calib/mechanism.hpp"
#include "robocal/robotio/motion_profile.hpp"
#include "robocal/robotio/ur_primary.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <thread>
#include <utility>

namespace robocal::robotio {
namespace {

using std::chrono::milliseconds;

constexpr int kUrJoints = 6;
constexpr int kRunning = 7;
constexpr int kNormal = 1, kReduced = 2, kProtectiveStop = 3;
constexpr int kPlaying = 2;

int parse_port(const std::string& text, const std::string& address) {
  int port = 0;
  for (char c : text) {
    if (c < '0' || c > '9' || port > 65535)
      throw LinkError(address, "port '" + text + "' is not a number within 1..65535");
    port = port * 10 + (c - '0');
  }
  if (text.empty() || port < 1 || port > 65535)
    throw LinkError(address, "port '" + text + "' is not a number within 1..65535");
  return port;
}

std::vector<std::string> split_colons(const std::string& text) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  for (;;) {
    const std::size_t colon = text.find(':', start);
    parts.push_back(text.substr(start, colon == std::string::npos ? colon : colon - start));
    if (colon == std::string::npos) return parts;
    start = colon + 1;
  }
}

Eigen::VectorXd vector_of(const rtde::FieldValues& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

}  // namespace

bool is_ur_link_address(const std::string& address) {
  return address.rfind("ur:", 0) == 0;
}

UrAddress parse_ur_address(const std::string& address) {
  if (!is_ur_link_address(address))
    throw LinkError(address, "expected ur:HOST or ur:HOST:RTDE_PORT:SECONDARY_PORT:DASHBOARD_PORT");
  const std::vector<std::string> parts = split_colons(address.substr(3));
  if ((parts.size() != 1 && parts.size() != 4) || parts[0].empty())
    throw LinkError(address,
                    "expected ur:HOST (ports 30004, 30002, 29999) or "
                    "ur:HOST:RTDE_PORT:SECONDARY_PORT:DASHBOARD_PORT");
  UrAddress a;
  a.host = parts[0];
  if (parts.size() == 4) {
    a.rtde_port = parse_port(parts[1], address);
    a.secondary_port = parse_port(parts[2], address);
    a.dashboard_port = parse_port(parts[3], address);
  }
  return a;
}

const std::vector<std::string>& ur_output_names() {
  static const std::vector<std::string> names = {
      "timestamp",     "actual_q",       "actual_qd",     "target_q",
      "robot_mode",    "safety_status",  "runtime_state", "target_speed_fraction",
      "speed_scaling", "actual_TCP_pose"};
  return names;
}

const std::string& ur_tcp_offset_output() {
  static const std::string name = "tcp_offset";
  return name;
}

Eigen::Isometry3d ur_pose_to_isometry(const Eigen::VectorXd& pose) {
  if (pose.size() != 6)
    throw std::invalid_argument(fmt::format("a UR pose has 6 values, not {}", pose.size()));
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d r = pose.tail<3>();
  const double angle = r.norm();
  if (angle > 0.0) t.linear() = Eigen::AngleAxisd(angle, r / angle).toRotationMatrix();
  t.translation() = pose.head<3>();
  return t;
}

Eigen::Matrix<double, 6, 1> ur_pose_from_isometry(const Eigen::Isometry3d& pose) {
  const Eigen::AngleAxisd r(pose.linear());
  Eigen::Matrix<double, 6, 1> out;
  out << pose.translation(), r.angle() * r.axis();
  return out;
}

Eigen::Isometry3d ur_flange_pose(const Eigen::VectorXd& tcp_pose,
                                 const Eigen::VectorXd& tcp_offset) {
  return ur_pose_to_isometry(tcp_pose) * ur_pose_to_isometry(tcp_offset).inverse();
}

UrState ur_state_from(const rtde::DataPackage& package, int joints) {
  const std::size_t n = ur_output_names().size();
  if (package.fields.size() != n && package.fields.size() != n + 1)
    throw rtde::RtdeFormatError(
        fmt::format("a data package of {} fields, the recipe has {}", package.fields.size(), n));
  const auto& f = package.fields;
  UrState s;
  s.timestamp = f[0][0];
  s.actual_q = vector_of(f[1]).head(joints);
  s.actual_qd = vector_of(f[2]).head(joints);
  s.target_q = vector_of(f[3]).head(joints);
  s.robot_mode = static_cast<int>(f[4][0]);
  s.safety_status = static_cast<int>(f[5][0]);
  s.runtime_state = static_cast<int>(f[6][0]);
  s.speed_fraction = f[7][0];
  s.speed_scaling = f[8][0];
  s.tcp_pose = vector_of(f[9]);
  if (f.size() > n) s.tcp_offset = vector_of(f[n]);
  return s;
}

std::string ur_robot_mode_name(int mode) {
  static const char* const names[] = {
      "NO_CONTROLLER", "DISCONNECTED", "CONFIRM_SAFETY", "BOOTING", "POWER_OFF",
      "POWER_ON",      "IDLE",         "BACKDRIVE",      "RUNNING", "UPDATING_FIRMWARE"};
  if (mode < -1 || mode > 8) return fmt::format("mode {}", mode);
  return names[mode + 1];
}

std::string ur_safety_status_name(int status) {
  static const char* const names[] = {"",
                                      "NORMAL",
                                      "REDUCED",
                                      "PROTECTIVE_STOP",
                                      "RECOVERY",
                                      "SAFEGUARD_STOP",
                                      "SYSTEM_EMERGENCY_STOP",
                                      "ROBOT_EMERGENCY_STOP",
                                      "VIOLATION",
                                      "FAULT",
                                      "VALIDATE_JOINT_ID",
                                      "UNDEFINED_SAFETY_MODE",
                                      "AUTOMATIC_MODE_SAFEGUARD_STOP",
                                      "SYSTEM_THREE_POSITION_ENABLING_STOP"};
  if (status < 1 || status > 13) return fmt::format("status {}", status);
  return names[status];
}

std::string ur_dashboard_value(const std::string& reply) {
  const std::size_t colon = reply.find(": ");
  return colon == std::string::npos ? reply : reply.substr(colon + 2);
}

std::string ur_motion_blocker(const UrState& state) {
  if (state.safety_status != kNormal && state.safety_status != kReduced)
    return fmt::format("safety status {} ({})", ur_safety_status_name(state.safety_status),
                       state.safety_status);
  if (state.robot_mode != kRunning)
    return fmt::format("robot mode {} ({}): power on and release the brakes on the pendant",
                       ur_robot_mode_name(state.robot_mode), state.robot_mode);
  if (state.speed_fraction < 0.999)
    return fmt::format(
        "the speed slider is at {:.0f} %: set it to 100 % (robocal's move times and the guard's "
        "speed checks assume the commanded speed)",
        100.0 * state.speed_fraction);
  return "";
}

std::string urscript_movej(const Eigen::VectorXd& q, double acceleration, double speed) {
  std::string joints;
  for (Eigen::Index i = 0; i < q.size(); ++i) joints += fmt::format("{}{:.9f}", i ? "," : "", q[i]);
  return fmt::format("movej([{}], a={:.6f}, v={:.6f})", joints, acceleration, speed);
}

std::string urscript_stopj(double deceleration) {
  return fmt::format("stopj({:.6f})", deceleration);
}

UrLink::UrLink(SafetyGuard& guard, UrLinkOptions options)
    : RobotLink(guard),
      options_(std::move(options)),
      where_(parse_ur_address(options_.address)),
      device_("UR " + where_.host),
      rtde_(where_.host, where_.rtde_port),
      secondary_(where_.host, where_.secondary_port),
      dashboard_(where_.host, where_.dashboard_port),
      scale_(nominal_encoder_scales(guard)) {
  status_.device = device_;
}

UrLink::~UrLink() {
  close_all();
}

void UrLink::fail(const std::string& problem, const std::string& said) {
  status_.last_error = problem;
  ++status_.errors;
  throw LinkError(device_, problem, said);
}

Eigen::VectorXd UrLink::to_si(const Eigen::VectorXd& readings) const {
  return readings.cwiseProduct(scale_);
}

void UrLink::close_all() {
  secondary_buffer_.clear();
  rtde_.close();
  secondary_.close();
  dashboard_.close();
  streaming_ = false;
  rtde_buffer_.clear();
}

// Opens the three connections; the dashboard greets every client with one line.
void UrLink::open_all() {
  close_all();
  try {
    dashboard_.open();
    rtde_.open();
    secondary_.open();
  } catch (const LinkError& e) {
    close_all();
    throw LinkError(device_, e.what());
  }
  const std::optional<std::string> hello =
      dashboard_.read_line(Clock::now() + options_.reply_timeout);
  if (!hello || hello->find("Dashboard Server") == std::string::npos)
    fail(fmt::format("port {} is not a UR dashboard server", where_.dashboard_port),
         hello.value_or(""));
  rtde_handshake();
}

std::string UrLink::dashboard(const std::string& command) {
  try {
    dashboard_.write_line(command);
    const std::optional<std::string> reply =
        dashboard_.read_line(Clock::now() + options_.reply_timeout);
    if (!reply) fail(fmt::format("the dashboard server did not answer '{}'", command));
    ++status_.commands;
    return *reply;
  } catch (const LinkError& e) {
    if (e.device() == device_) throw;
    throw LinkError(device_, fmt::format("dashboard '{}': {}", command, e.what()));
  }
}

void UrLink::rtde_send(const std::string& bytes) {
  try {
    rtde_.write_bytes(bytes);
  } catch (const LinkError& e) {
    throw LinkError(device_, fmt::format("RTDE: {}", e.what()));
  }
}

// The reply of `type`; data packages still in flight (sent before a pause took effect) and text
// messages are read past.
rtde::Package UrLink::rtde_reply(rtde::PackageType type) {
  const auto deadline = Clock::now() + options_.reply_timeout;
  for (;;) {
    try {
      while (std::optional<rtde::Package> p = rtde::take_package(rtde_buffer_)) {
        if (p->type == static_cast<std::uint8_t>(type)) return *p;
        if (p->type == static_cast<std::uint8_t>(rtde::PackageType::kTextMessage))
          status_.last_error = rtde::decode_text_message(*p).message;
      }
    } catch (const rtde::RtdeFormatError& e) {
      fail(fmt::format("RTDE answered something that is not an RTDE package: {}", e.what()));
    }
    std::optional<std::string> bytes;
    try {
      bytes = rtde_.read_some(deadline);
    } catch (const LinkError& e) {
      throw LinkError(device_, fmt::format("RTDE: {}", e.what()));
    }
    if (!bytes)
      fail(fmt::format("RTDE did not answer {} within {} ms", rtde::to_string(type),
                       options_.reply_timeout.count()));
    rtde_buffer_ += *bytes;
  }
}

void UrLink::rtde_handshake() {
  rtde_send(rtde::encode_request_protocol_version(rtde::kProtocolVersion));
  if (!rtde::decode_accepted(rtde_reply(rtde::PackageType::kRequestProtocolVersion)))
    fail("the controller refuses RTDE protocol version 2 (RTDE needs CB3 software 3.4 or newer)");
  rtde_send(rtde::encode_get_urcontrol_version());
  rtde::ControllerVersion version;
  try {
    version = rtde::decode_controller_version(rtde_reply(rtde::PackageType::kGetUrControlVersion));
  } catch (const rtde::RtdeFormatError& e) {
    fail(fmt::format("RTDE's controller version reply: {}", e.what()));
  }
  // tcp_offset first with the rest; a controller that predates it gets the recipe without it.
  std::vector<std::string> names = ur_output_names();
  names.push_back(ur_tcp_offset_output());
  std::vector<std::string> unknown;
  for (int round = 0; round < 2; ++round) {
    rtde_send(rtde::encode_setup_outputs(options_.frequency, names));
    try {
      recipe_ = rtde::decode_output_recipe(rtde_reply(rtde::PackageType::kSetupOutputs));
      unknown = rtde::unknown_outputs(names, recipe_);
    } catch (const rtde::RtdeFormatError& e) {
      fail(fmt::format("RTDE's output recipe reply: {}", e.what()));
    }
    if (unknown.size() == 1 && unknown.front() == ur_tcp_offset_output() && round == 0) {
      names.pop_back();
      continue;
    }
    break;
  }
  has_tcp_offset_ = names.back() == ur_tcp_offset_output();
  std::erase(unknown, ur_tcp_offset_output());
  if (!unknown.empty()) {
    std::string list;
    for (const std::string& n : unknown) list += (list.empty() ? "'" : ", '") + n + "'";
    fail(
        fmt::format("RTDE on URControl {} does not know the output{} {} (NOT_FOUND): robocal "
                    "needs them to read the joints and the robot's state; update the "
                    "controller's software",
                    version.text(), unknown.size() > 1 ? "s" : "", list));
  }
  status_.firmware = {Firmware::kUnknown, "Universal Robots URControl " + version.text(),
                      version.text(),
                      has_tcp_offset_ ? "RTDE protocol version 2"
                                      : "RTDE protocol version 2 (no tcp_offset output: the "
                                        "readings carry no flange pose)"};
}

void UrLink::start_stream() {
  if (streaming_) return;
  rtde_send(rtde::encode_start());
  if (!rtde::decode_accepted(rtde_reply(rtde::PackageType::kStart)))
    fail("RTDE refused to start the output stream");
  streaming_ = true;
}

void UrLink::pause_stream() {
  if (!streaming_) return;
  rtde_send(rtde::encode_pause());
  (void)rtde_reply(rtde::PackageType::kPause);
  streaming_ = false;
  rtde_buffer_.clear();
}

bool UrLink::next_state(Clock::time_point deadline) {
  for (;;) {
    try {
      while (std::optional<rtde::Package> p = rtde::take_package(rtde_buffer_)) {
        if (p->type != static_cast<std::uint8_t>(rtde::PackageType::kDataPackage)) continue;
        const rtde::DataPackage d = rtde::decode_data_package(*p, recipe_.types);
        if (d.recipe_id != recipe_.id) continue;
        state_ = ur_state_from(d, actuator_count());
        return true;
      }
    } catch (const rtde::RtdeFormatError& e) {
      fail(fmt::format("RTDE data package does not match the recipe: {}", e.what()));
    }
    std::optional<std::string> bytes;
    try {
      bytes = rtde_.read_some(deadline);
    } catch (const LinkError& e) {
      streaming_ = false;
      throw LinkError(device_, fmt::format("RTDE: {}", e.what()));
    }
    if (!bytes) return false;
    rtde_buffer_ += *bytes;
  }
}

const UrState& UrLink::fresh_state() {
  for (int round = 0; round < 2; ++round) {
    try {
      start_stream();
      if (next_state(Clock::now() + options_.package_timeout)) return state_;
      ++status_.timeouts;
    } catch (const LinkError&) {
      if (round == 1) throw;
    }
    reconnect();
  }
  fail(fmt::format("no RTDE data package within {} ms", options_.package_timeout.count()));
}

void UrLink::check_dashboard_state() {
  const std::string remote = dashboard("is in remote control");
  if (remote == "false")
    fail(
        "remote control is off: switch the teach pendant to Remote Control so the secondary "
        "interface accepts robocal's URScript",
        remote);
  const std::string safety = dashboard("safetystatus");
  const std::string status = ur_dashboard_value(safety);
  if (status == "PROTECTIVE_STOP") {
    if (!options_.unlock_protective_stop)
      fail(
          "the UR is in a protective stop: inspect its cause, then unlock it on the pendant (or "
          "let robocal unlock it after you confirm)",
          safety);
    // Unlocked before the first move (require_motion_allowed), which the guard passed only once
    // the operator confirmed: connecting alone never releases a stop.
    status_.last_error = "in a protective stop: unlocked before the first move, as allowed";
  } else if (status != "NORMAL" && status != "REDUCED") {
    fail(fmt::format("the UR's safety status is {}: clear it on the pendant", status), safety);
  }
  const std::string mode = dashboard("robotmode");
  if (ur_dashboard_value(mode) != "RUNNING")
    fail("the arm is not running: power it on and release the brakes on the pendant", mode);
}

// Only after the operator's confirmation (options_.unlock_protective_stop). The controller itself
// refuses within 5 s of the stop; the link asks again until it releases or 8 s pass.
void UrLink::unlock_protective_stop() {
  const auto until = Clock::now() + std::chrono::seconds(8);
  std::string reply;
  for (;;) {
    (void)dashboard("close safety popup");
    reply = dashboard("unlock protective stop");
    if (reply == "Protective stop releasing") break;
    if (Clock::now() >= until) fail("the protective stop could not be unlocked", reply);
    std::this_thread::sleep_for(milliseconds(500));
  }
  status_.last_error = "protective stop unlocked on the operator's confirmation";
  // Packages already streamed still say PROTECTIVE_STOP: the next state is read afresh.
  pause_stream();
  for (;;) {
    if (ur_dashboard_value(dashboard("safetystatus")) == "NORMAL") return;
    if (Clock::now() >= until) fail("the protective stop did not release", reply);
    std::this_thread::sleep_for(milliseconds(50));
  }
}

FirmwareInfo UrLink::connect() {
  if (actuator_count() != kUrJoints)
    throw LinkError(device_, fmt::format("the robot file '{}' has {} actuators; a UR arm has {}",
                                         guard().model().name, actuator_count(), kUrJoints));
  for (int round = 0;; ++round) {
    try {
      if (round > 0) std::this_thread::sleep_for(milliseconds(250));
      open_all();
      break;
    } catch (const LinkError& e) {
      // Nobody listening yet is retried; anything a controller said is final.
      if (dashboard_.is_open() || round >= options_.reconnect_attempts) throw;
    }
  }
  check_dashboard_state();
  set_last_known(do_read().values);
  status_.state = LinkState::kIdle;
  return status_.firmware;
}

void UrLink::reconnect() {
  std::string why;
  for (int attempt = 0; attempt < options_.reconnect_attempts; ++attempt) {
    if (attempt > 0) std::this_thread::sleep_for(milliseconds(250));
    try {
      open_all();
      ++status_.reconnects;
      return;
    } catch (const LinkError& e) {
      why = e.what();
    }
  }
  status_.state = LinkState::kDisconnected;
  throw LinkError(device_, fmt::format("reconnect failed after {} attempts: {}",
                                       options_.reconnect_attempts, why));
}

void UrLink::disconnect() {
  try {
    pause_stream();
  } catch (const LinkError&) {
    // Closing anyway: the controller drops the recipe with the connection.
  }
  close_all();
  status_.state = LinkState::kDisconnected;
}

void UrLink::poll_secondary() {
  try {
    while (std::optional<std::string> bytes = secondary_.read_some(Clock::now()))
      secondary_buffer_ += *bytes;
  } catch (const LinkError&) {
    return;  // gone: the next script send reconnects
  }
  try {
    while (std::optional<ur_primary::Package> p = ur_primary::take_package(secondary_buffer_)) {
      // Robot states (10 Hz) and messages that do not matter are read past.
      const std::optional<ur_primary::RobotMessage> m = ur_primary::decode_robot_message(*p);
      if (!m || !ur_primary::matters(*m)) continue;
      controller_said_ = ur_primary::describe(*m);
      status_.last_error = "the controller says: " + controller_said_;
    }
  } catch (const std::runtime_error& e) {
    // Out of step with the package framing: what is buffered cannot be read.
    secondary_buffer_.clear();
    status_.last_error = fmt::format("secondary interface: {}", e.what());
  }
}

std::string UrLink::controller_said() const {
  return controller_said_.empty() ? "" : "; the controller said: " + controller_said_;
}

void UrLink::send_script(const std::string& line) {
  try {
    poll_secondary();
    secondary_.write_line(line);
    ++status_.commands;
  } catch (const LinkError& e) {
    throw LinkError(device_, fmt::format("secondary interface: {}", e.what()));
  }
}

// Nothing is sent while RTDE reports a state the arm cannot move in; a protective stop is
// unlocked only when the operator allowed it.
void UrLink::require_motion_allowed() {
  if (state_.safety_status == kProtectiveStop && options_.unlock_protective_stop) {
    unlock_protective_stop();
    (void)fresh_state();
  }
  if (const std::string blocker = ur_motion_blocker(state_); !blocker.empty())
    fail("refusing to move: RTDE reports " + blocker);
}

bool UrLink::settled_at(const Eigen::VectorXd& target_si) const {
  if (state_.actual_q.size() != target_si.size()) return false;
  return (state_.actual_q - target_si).cwiseAbs().maxCoeff() <= options_.joint_tolerance &&
         state_.actual_qd.cwiseAbs().maxCoeff() < options_.speed_threshold;
}

void UrLink::stop_for(const std::string& why) {
  try {
    send_script(urscript_stopj(options_.stop_deceleration));
  } catch (const LinkError&) {
    // The secondary interface is gone: the dashboard's stop halts the program as well.
    try {
      (void)dashboard("stop");
    } catch (const LinkError&) {
      status_.last_error = why + ": neither stopj nor the dashboard's stop could be sent";
    }
  }
  status_.state = LinkState::kStopped;
}

void UrLink::do_move(const Eigen::VectorXd& target, const MoveSpeed& speed) {
  status_.state = LinkState::kMoving;
  settled_state_ = false;
  target_si_ = to_si(target);
  // What the controller says from here on is about this move.
  poll_secondary();
  controller_said_.clear();
  (void)fresh_state();
  require_motion_allowed();
  last_script_ = urscript_movej(target_si_, speed.acceleration, speed.speed);
  move_started_ = false;
  settled_run_ = 0;
  try {
    send_script(last_script_);
  } catch (const LinkError&) {
    // Lost on the way: watching the move (do_wait_settled) finds the robot still and sends the
    // movej again after reconnecting.
    ++status_.timeouts;
  }
}

// Watches data packages until the move settles (kSettled), the robot has not begun within the
// start window (kNotStarted), the stream is lost (kLost), or a protective stop the operator allowed
// robocal to unlock halted it (kProtectiveStop). Throws on a protective stop during
// the move, on a stall past `deadline` (after stopping the arm) and on a stop request.
UrLink::Wait UrLink::watch_move(Clock::time_point deadline, Clock::time_point start_deadline) {
  auto last_package = Clock::now();
  bool seen = false;  // whether the arm was looked at: only then can it be judged still
  try {
    start_stream();
  } catch (const LinkError&) {
    return Wait::kLost;
  }
  for (;;) {
    if (guard().stop_requested()) {
      stop_for("stop requested");
      interrupted("movej");
    }
    poll_secondary();
    bool got = false;
    try {
      got = next_state(std::min(deadline, Clock::now() + milliseconds(50)));
    } catch (const LinkError&) {
      return Wait::kLost;
    }
    const auto now = Clock::now();
    if (got) {
      last_package = now;
      seen = true;
      if (state_.safety_status == kProtectiveStop && options_.unlock_protective_stop)
        return Wait::kProtectiveStop;
      if (const std::string blocker = ur_motion_blocker(state_); !blocker.empty()) {
        status_.state = LinkState::kFault;
        poll_secondary();
        fail("the move ended early: RTDE reports " + blocker + controller_said());
      }
      if (state_.runtime_state == kPlaying ||
          state_.actual_qd.cwiseAbs().maxCoeff() >= options_.speed_threshold)
        move_started_ = true;
      settled_run_ = settled_at(target_si_) ? settled_run_ + 1 : 0;
      if (settled_run_ >= options_.settle_packages) return Wait::kSettled;
    } else if (now - last_package > options_.package_timeout) {
      ++status_.timeouts;
      return Wait::kLost;
    }
    if (seen && !move_started_ && settled_run_ == 0 && now >= start_deadline)
      return Wait::kNotStarted;
    if (now >= deadline) {
      stop_for("stalled");
      fail(
          fmt::format("the move did not settle in time (stalled?): sent stopj; the joints stopped "
                      "{:.4f} rad from the target{}",
                      (state_.actual_q - target_si_).cwiseAbs().maxCoeff(), controller_said()));
    }
  }
}

void UrLink::do_wait_settled(milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  int sends = 1;
  auto start_window = [this] { return Clock::now() + options_.reply_timeout; };
  for (auto start_deadline = start_window();;) {
    const Wait w = watch_move(deadline, start_deadline);
    if (w == Wait::kSettled) break;
    if (w == Wait::kLost) {
      // The robot may still be finishing the move, or the movej may never have arrived: watch
      // again after reconnecting, and send it again only if the arm stays still elsewhere.
      reconnect();
      move_started_ = false;
      settled_run_ = 0;
      start_deadline = start_window();
      continue;
    }
    if (w == Wait::kProtectiveStop) {
      // Allowed by the operator: unlock, then take the move up again from where the arm stopped.
      unlock_protective_stop();
      (void)fresh_state();
      require_motion_allowed();
      send_script(last_script_);
      move_started_ = false;
      settled_run_ = 0;
      start_deadline = start_window();
      continue;
    }
    if (sends >= options_.attempts) {
      const std::string remote = dashboard("is in remote control");
      poll_secondary();
      fail(fmt::format("the arm did not take the movej after {} sends (remote control: {}; "
                       "runtime state {}){}",
                       sends, remote, state_.runtime_state, controller_said()),
           remote);
    }
    ++sends;
    ++status_.resends;
    send_script(last_script_);
    start_deadline = start_window();
  }
  status_.state = LinkState::kIdle;
  settled_state_ = true;
}

// Right after a settle the last package is the reading: the arm has been at rest for
// settle_packages packages, so waiting for one more would only add a period.
ActuatorReadings UrLink::do_read() {
  ActuatorReadings r;
  const UrState& s = settled_state_ ? state_ : fresh_state();
  r.values = s.actual_q.cwiseQuotient(scale_);
  // The controller's own flange pose, from the same package as the joints.
  if (has_tcp_offset_ && s.tcp_pose.size() == 6 && s.tcp_offset.size() == 6)
    r.base_T_flange = ur_flange_pose(s.tcp_pose, s.tcp_offset);
  settled_state_ = false;
  pause_stream();
  return r;
}

void UrLink::do_stop(StopKind kind) {
  const bool emergency = kind == StopKind::kEmergency;
  // A UR's emergency stop is its red button; from here the strongest stop is a fast stopj and
  // powering the arm off (it must then be powered on and its brakes released: a reset).
  send_script(urscript_stopj(emergency ? 10.0 : options_.stop_deceleration));
  const std::string reply = dashboard(emergency ? "power off" : "stop");
  status_.state = emergency ? LinkState::kFault : LinkState::kStopped;
  if (reply.rfind("Failed", 0) == 0) fail("the dashboard's stop failed", reply);
}

bool UrLink::at_target(const ActuatorReadings& readings, const Eigen::VectorXd& target) const {
  if (readings.values.size() != target.size()) return false;
  return (to_si(readings.values) - to_si(target)).cwiseAbs().maxCoeff() <= options_.joint_tolerance;
}

// movej's time is its leading joint's: the others are scaled to arrive with it.
double UrLink::expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                                const MoveSpeed& speed) const {
  const double lead = (to_si(to) - to_si(from)).cwiseAbs().maxCoeff();
  expected_move_seconds_ = trapezoid_seconds(lead, speed.speed, speed.acceleration);
  return expected_move_seconds_;
}

}  // namespace robocal::robotio
