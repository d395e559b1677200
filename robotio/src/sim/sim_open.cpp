// The simulated controller's open link protocol (robotio/OPEN_LINK.md): JSON lines over TCP,
// request ids with the last reply repeated for a repeated id, stops acted on receipt, blocking
// wait_settled/home with busy keep-alives, settled notifications, and the faults this protocol
// has (drop, busy, error, stall, lost_ok, slow, garbage).
#include "sim_internal.hpp"

#include "robocal/core/random_draws.hpp"

#include <fmt/core.h>

#include <unistd.h>
#include <cerrno>
#include <cmath>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace robocal::robotio {
namespace {

using nlohmann::json;

constexpr const char* kProtocol = "robocal-open-link";

bool is_prismatic(const SimRobot& r, int i) {
  return r.model.bodies[r.model.actuated[static_cast<std::size_t>(i)]].joint ==
         calib::JointType::kPrismatic;
}

// SI joint units (m, rad) per G-code unit (mm, degree) of an axis.
double si_per_unit(const SimRobot& r, int i) {
  return is_prismatic(r, i) ? 1e-3 : std::numbers::pi / 180.0;
}

json error_reply(int code, const std::string& message) {
  return {{"ok", false}, {"error", {{"code", code}, {"message", message}}}};
}

std::string command_of(const json& request) {
  if (!request.is_object() || !request.contains("cmd") || !request["cmd"].is_string()) return "";
  return request["cmd"].get<std::string>();
}

bool well_formed(const json& request) {
  return request.is_object() && request.contains("id") && request["id"].is_number_integer() &&
         !command_of(request).empty();
}

double positive_number(const json& request, const char* field) {
  if (!request.contains(field) || !request[field].is_number()) return -1.0;
  return request[field].get<double>();
}

}  // namespace

json SimController::Impl::open_position() const {
  std::vector<double> position(counts.size());
  for (int i = 0; i < robot.axes.size(); ++i)
    position[static_cast<std::size_t>(i)] =
        units_of(counts[static_cast<std::size_t>(i)], i) * si_per_unit(robot, i);
  return {{"position", position}, {"counts", counts}};
}

json SimController::Impl::open_flange_pose() {
  const std::optional<Eigen::Isometry3d> pose =
      true_flange_pose(robot, true_readings(now_seconds()));
  if (!pose) return nullptr;
  std::normal_distribution<double> unit(0.0, 1.0);
  const Eigen::Vector3d dp = core::draw_vector3(unit, flange_rng);
  const Eigen::Vector3d dphi = core::draw_vector3(unit, flange_rng);
  const Eigen::Vector3d p = pose->translation() + options.flange_noise_m * dp;
  // The rotation noise is a world-frame rotation vector, as the pose covariances are taken.
  const Eigen::Quaterniond q(Eigen::AngleAxisd(options.flange_noise_rad * dphi.norm(),
                                               dphi.norm() > 0.0
                                                   ? Eigen::Vector3d(dphi.normalized())
                                                   : Eigen::Vector3d::UnitZ()) *
                             pose->linear());
  return {{"position", {p.x(), p.y(), p.z()}}, {"quaternion_xyzw", {q.x(), q.y(), q.z(), q.w()}}};
}

void SimController::Impl::open_reply(Channel& c, const json& id, json reply, bool lost) {
  reply["id"] = id;
  c.last_id = id;
  c.last_reply = reply.dump();
  if (lost) {
    write_log({{"ev", "ok_dropped"}, {"ch", c.name}});
    return;
  }
  send(c, c.last_reply);
}

void SimController::Impl::open_stop(Channel& c, const std::string& kind) {
  const bool emergency = kind == "emergency";
  quick_stop(emergency ? "stop emergency" : "stop controlled");
  halted = halted || emergency;
  stopped_by_request = !emergency;
  if (c.blocked) {
    c.blocked = false;
    open_reply(c, c.wait_id,
               error_reply(204, fmt::format("{} stopped by a {} stop", c.wait_cmd, kind)), false);
  }
}

void SimController::Impl::open_receive(Channel& c) {
  if (!read_input(c)) return;
  std::size_t eol;
  while (c.open() && (eol = c.inbuf.find('\n')) != std::string::npos) {
    std::string line = c.inbuf.substr(0, eol);
    c.inbuf.erase(0, eol + 1);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    ++counters.lines;
    write_log({{"ev", "rx"}, {"ch", c.name}, {"line", line}});
    if (options.mute) continue;
    const json request = json::parse(line, nullptr, false);
    if (command_of(request) == "stop") {
      const std::string kind =
          request.contains("kind") && request["kind"].is_string() ? request["kind"] : "controlled";
      open_stop(c, kind);
    }
    c.pending.push_back({line, false, std::nullopt});
  }
}

