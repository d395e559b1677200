// The simulated controller as a Universal Robots controller: RTDE on the TCP port (protocol
// versions 1 and 2, output recipes with NOT_FOUND for unknown names, start/pause, data packages
// at the recipe's frequency), URScript on the secondary client port (movej with a joint list,
// a= and v=; stopj), and the dashboard server with its documented replies. The faults a UR link
// meets: a dropped connection, a refused script, a stalled move, late or missing RTDE packages,
// a protective stop.
#include "robocal/calib/closure.hpp"
#include "robocal/robotio/motion_profile.hpp"
#include "robocal/robotio/rtde.hpp"
#include "robocal/robotio/ur_link.hpp"
#include "robocal/robotio/ur_primary.hpp"
#include "sim_internal.hpp"

#include <unistd.h>

#include <fmt/core.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>
#include <numbers>
#include <string>
#include <vector>

namespace robocal::robotio {
namespace {

using rtde::PackageType;

constexpr int kUrJoints = 6;
constexpr int kRunning = 7, kPowerOff = 3, kIdle = 5;
constexpr int kNormal = 1, kProtectiveStop = 3;

// SI joint units (m, rad) per G-code unit (mm, degree) of an axis.
double joint_si(const SimRobot& r, int i) {
  return r.model.bodies[r.model.actuated[static_cast<std::size_t>(i)]].joint ==
                 calib::JointType::kPrismatic
             ? 1e-3
             : std::numbers::pi / 180.0;
}

// The outputs this controller serves and their RTDE types (RTDE guide, "Robot controller
// outputs"); any other name is NOT_FOUND.
const std::map<std::string, std::string>& output_types() {
  static const std::map<std::string, std::string> types = {
      {"timestamp", "DOUBLE"},     {"target_q", "VECTOR6D"},    {"target_qd", "VECTOR6D"},
      {"actual_q", "VECTOR6D"},    {"actual_qd", "VECTOR6D"},   {"actual_TCP_pose", "VECTOR6D"},
      {"robot_mode", "INT32"},     {"safety_mode", "INT32"},    {"safety_status", "INT32"},
      {"runtime_state", "UINT32"}, {"speed_scaling", "DOUBLE"}, {"target_speed_fraction", "DOUBLE"},
      {"tcp_offset", "VECTOR6D"}};
  return types;
}

std::string safety_name(int status) {
  return status == kProtectiveStop ? "PROTECTIVE_STOP" : "NORMAL";
}

std::string robot_mode_name(int mode) {
  switch (mode) {
    case kRunning:
      return "RUNNING";
    case kPowerOff:
      return "POWER_OFF";
    case kIdle:
      return "IDLE";
    default:
      return fmt::format("{}", mode);
  }
}

// "a=1.4" style keyword value in a URScript argument list; `fallback` when absent.
double keyword(const std::string& args, const std::string& key, double fallback) {
  std::size_t at = 0;
  while ((at = args.find(key + "=", at)) != std::string::npos) {
    const bool word_start = at == 0 || args[at - 1] == ',' || args[at - 1] == ' ';
    if (word_start) return std::strtod(args.c_str() + at + key.size() + 1, nullptr);
    ++at;
  }
  return fallback;
}

// The numbers of "[a,b,...]" at the start of `args`; empty when it is no list of numbers.
std::vector<double> number_list(const std::string& args) {
  std::vector<double> out;
  const std::size_t open = args.find('['), close = args.find(']');
  if (open != 0 || close == std::string::npos) return out;
  const char* p = args.c_str() + 1;
  const char* end = args.c_str() + close;
  while (p < end) {
    char* next = nullptr;
    out.push_back(std::strtod(p, &next));
    if (next == p) return {};
    p = next;
    while (p < end && (*p == ',' || *p == ' ')) ++p;
  }
  return out;
}

std::string trimmed(const std::string& s) {
  const std::size_t b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  return s.substr(b, s.find_last_not_of(" \t\r") - b + 1);
}

}  // namespace

void SimController::Impl::ur_start() {
  tcp.name = "rtde";
  ur.remote = options.ur.remote_control;
  ur.speed_fraction = options.ur.speed_fraction;
  if (options.ur.protective_stop) {
    ur.safety = kProtectiveStop;
    ur.pstop_at = t();
  }
  ur.secondary_listen = listen_loopback(options.ur.secondary_port, &ur.secondary_port);
  ur.dashboard_listen = listen_loopback(options.ur.dashboard_port, &ur.dashboard_port);
}

void SimController::Impl::ur_close() {
  close_channel(ur.secondary, false);
  close_channel(ur.dashboard, false);
  for (int fd : {ur.secondary_listen, ur.dashboard_listen})
    if (fd >= 0) ::close(fd);
  ur.secondary_listen = ur.dashboard_listen = -1;
}

void SimController::Impl::ur_on_connect(Channel& c) {
  ++counters.connections;
  write_log({{"ev", "connect"}, {"ch", c.name}});
  if (&c == &ur.dashboard) send(c, "Connected: Universal Robots Dashboard Server");
  if (&c == &tcp) {
    // A new RTDE client starts a new session: version 1 until it asks for 2, no recipe.
    ur.protocol = 1;
    ur.names.clear();
    ur.types.clear();
    ur.recipe_id = 0;
    ur.streaming = false;
    ur.late_packages.clear();
  }
}

void SimController::Impl::ur_receive(Channel& c) {
  if (!read_input(c)) return;
  if (&c == &tcp) {
    try {
      while (c.open()) {
        const std::optional<rtde::Package> p = rtde::take_package(c.inbuf);
        if (!p) break;
        ++counters.lines;
        write_log({{"ev", "rx"},
                   {"ch", c.name},
                   {"type", std::string(1, static_cast<char>(p->type))},
                   {"size", p->payload.size() + rtde::kHeaderBytes}});
        ur_rtde_package(c, p->type, p->payload);
      }
    } catch (const rtde::RtdeFormatError& e) {
      write_log({{"ev", "rtde_error"}, {"what", e.what()}});
      close_channel(c, false);
    }
    return;
  }
  std::size_t eol;
  while (c.open() && (eol = c.inbuf.find('\n')) != std::string::npos) {
    const std::string line = trimmed(c.inbuf.substr(0, eol));
    c.inbuf.erase(0, eol + 1);
    if (line.empty()) continue;
    ++counters.lines;
    write_log({{"ev", "rx"}, {"ch", c.name}, {"line", line}});
    if (options.mute) continue;
    if (&c == &ur.secondary) {
      ur_script(c, line);
    } else {
      const std::string reply = ur_dashboard_reply(c, line);
      send(c, reply);
      if (line == "quit") close_channel(c, false);
    }
  }
}

void SimController::Impl::ur_rtde_package(Channel& c, std::uint8_t type,
                                          const std::string& payload) {
  if (options.mute) return;
  const rtde::Package p{type, payload};
  std::string reply;
  switch (static_cast<PackageType>(type)) {
    case PackageType::kRequestProtocolVersion: {
      std::size_t offset = 0;
      const int version = rtde::get_u16(payload, offset, "protocol version");
      const bool accepted = version == 1 || version == 2;
      if (accepted) ur.protocol = version;
      reply = rtde::encode_accepted(PackageType::kRequestProtocolVersion, accepted);
      break;
    }
    case PackageType::kGetUrControlVersion:
      reply = rtde::encode_controller_version({5, 11, 0, 108});
      break;
    case PackageType::kSetupOutputs: {
      rtde::OutputSetupRequest r;
      if (ur.protocol >= 2) {
        r = rtde::decode_setup_outputs(p);
      } else {  // version 1 has no frequency: the names alone, served at 125 Hz
        r = rtde::decode_setup_outputs({type, std::string(8, '\0') + payload});
        r.frequency = 125.0;
      }
      ur.names = r.names;
      ur.types.clear();
      bool all_known = r.frequency >= 1.0 && r.frequency <= options.ur.max_frequency;
      const auto& predated = options.ur.unknown_outputs;
      for (const std::string& n : r.names) {
        auto found = output_types().find(n);
        if (std::find(predated.begin(), predated.end(), n) != predated.end())
          found = output_types().end();
        ur.types.push_back(found == output_types().end() ? "NOT_FOUND" : found->second);
        all_known = all_known && found != output_types().end();
      }
      if (r.frequency < 1.0 || r.frequency > options.ur.max_frequency)
        write_all(c.fd,
                  rtde::encode_text_message({fmt::format("output frequency {} outside 1..{} Hz",
                                                         r.frequency, options.ur.max_frequency),
                                             "RTDE", 1}));
      ur.recipe_id = all_known ? 1 : 0;
      ur.period = 1.0 / std::max(1.0, r.frequency);
      reply = rtde::encode_output_recipe(ur.recipe_id, ur.types);
      break;
    }
    case PackageType::kSetupInputs: {
      // This controller offers no inputs: every name is NOT_FOUND.
      const std::size_t n =
          static_cast<std::size_t>(std::count(payload.begin(), payload.end(), ',')) + 1;
      std::string body(1, '\0');
      for (std::size_t i = 0; i < n; ++i) body += (i ? ",NOT_FOUND" : "NOT_FOUND");
      reply = rtde::encode_package(PackageType::kSetupInputs, body);
      break;
    }
    case PackageType::kStart:
      ur.streaming = ur.recipe_id != 0;
      ur.next_package = now_seconds();
      reply = rtde::encode_accepted(PackageType::kStart, ur.streaming);
      break;
    case PackageType::kPause:
      ur.streaming = false;
      reply = rtde::encode_accepted(PackageType::kPause, true);
      break;
    case PackageType::kDataPackage:
      return;  // inputs: none are set up
    default:
      reply = rtde::encode_text_message(
          {fmt::format("unknown package type {}", static_cast<int>(type)), "RTDE", 1});
  }
  write_log({{"ev", "tx"},
             {"ch", c.name},
             {"type", std::string(1, reply.size() > 2 ? reply[2] : '?')},
             {"size", reply.size()}});
  write_all(c.fd, reply);
}

std::string SimController::Impl::ur_data_package(double now) const {
  const int n = robot.axes.size();
  const bool moving = !queue.empty() && queue.front().start >= 0.0;
  const std::vector<long> at = moving ? interpolate(queue.front(), now) : counts;
  std::vector<long> before = at;
  constexpr double kDt = 0.008;
  if (moving) before = interpolate(queue.front(), std::max(queue.front().start, now - kDt));
  rtde::FieldValues q(kUrJoints, 0.0), qd(kUrJoints, 0.0);
  for (int i = 0; i < n && i < kUrJoints; ++i) {
    const auto k = static_cast<std::size_t>(i);
    q[k] = units_of(at[k], i) * joint_si(robot, i);
    qd[k] = units_of(at[k] - before[k], i) * joint_si(robot, i) / kDt;
  }
  // The controller's kinematics are the true robot's (a calibrated arm) applied to its joint
  // encoders (it cannot see backlash or noise beyond them): actual_TCP_pose is that flange pose
  // times the active TCP offset, as rotation vectors.
  const auto& o = options.ur.tcp_offset;
  const rtde::FieldValues offset(o.begin(), o.end());
  rtde::FieldValues tcp_pose(6, 0.0);
  const std::vector<double> r = readings_of(at);
  const Eigen::VectorXd encoders =
      Eigen::Map<const Eigen::VectorXd>(r.data(), static_cast<Eigen::Index>(r.size()));
  if (const std::optional<Eigen::Isometry3d> flange = true_flange_pose(robot, encoders)) {
    const Eigen::Matrix<double, 6, 1> p = ur_pose_from_isometry(
        *flange * ur_pose_to_isometry(Eigen::Map<const Eigen::VectorXd>(offset.data(), 6)));
    tcp_pose.assign(p.data(), p.data() + 6);
  }
  std::vector<rtde::FieldValues> fields;
  for (const std::string& name : ur.names) {
    if (name == "timestamp") fields.push_back({t()});
    if (name == "actual_q" || name == "target_q") fields.push_back(q);
    if (name == "actual_qd" || name == "target_qd") fields.push_back(qd);
    if (name == "robot_mode") fields.push_back({static_cast<double>(ur.robot_mode)});
    if (name == "safety_mode" || name == "safety_status")
      fields.push_back({static_cast<double>(ur.safety)});
    if (name == "runtime_state") fields.push_back({queue.empty() ? 1.0 : 2.0});
    if (name == "speed_scaling" || name == "target_speed_fraction")
      fields.push_back({ur.speed_fraction});
    if (name == "actual_TCP_pose") fields.push_back(tcp_pose);
    if (name == "tcp_offset") fields.push_back(offset);
  }
  return rtde::encode_data_package(ur.recipe_id, ur.types, fields);
}

void SimController::Impl::ur_send_packages(Channel& c, double now) {
  if (!c.open() || !ur.streaming || now < ur.next_package) return;
  // An overloaded controller skips packages rather than falling behind (RTDE guide).
  ur.next_package = std::max(ur.next_package + ur.period, now);
  if (now < ur.missing_until) return;
  const std::string package = ur_data_package(now);
  if (now < ur.late_until) {
    ur.late_packages += package;
    return;
  }
  if (!ur.late_packages.empty()) write_all(c.fd, std::exchange(ur.late_packages, std::string()));
  write_all(c.fd, package);
}

void SimController::Impl::ur_process(Channel& c, double now) {
  if (&c != &tcp) return;
  if (ur.pstop_motion != 0) {
    const bool running = !queue.empty() && queue.front().id == ur.pstop_motion;
    if (!running ||
        (queue.front().start >= 0.0 && now >= queue.front().start + 0.4 * queue.front().duration)) {
      ur.pstop_motion = 0;
      ur_protective_stop("injected fault");
    }
  }
  ur_send_packages(c, now);
}

void SimController::Impl::ur_protective_stop(const std::string& why) {
  quick_stop("protective stop");
  ur.safety = kProtectiveStop;
  ur.pstop_at = t();
  write_log({{"ev", "protective_stop"}, {"why", why}});
}

void SimController::Impl::ur_script(Channel& c, const std::string& line) {
  const std::size_t paren = line.find('(');
  const std::string fn = paren == std::string::npos ? line : line.substr(0, paren);
  const std::string args = paren == std::string::npos || line.back() != ')'
                               ? std::string()
                               : trimmed(line.substr(paren + 1, line.size() - paren - 2));
  if (fn == "stopj") {
    // Always obeyed, remote control or not: a stop must get through.
    quick_stop("stopj");
    return;
  }
  if (fn != "movej" || args.empty()) {
    write_log(
        {{"ev", "script_error"}, {"line", line}, {"why", "this controller runs movej and stopj"}});
    ur_script_exception(
        c, fmt::format("this simulated controller runs movej and stopj, not: {}", line));
    return;
  }
  const std::optional<FaultKind> fault = ur_roll_fault("movej");
  const std::vector<double> q = number_list(args);
  if (static_cast<int>(q.size()) != kUrJoints || robot.axes.size() > kUrJoints) {
    write_log({{"ev", "script_error"}, {"line", line}, {"why", "movej needs a list of 6 joints"}});
    ur_script_exception(c, "movej needs a list of 6 joints");
    return;
  }
  const char* rejected = !ur.remote                  ? "not in remote control"
                         : ur.safety != kNormal      ? "protective stop"
                         : ur.robot_mode != kRunning ? "robot not running"
                                                     : nullptr;
  if (rejected != nullptr) {
    write_log({{"ev", "rejected"}, {"line", line}, {"why", rejected}});
    return;
  }
  ur_movej(c, q, keyword(args, "a", 1.4), keyword(args, "v", 1.05), fault);
}

void SimController::Impl::ur_movej(Channel& c, const std::vector<double>& q, double a, double v,
                                   std::optional<FaultKind> fault) {
  const double now = now_seconds();
  if (fault) {
    ++counters.faults[static_cast<std::size_t>(*fault)];
    write_log({{"ev", "fault"}, {"kind", to_string(*fault)}, {"ch", c.name}, {"cmd", "movej"}});
  }
  if (fault == FaultKind::kError) {
    write_log({{"ev", "refused"}, {"cmd", "movej"}});
    ur_script_exception(c, "movej refused (injected fault)");
    return;
  }
  // A new script replaces the running one.
  if (!queue.empty()) quick_stop("replaced by a new script");
  Motion m;
  m.channel = c.name;
  m.to = counts;
  double units2 = 0.0, lead = 0.0;
  for (int i = 0; i < robot.axes.size(); ++i) {
    const auto k = static_cast<std::size_t>(i);
    m.to[k] = std::lround(q[k] / joint_si(robot, i) * robot.axes.steps_per_unit[k]);
    const double d = units_of(m.to[k] - counts[k], i);
    units2 += d * d;
    lead = std::max(lead, std::abs(d * joint_si(robot, i)));
  }
  // movej: the leading joint moves at v and a; the others are scaled to arrive with it. The
  // motion runs along the axis-space line, so its feed is v scaled by (line length / lead).
  const double ratio = lead > 0.0 ? std::sqrt(units2) / lead : 1.0 / joint_si(robot, 0);
  m.feed = v * ratio;
  m.acceleration = a * ratio;
  m.stall = fault == FaultKind::kStall;
  m.id = ++motion_ids;
  m.line = m.id;
  queue.push_back(m);
  advance_motion(now);
  if (fault == FaultKind::kProtectiveStop) ur.pstop_motion = m.id;
  if (fault == FaultKind::kSlow) ur.late_until = now + options.faults.slow_seconds;
  if (fault == FaultKind::kMissing) ur.missing_until = now + options.faults.slow_seconds;
  if (fault == FaultKind::kDrop) {
    // A cable pulled after the script arrived: the arm goes on, every client is cut off.
    write_log({{"ev", "drop"}, {"ch", c.name}, {"executed", true}});
    close_channel(tcp, false);
    close_channel(ur.secondary, false);
    close_channel(ur.dashboard, false);
  }
}

// A script the controller does not run is reported to the client that sent it as a runtime
// exception robot message (ur_primary.hpp), as a UR does on its client interfaces.
void SimController::Impl::ur_script_exception(Channel& c, const std::string& text) {
  if (!c.open()) return;
  write_all(c.fd, ur_primary::encode_runtime_exception(static_cast<std::uint64_t>(t() * 1000.0), 1,
                                                       1, text));
  write_log({{"ev", "tx"}, {"ch", c.name}, {"robot_message", "runtime_exception"}, {"text", text}});
}

// The dashboard server's replies, worded as UR's dashboard server documentation gives them.
std::string SimController::Impl::ur_dashboard_reply(Channel& /*c*/, const std::string& command) {
  if (command == "robotmode") return "Robotmode: " + robot_mode_name(ur.robot_mode);
  if (command == "safetystatus") return "Safetystatus: " + safety_name(ur.safety);
  if (command == "safetymode") return "Safetymode: " + safety_name(ur.safety);
  if (command == "is in remote control") return ur.remote ? "true" : "false";
  if (command == "close popup") return "closing popup";
  if (command == "close safety popup") return "closing safety popup";
  if (command == "PolyscopeVersion") return "URSoftware 5.11.0.108 (simulated)";
  if (command == "quit") return "Disconnected";
  if (command == "stop") {
    quick_stop("dashboard stop");
    return "Stopped";
  }
  if (command == "unlock protective stop") {
    if (ur.safety == kProtectiveStop && t() - ur.pstop_at < options.ur.unlock_delay)
      return "Cannot unlock protective stop until 5s after occurrence. Always inspect cause of "
             "protective stop before unlocking";
    if (ur.safety == kProtectiveStop) write_log({{"ev", "unlock_protective_stop"}});
    ur.safety = kNormal;
    return "Protective stop releasing";
  }
  if (command == "power off") {
    quick_stop("power off");
    ur.robot_mode = kPowerOff;
    return "Powering off";
  }
  if (command == "power on") {
    ur.robot_mode = kIdle;
    return "Powering on";
  }
  if (command == "brake release") {
    ur.robot_mode = kRunning;
    return "Brake releasing";
  }
  return "could not understand: '" + command + "'";
}

}  // namespace robocal::robotio
