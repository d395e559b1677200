// The open link (robotio/OPEN_LINK.md) as a RobotLink: hello and its checks, moves confirmed by
// the controller's counts, recovery after a lost connection without repeating or losing a move,
// the stop sent when a move does not settle or a stop is requested.
#include "robocal/robotio/open_link.hpp"

#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/motion_profile.hpp"

#include <fmt/core.h>

#include <cmath>
#include <optional>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

namespace robocal::robotio {
namespace {

using nlohmann::json;
using std::chrono::milliseconds;

std::string device_name(const std::string& address) {
  return "open link " + (is_open_link_address(address) ? address.substr(5) : address);
}

// `count` finite numbers in `field` of `pose`; empty, with the problem named, when not.
std::vector<double> finite_numbers(const json& pose, const char* field, std::size_t count,
                                   std::string& problem) {
  const json& v = pose.contains(field) ? pose[field] : json();
  std::vector<double> out;
  if (v.is_array() && v.size() == count)
    for (const json& x : v)
      if (x.is_number() && std::isfinite(x.get<double>())) out.push_back(x.get<double>());
  if (out.size() != count) {
    problem = fmt::format("\"flange_pose\" needs \"{}\": {} finite numbers", field, count);
    out.clear();
  }
  return out;
}

}  // namespace

std::optional<Eigen::Isometry3d> parse_open_flange_pose(const json& reply, std::string& problem) {
  problem.clear();
  const json& pose = reply.contains("flange_pose") ? reply["flange_pose"] : json();
  if (!pose.is_object()) {
    problem = "the reply has no \"flange_pose\" object";
    return std::nullopt;
  }
  const std::vector<double> p = finite_numbers(pose, "position", 3, problem);
  if (!problem.empty()) return std::nullopt;
  const std::vector<double> q = finite_numbers(pose, "quaternion_xyzw", 4, problem);
  if (!problem.empty()) return std::nullopt;
  const Eigen::Quaterniond rotation(q[3], q[0], q[1], q[2]);
  // A unit quaternion written with 6+ digits is within 1e-5 of length 1; far from it, the
  // fields are not a rotation (another order, degrees, a scaled vector).
  if (std::abs(rotation.norm() - 1.0) > 1e-3) {
    problem = fmt::format(
        "\"flange_pose\" quaternion_xyzw [{}, {}, {}, {}] has length {:.6f}, not 1 (x y z w "
        "of a unit quaternion expected)",
        q[0], q[1], q[2], q[3], rotation.norm());
    return std::nullopt;
  }
  Eigen::Isometry3d base_T_flange = Eigen::Isometry3d::Identity();
  base_T_flange.linear() = rotation.normalized().toRotationMatrix();
  base_T_flange.translation() = Eigen::Vector3d(p[0], p[1], p[2]);
  return base_T_flange;
}

OpenLink::OpenLink(SafetyGuard& guard, const OpenLinkOptions& options)
    : OpenLink(guard, options, open_link_transport(options.address)) {}

OpenLink::OpenLink(SafetyGuard& guard, OpenLinkOptions options,
                   std::unique_ptr<Transport> transport)
    : RobotLink(guard),
      options_(std::move(options)),
      client_(std::move(transport), device_name(options_.address)),
      scale_(nominal_encoder_scales(guard)) {
  status_.device = client_.device();
}

LinkStatus OpenLink::status() const {
  LinkStatus s = status_;
  s.garbage = client_.garbage();
  s.resends = client_.repeats();
  s.unsolicited = client_.notifications();
  return s;
}

void OpenLink::fail(const std::string& problem) {
  status_.state = LinkState::kFault;
  status_.last_error = problem;
  throw LinkError(client_.device(), problem, client_.last_line());
}

FirmwareInfo OpenLink::connect() {
  for (int round = 0;; ++round) {
    try {
      if (round > 0) std::this_thread::sleep_for(milliseconds(250));
      client_.open();
      handshake();
      status_.state = LinkState::kIdle;
      set_last_known(do_read().values);
      return status_.firmware;
    } catch (const LinkError&) {
      // A connection lost while identifying is retried; anything the controller said is final.
      if (client_.is_open() || round >= options_.reconnect_attempts) throw;
    }
  }
}

void OpenLink::handshake() {
  const milliseconds total = options_.reply_timeout * (options_.attempts + 1);
  const json reply = client_.request({{"cmd", "hello"},
                                      {"protocol", kOpenLinkProtocol},
                                      {"version", {kOpenLinkMajor, kOpenLinkMinor}},
                                      {"client", "robocal"}},
                                     options_.reply_timeout, total, options_.attempts);
  const OpenLinkFailure failure = open_reply_failure(reply);
  if (failure.code == 103)
    fail(fmt::format("the controller refuses {} {}.{}: {}", kOpenLinkProtocol, kOpenLinkMajor,
                     kOpenLinkMinor, failure.message));
  if (failure.code != 0)
    fail(fmt::format("hello refused with error {}: {}", failure.code, failure.message));
  OpenLinkHello h;
  try {
    h = parse_open_hello(reply);
  } catch (const std::invalid_argument& e) {
    fail(fmt::format("the hello reply is not an open link hello: {}", e.what()));
  }
  if (h.protocol != kOpenLinkProtocol)
    fail(fmt::format("the controller speaks '{}', not {}", h.protocol, kOpenLinkProtocol));
  if (h.major != kOpenLinkMajor)
    fail(
        fmt::format("the controller '{}' speaks {} {}.{}, {} than this robocal's {}.{}: update "
                    "{}",
                    h.controller, kOpenLinkProtocol, h.major, h.minor,
                    h.major < kOpenLinkMajor ? "older" : "newer", kOpenLinkMajor, kOpenLinkMinor,
                    h.major < kOpenLinkMajor ? "the controller's adapter" : "robocal"));
  if (const std::string m = open_hello_mismatch(h, guard().model()); !m.empty())
    fail(fmt::format("controller '{}': {}", h.controller, m));
  hello_ = h;
  status_.firmware = {Firmware::kUnknown, h.controller, fmt::format("{}.{}", h.major, h.minor),
                      client_.last_line()};
}

void OpenLink::reconnect() {
  std::string why;
  for (int attempt = 0; attempt < options_.reconnect_attempts; ++attempt) {
    if (attempt > 0) std::this_thread::sleep_for(milliseconds(250));
    try {
      client_.open();
      handshake();
      ++status_.reconnects;
      status_.state = LinkState::kIdle;
      return;
    } catch (const LinkError& e) {
      why = e.what();
      client_.close();
    }
  }
  status_.state = LinkState::kDisconnected;
  throw LinkError(client_.device(), fmt::format("reconnect failed after {} attempts: {}",
                                                options_.reconnect_attempts, why));
}

void OpenLink::disconnect() {
  client_.close();
  status_.state = LinkState::kDisconnected;
}

json OpenLink::call(const json& request, milliseconds silence, milliseconds total,
                    bool interruptible, Clock::time_point quiet_until) {
  const std::string cmd = request.value("cmd", "?");
  auto tick = [this, &cmd] {
    if (!guard().stop_requested()) return;
    send_stop_during_wait();
    interrupted("'" + cmd + "'");
  };
  for (int attempt = 1;; ++attempt) {
    ++status_.commands;
    json reply =
        client_.request(request, silence, total, options_.attempts,
                        interruptible ? std::function<void()>(tick) : nullptr, quiet_until);
    const OpenLinkFailure failure = open_reply_failure(reply);
    if (failure.code == 0) return reply;
    ++status_.errors;
    status_.last_error = fmt::format("error {}: {}", failure.code, failure.message);
    if (failure.code == 200 && attempt < options_.attempts) continue;  // refused for now
    if (failure.code == 202) status_.state = LinkState::kFault;
    throw LinkError(client_.device(),
                    fmt::format("'{}' refused{}: error {}: {}", cmd,
                                failure.code == 200 ? fmt::format(" {} times", options_.attempts)
                                                    : std::string(),
                                failure.code, failure.message),
                    client_.last_line());
  }
}

void OpenLink::send_stop_during_wait() {
  try {
    do_stop(StopKind::kControlled);
  } catch (const LinkError&) {
    // The stop was written; its acknowledgement is not needed to stop the robot.
  }
}

void OpenLink::do_stop(StopKind kind) {
  const bool emergency = kind == StopKind::kEmergency;
  client_.request({{"cmd", "stop"}, {"kind", emergency ? "emergency" : "controlled"}},
                  options_.reply_timeout, options_.reply_timeout * (options_.attempts + 1),
                  options_.attempts);
  status_.state = emergency ? LinkState::kFault : LinkState::kStopped;
}

Eigen::VectorXd OpenLink::to_si(const Eigen::VectorXd& readings) const {
  return readings.cwiseProduct(scale_);
}

void OpenLink::require_hello() const {
  if (hello_.actuators.empty())
    throw LinkError(client_.device(), "not connected: the controller has not answered hello");
}

std::vector<long> OpenLink::counts_for(const Eigen::VectorXd& readings) const {
  require_hello();
  const Eigen::VectorXd si = to_si(readings);
  std::vector<long> c(static_cast<std::size_t>(si.size()));
  for (Eigen::Index i = 0; i < si.size(); ++i)
    c[static_cast<std::size_t>(i)] =
        std::lround(si[i] / hello_.actuators[static_cast<std::size_t>(i)].resolution);
  return c;
}

void OpenLink::do_move(const Eigen::VectorXd& target, const MoveSpeed& speed) {
  status_.state = LinkState::kMoving;
  // The target rounded to the controller's resolution: its counts then equal ours exactly.
  const std::vector<long> counts = counts_for(target);
  std::vector<double> si(counts.size());
  for (std::size_t i = 0; i < counts.size(); ++i)
    si[i] = static_cast<double>(counts[i]) * hello_.actuators[i].resolution;
  const json request = {{"cmd", "move"},
                        {"target", si},
                        {"speed", speed.speed},
                        {"acceleration", speed.acceleration}};
  const milliseconds total = options_.reply_timeout * (options_.attempts + 1);
  for (int round = 0;; ++round) {
    try {
      if (round > 0) {
        // Connection lost mid-request: the move may or may not have reached the controller.
        // Look before sending it again, so it is neither lost nor executed twice.
        reconnect();
        wait_until_settled(milliseconds(120000), Clock::now());
        if (at_target(do_read(), target)) return;
      }
      call(request, options_.reply_timeout, total, true);
      return;
    } catch (const MotionInterrupted&) {
      throw;
    } catch (const LinkError&) {
      // A refusal by a connected controller is final; a lost connection is recovered.
      if (client_.is_open() || round >= options_.reconnect_attempts) throw;
    }
  }
}

// Silence allowed while a move runs: the keep-alive interval when the controller sends one,
// otherwise the whole wait (a controller without keep-alives says nothing until it settles).
milliseconds OpenLink::wait_silence(milliseconds total) const {
  if (hello_.keepalive_s <= 0.0) return total;
  return options_.reply_timeout + milliseconds(static_cast<long>(1000.0 * hello_.keepalive_s));
}

void OpenLink::wait_until_settled(milliseconds total, Clock::time_point motion_end) {
  call({{"cmd", "wait_settled"}, {"timeout", static_cast<double>(total.count()) / 1000.0}},
       wait_silence(total), total, true, motion_end);
}

void OpenLink::do_wait_settled(milliseconds timeout) {
  const auto motion_end =
      Clock::now() + milliseconds(static_cast<long>(1000.0 * expected_move_seconds_));
  const milliseconds total = timeout + wait_silence(timeout);
  for (int round = 0;; ++round) {
    try {
      if (round > 0) reconnect();
      wait_until_settled(total, motion_end);
      break;
    } catch (const MotionInterrupted&) {
      throw;
    } catch (const OpenLinkTimeout&) {
      if (!client_.is_open()) throw;
      // Stalled: stop the robot rather than leave a move running that nobody waits for.
      send_stop_during_wait();
      status_.state = LinkState::kStopped;
      throw LinkError(client_.device(),
                      fmt::format("move did not settle within {:.1f} s (stalled?): sent the "
                                  "controller's stop",
                                  static_cast<double>(total.count()) / 1000.0),
                      client_.last_line());
    } catch (const LinkError&) {
      if (!client_.is_open() && round < options_.reconnect_attempts) continue;
      throw;
    }
  }
  status_.state = LinkState::kIdle;
}

ActuatorReadings OpenLink::readings_from(const json& reply) const {
  const auto n = static_cast<std::size_t>(actuator_count());
  const json& p = reply.contains("position") ? reply["position"] : json();
  if (!p.is_array() || p.size() != n)
    throw LinkError(client_.device(),
                    fmt::format("the read reply has no \"position\" of {} numbers", n),
                    client_.last_line());
  ActuatorReadings r;
  r.values.resize(static_cast<Eigen::Index>(n));
  for (std::size_t i = 0; i < n; ++i) {
    if (!p[i].is_number())
      throw LinkError(client_.device(), fmt::format("position {} is not a number", i + 1),
                      client_.last_line());
    r.values[static_cast<Eigen::Index>(i)] =
        p[i].get<double>() / scale_[static_cast<Eigen::Index>(i)];
  }
  if (hello_.has("counts")) {
    const json& c = reply.contains("counts") ? reply["counts"] : json();
    if (!c.is_array() || c.size() != n)
      throw LinkError(client_.device(),
                      fmt::format("the controller has the counts capability but its read reply "
                                  "has no \"counts\" of {} integers",
                                  n),
                      client_.last_line());
    for (const json& v : c) {
      if (!v.is_number_integer())
        throw LinkError(client_.device(), "a count is not an integer", client_.last_line());
      r.counts.push_back(v.get<long>());
    }
  }
  if (hello_.has("flange_pose")) {
    std::string problem;
    r.base_T_flange = parse_open_flange_pose(reply, problem);
    if (!r.base_T_flange)
      throw LinkError(client_.device(),
                      "the controller has the flange_pose capability but its read reply is "
                      "wrong: " +
                          problem,
                      client_.last_line());
  }
  return r;
}

ActuatorReadings OpenLink::do_read() {
  require_hello();
  const milliseconds total = options_.reply_timeout * (options_.attempts + 1);
  for (int round = 0;; ++round) {
    try {
      return readings_from(call({{"cmd", "read"}}, options_.reply_timeout, total, false));
    } catch (const LinkError&) {
      if (client_.is_open() || round >= options_.reconnect_attempts) throw;
      reconnect();
    }
  }
}

void OpenLink::do_home() {
  require_hello();
  // A controller without a home command keeps its own reference: nothing to do.
  if (!hello_.has("home")) return;
  status_.state = LinkState::kMoving;
  call({{"cmd", "home"}}, wait_silence(milliseconds(120000)), milliseconds(120000), true);
  status_.state = LinkState::kIdle;
}

bool OpenLink::at_target(const ActuatorReadings& readings, const Eigen::VectorXd& target) const {
  if (readings.values.size() != target.size() || hello_.actuators.empty()) return false;
  if (!readings.counts.empty()) return readings.counts == counts_for(target);
  const Eigen::VectorXd got = to_si(readings.values), want = to_si(target);
  for (Eigen::Index i = 0; i < want.size(); ++i)
    if (std::abs(got[i] - want[i]) >
        0.5 * hello_.actuators[static_cast<std::size_t>(i)].resolution + 1e-12)
      return false;
  return true;
}

double OpenLink::expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                                  const MoveSpeed& speed) const {
  const double length = (to - from).cwiseProduct(guard().joint_per_reading()).norm();
  const double s = trapezoid_seconds(length, speed.speed, speed.acceleration);
  expected_move_seconds_ = s;
  return s;
}

}  // namespace robocal::robotio