void SimController::Impl::open_process(Channel& c, double now) {
  if (!c.open()) return;
  if (c.blocked) {
    if (queue.empty()) {
      c.blocked = false;
      json reply = {{"ok", true}, {"motion", motion_ids}};
      reply.update(open_position());
      open_reply(c, c.wait_id, reply, c.blocked_lost_ok);
    } else if (now >= c.next_busy) {
      send(c, R"({"event":"busy"})");
      c.next_busy = now + busy_interval;
    }
  }
  while (c.open() && !c.blocked && !c.pending.empty() && now >= c.hold_until) {
    Pending& item = c.pending.front();
    if (!item.rolled) {
      item.rolled = true;
      const json request = json::parse(item.text, nullptr, false);
      if (well_formed(request) && !halted) item.fault = open_roll_fault(command_of(request));
      if (item.fault == FaultKind::kSlow) {
        c.hold_until = now + options.faults.slow_seconds;
        continue;
      }
    }
    Pending taken = std::move(item);
    c.pending.pop_front();
    open_handle(c, taken);
  }
  if (c.open() && queue.empty() && c.notified_motion < motion_ids) {
    c.notified_motion = motion_ids;
    json event = {{"event", "settled"}, {"motion", motion_ids}};
    event.update(open_position());
    send(c, event.dump());
  }
}

void SimController::Impl::open_handle(Channel& c, Pending& item) {
  const json request = json::parse(item.text, nullptr, false);
  const std::optional<FaultKind> fault = item.fault;
  if (!well_formed(request)) {
    json reply = error_reply(
        100, "malformed request: expected one JSON object with an integer \"id\" and a \"cmd\"");
    reply["id"] = request.is_object() && request.contains("id") ? request["id"] : json(nullptr);
    send(c, reply.dump());
    return;
  }
  const json& id = request["id"];
  const std::string cmd = command_of(request);
  if (fault) {
    ++counters.faults[static_cast<std::size_t>(*fault)];
    write_log(
        {{"ev", "fault"}, {"kind", to_string(*fault)}, {"ch", c.name}, {"line", id}, {"cmd", cmd}});
  }
  if (fault == FaultKind::kGarbage) send(c, "\x02\x7f\x1b[0;~\x7f\x01");
  if (fault == FaultKind::kBusy)
    for (int i = 0; i < options.faults.busy_lines; ++i) send(c, R"({"event":"busy"})");
  if (!c.last_id.is_null() && id == c.last_id) {
    // The client did not get the reply: the same reply again, nothing executed twice.
    void_fault(c, fault);
    send(c, c.last_reply);
    return;
  }
  if (halted && cmd != "reset" && cmd != "state" && cmd != "hello" && cmd != "stop") {
    open_reply(c, id, error_reply(202, "halted by an emergency stop: send reset"), false);
    return;
  }
  if (fault == FaultKind::kDrop) {
    // Half the drops lose the request on the wire, half happen after the controller took it.
    std::uniform_int_distribution<int> coin(0, 1);
    const bool executed = coin(fault_rng) == 1;
    if (executed) (void)open_execute(c, request, std::nullopt);
    write_log({{"ev", "drop"}, {"ch", c.name}, {"executed", executed}});
    close_channel(c, false);
    return;
  }
  if (fault == FaultKind::kError) {
    open_reply(c, id,
               error_reply(200, fmt::format("'{}' refused for now (injected fault), request {}",
                                            cmd, id.dump())),
               false);
    return;
  }
  const std::optional<json> reply = open_execute(c, request, fault);
  if (reply) {
    open_reply(c, id, *reply, fault == FaultKind::kLostOk);
  } else {
    c.wait_id = id;
    c.wait_cmd = cmd;
    c.blocked_lost_ok = fault == FaultKind::kLostOk;
  }
}

std::optional<json> SimController::Impl::open_execute(Channel& c, const json& request,
                                                      std::optional<FaultKind> fault) {
  const std::string cmd = command_of(request);
  const int n = robot.axes.size();
  if (cmd == "hello") {
    if (!request.contains("protocol") || request["protocol"] != kProtocol)
      return error_reply(102, fmt::format("\"protocol\" must be \"{}\"", kProtocol));
    const json& v = request.contains("version") ? request["version"] : json();
    if (!v.is_array() || v.size() != 2 || !v[0].is_number_integer() || !v[1].is_number_integer())
      return error_reply(102, "\"version\" must be [major, minor]");
    if (v[0].get<int>() != options.open_major)
      return error_reply(103, fmt::format("this controller speaks {} {}.{}; the client asked for "
                                          "{}.{}",
                                          kProtocol, options.open_major, options.open_minor,
                                          v[0].get<int>(), v[1].get<int>()));
    json actuators = json::array();
    for (int i = 0; i < n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      actuators.push_back({{"name", robot.model.bodies[robot.model.actuated[k]].name},
                           {"unit", is_prismatic(robot, i) ? "m" : "rad"},
                           {"resolution", si_per_unit(robot, i) / robot.axes.steps_per_unit[k]}});
    }
    json capabilities = {"counts", "home", "emergency_stop", "settled_event"};
    if (options.flange_pose) capabilities.push_back("flange_pose");
    return json{{"ok", true},
                {"protocol", kProtocol},
                {"version", {options.open_major, options.open_minor}},
                {"controller", options.firmware_name.empty()
                                   ? "robocal simulated controller (" + robot.model.name + ")"
                                   : options.firmware_name},
                {"capabilities", capabilities},
                {"actuators", actuators},
                {"keepalive_s", busy_interval}};
  }
  if (cmd == "read") {
    json reply = {{"ok", true}, {"moving", !queue.empty()}};
    reply.update(open_position());
    if (options.flange_pose) {
      json flange = open_flange_pose();
      if (flange.is_null())
        return error_reply(203, "the robot's kinematics cannot place the flange here");
      reply["flange_pose"] = std::move(flange);
    }
    return reply;
  }
  if (cmd == "state") {
    const char* state = halted               ? "halted"
                        : !queue.empty()     ? "moving"
                        : stopped_by_request ? "stopped"
                                             : "idle";
    return json{{"ok", true}, {"state", state}, {"motion", motion_ids}};
  }
  if (cmd == "stop") return json{{"ok", true}, {"state", halted ? "halted" : "stopped"}};
  if (cmd == "reset") {
    if (halted) write_log({{"ev", "reset"}});
    halted = false;
    return json{{"ok", true}, {"state", "idle"}};
  }
  if (cmd == "move") {
    const json& target = request.contains("target") ? request["target"] : json();
    if (!target.is_array() || static_cast<int>(target.size()) != n)
      return error_reply(102, fmt::format("\"target\" needs {} numbers (one per actuator), got {}",
                                          n, target.dump()));
    const double speed = positive_number(request, "speed");
    const double accel = positive_number(request, "acceleration");
    if (!(speed > 0.0) || !(accel > 0.0))
      return error_reply(102, "\"speed\" and \"acceleration\" must be positive numbers");
    Motion m;
    m.line = request["id"].get<long>();
    m.channel = c.name;
    const std::vector<long> from = queue.empty() ? counts : queue.back().to;
    m.to = from;
    double gcode2 = 0.0, si2 = 0.0;
    for (int i = 0; i < n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      if (!target[k].is_number())
        return error_reply(102, fmt::format("target {} is not a number", i + 1));
      m.to[k] = std::lround(target[k].get<double>() / si_per_unit(robot, i) *
                            robot.axes.steps_per_unit[k]);
      const double d = units_of(m.to[k] - from[k], i);
      gcode2 += d * d;
      si2 += d * si_per_unit(robot, i) * d * si_per_unit(robot, i);
    }
    // Speed and acceleration are along the SI joint path; the motion runs in axis units.
    const double ratio = si2 > 0.0 ? std::sqrt(gcode2 / si2) : 1.0 / si_per_unit(robot, 0);
    m.feed = speed * ratio;
    m.acceleration = accel * ratio;
    m.stall = fault == FaultKind::kStall;
    m.id = ++motion_ids;
    queue.push_back(m);
    stopped_by_request = false;
    advance_motion(now_seconds());
    return json{{"ok", true}, {"motion", m.id}};
  }
  if (cmd == "wait_settled" || cmd == "home") {
    if (cmd == "home") {
      Motion m;
      m.id = ++motion_ids;
      m.line = request["id"].get<long>();
      m.channel = c.name;
      m.to = counts_of(robot.home_readings);
      m.feed = feed;
      m.acceleration = acceleration;
      m.homing = true;
      queue.push_back(m);
      stopped_by_request = false;
      advance_motion(now_seconds());
    }
    if (queue.empty()) {
      json reply = {{"ok", true}, {"motion", motion_ids}};
      reply.update(open_position());
      return reply;
    }
    c.blocked = true;
    c.next_busy = now_seconds() + busy_interval;
    return std::nullopt;
  }
  return error_reply(101, fmt::format("unknown command '{}'", cmd));
}

}  // namespace robocal::robotio
