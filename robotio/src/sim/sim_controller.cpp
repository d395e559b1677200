#include "robocal/robotio/sim_controller.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/core/input_error.hpp"
#include "robocal/core/text_lines.hpp"
#include "robocal/robotio/motion_profile.hpp"

#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pty.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <random>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

namespace robocal::robotio {
namespace {

constexpr std::array<const char*, kFaultKindCount> kFaultNames = {
    "drop", "busy", "error", "stall", "corrupt", "lost_ok", "resend", "slow", "garbage", "partial"};

double now_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

int listen_tcp(int port, int* bound_port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) throw std::runtime_error(std::string("socket: ") + std::strerror(errno));
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(fd, 4) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    throw std::runtime_error(fmt::format("cannot listen on 127.0.0.1:{}: {}", port, why));
  }
  socklen_t len = sizeof addr;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  *bound_port = ntohs(addr.sin_port);
  return fd;
}

void write_all(int fd, const std::string& data) {
  std::size_t sent = 0;
  while (sent < data.size()) {
    const ssize_t n = ::write(fd, data.data() + sent, data.size() - sent);
    if (n < 0 && (errno == EINTR || errno == EAGAIN)) {
      pollfd p{fd, POLLOUT, 0};
      ::poll(&p, 1, 50);
      continue;
    }
    if (n <= 0) return;  // the peer is gone; the read side notices and closes
    sent += static_cast<std::size_t>(n);
  }
}

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
  bool open() const { return fd >= 0; }
};

}  // namespace

const char* to_string(FaultKind kind) {
  return kFaultNames[static_cast<std::size_t>(kind)];
}

std::optional<FaultKind> fault_kind_from_string(const std::string& name) {
  for (std::size_t i = 0; i < kFaultNames.size(); ++i)
    if (name == kFaultNames[i]) return static_cast<FaultKind>(i);
  return std::nullopt;
}

FaultPlan parse_fault_spec(const std::string& spec) {
  FaultPlan plan;
  std::stringstream in(spec);
  std::string item;
  while (std::getline(in, item, ',')) {
    if (item.empty()) continue;
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos)
      throw std::invalid_argument("fault '" + item + "': expected KIND=RATE");
    const std::string kind = item.substr(0, eq);
    double rate = 0.0;
    try {
      rate = std::stod(item.substr(eq + 1));
    } catch (const std::exception&) {
      throw std::invalid_argument("fault '" + item + "': rate is not a number");
    }
    if (rate < 0.0 || rate > 1.0)
      throw std::invalid_argument("fault '" + item + "': rate must be within [0, 1]");
    if (kind == "all") {
      plan.rate.fill(rate);
      continue;
    }
    const auto k = fault_kind_from_string(kind);
    if (!k)
      throw std::invalid_argument("fault '" + kind +
                                  "': unknown kind (drop, busy, error, stall, corrupt, lost_ok, "
                                  "resend, slow, garbage, partial, all)");
    plan.rate[static_cast<std::size_t>(*k)] = rate;
  }
  return plan;
}

void load_fault_script(const std::string& path, FaultPlan& plan) {
  std::vector<core::ContentLine> lines;
  try {
    lines = core::read_content_lines(path);
  } catch (const core::InputError& e) {
    throw std::invalid_argument(e.what());
  }
  for (const core::ContentLine& line : lines) {
    std::stringstream ss(line.text);
    long index = 0;
    std::string kind;
    if (!(ss >> index) || !(ss >> kind) || index < 1)
      throw std::invalid_argument(
          fmt::format("{}:{}: expected '<command index> <kind>'", path, line.number));
    const auto k = fault_kind_from_string(kind);
    if (!k)
      throw std::invalid_argument(
          fmt::format("{}:{}: unknown fault kind '{}'", path, line.number, kind));
    plan.script[index] = *k;
  }
}

std::string pose_channel_reply(const SimRobot& robot, const Eigen::VectorXd& true_readings,
                               double t, bool moving, long motion) {
  nlohmann::json j;
  j["t"] = t;
  j["moving"] = moving;
  j["motion"] = motion;
  const int frame = robot.model.task.frame >= 0 ? robot.model.task.frame : robot.model.tool;
  const calib::ForwardResult fk =
      calib::forward_kinematics(robot.model, robot.truth, true_readings, frame);
  j["frame"] = robot.model.bodies[static_cast<std::size_t>(frame)].name;
  j["actuators_true"] =
      std::vector<double>(true_readings.data(), true_readings.data() + true_readings.size());
  if (!fk.closure.ok()) {
    j["error"] = std::string("closure: ") + calib::to_string(fk.closure.status);
    return j.dump();
  }
  const Eigen::Vector3d p = fk.pose.translation();
  const Eigen::Quaterniond q(fk.pose.linear());
  j["position"] = {p.x(), p.y(), p.z()};
  j["quaternion_wxyz"] = {q.w(), q.x(), q.y(), q.z()};
  return j.dump();
}

struct SimController::Impl {
  SimRobot robot;
  SimOptions options;
  SimCounters counters;
  std::mt19937 noise_rng;
  std::mt19937 fault_rng;
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
  long commands_received = 0;       // numbered commands (fault script index)
  Eigen::VectorXd physical_offset;  // backlash + repeatability of the current position
  std::vector<int> last_direction;

  Impl(SimRobot r, SimOptions o)
      : robot(std::move(r)),
        options(std::move(o)),
        noise_rng(options.seed),
        fault_rng(options.faults.seed),
        feed(options.feed / 60.0),
        acceleration(options.acceleration),
        busy_interval(options.busy_interval) {
    counts = counts_of(robot.home_readings);
    physical_offset = Eigen::VectorXd::Zero(robot.axes.size());
    last_direction.assign(static_cast<std::size_t>(robot.axes.size()), 0);
  }

  ~Impl() {
    for (Channel* c : {&tcp, &pty}) close_channel(*c, false);
    if (pty.slave >= 0) ::close(pty.slave);
    for (int fd : pose_clients) ::close(fd);
    if (tcp_listen >= 0) ::close(tcp_listen);
    if (pose_listen >= 0) ::close(pose_listen);
    if (!options.pty_link.empty()) std::filesystem::remove(options.pty_link);
    if (log != nullptr) std::fclose(log);
  }

  double t() const { return now_seconds() - t0; }

  std::vector<long> counts_of(const Eigen::VectorXd& readings) const {
    return axis_counts(robot.axes, readings);
  }
  double units_of(long count, int axis) const {
    return static_cast<double>(count) / robot.axes.steps_per_unit[static_cast<std::size_t>(axis)];
  }

  void write_log(nlohmann::json j) {
    if (log == nullptr) return;
    j["t"] = std::round(t() * 1e6) / 1e6;
    const std::string s = j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    std::fputs(s.c_str(), log);
    std::fputc('\n', log);
    std::fflush(log);
  }

  // ---- channels ------------------------------------------------------------------------------

  void open_pty() {
    int master = -1, slave = -1;
    if (::openpty(&master, &slave, nullptr, nullptr, nullptr) != 0)
      throw std::runtime_error(std::string("openpty: ") + std::strerror(errno));
    termios tio{};
    ::tcgetattr(slave, &tio);
    ::cfmakeraw(&tio);  // a USB CDC port: no echo, no line editing
    ::tcsetattr(slave, TCSANOW, &tio);
    ::fcntl(master, F_SETFL, ::fcntl(master, F_GETFL) | O_NONBLOCK);
    ::fcntl(master, F_SETFD, FD_CLOEXEC);
    ::fcntl(slave, F_SETFD, FD_CLOEXEC);
    pty.fd = master;
    pty.slave = slave;
    pty_path = ::ttyname(slave) != nullptr ? ::ttyname(slave) : "";
    if (!options.pty_link.empty()) {
      const std::string tmp = options.pty_link + ".new";
      std::filesystem::remove(tmp);
      std::filesystem::create_symlink(pty_path, tmp);
      std::filesystem::rename(tmp, options.pty_link);
    }
    reset_channel(pty);
  }

  void reset_channel(Channel& c) {
    c.inbuf.clear();
    c.pending.clear();
    c.last_n = 0;
    c.blocked = false;
    c.hold_until = 0.0;
    c.next_temperature = t() + options.temperature_interval;
  }

  void close_channel(Channel& c, bool reopen) {
    if (c.fd < 0) return;
    ::close(c.fd);
    c.fd = -1;
    if (c.name == "pty") {
      ::close(c.slave);
      c.slave = -1;
    }
    write_log({{"ev", "disconnect"}, {"ch", c.name}});
    // A USB board that drops off the bus comes back as a new device; the stable link follows.
    if (reopen && c.name == "pty") open_pty();
  }

  void send(Channel& c, const std::string& line) {
    if (c.fd < 0) return;
    write_log({{"ev", "tx"}, {"ch", c.name}, {"line", line}});
    write_all(c.fd, line + "\n");
  }

  void greet(Channel& c) {
    ++counters.connections;
    write_log({{"ev", "connect"}, {"ch", c.name}});
    if (options.mute) return;
    // Marlin prints its boot banner when a host opens the port (the board resets on DTR).
    if (options.dialect == Firmware::kMarlin && options.firmware_name.empty()) {
      send(c, "start");
      send(c, "echo:Marlin 2.1.2.1");
    }
  }

  // ---- motion --------------------------------------------------------------------------------

  void start_next_motion(double now) {
    if (queue.empty() || queue.front().start >= 0.0) return;
    Motion& m = queue.front();
    m.from = counts;
    double len2 = 0.0;
    for (int i = 0; i < robot.axes.size(); ++i) {
      const double d =
          units_of(m.to[static_cast<std::size_t>(i)] - m.from[static_cast<std::size_t>(i)], i);
      len2 += d * d;
    }
    m.length = std::sqrt(len2);
    m.duration = trapezoid_seconds(m.length, m.feed, m.acceleration);
    m.start = now;
    ++counters.motions;
    std::vector<double> target(m.to.size());
    for (int i = 0; i < robot.axes.size(); ++i)
      target[static_cast<std::size_t>(i)] = units_of(m.to[static_cast<std::size_t>(i)], i);
    write_log({{"ev", "motion_start"},
               {"id", m.id},
               {"ch", m.channel},
               {"line", m.line},
               {"from", m.from},
               {"to", m.to},
               {"target", target},
               {"target_readings", readings_of(m.to)},
               {"length", m.length},
               {"feed", m.feed},
               {"acceleration", m.acceleration},
               {"duration_s", m.duration},
               {"homing", m.homing}});
  }

  std::vector<double> readings_of(const std::vector<long>& c) const {
    std::vector<double> r(c.size());
    for (int i = 0; i < robot.axes.size(); ++i)
      r[static_cast<std::size_t>(i)] = units_of(c[static_cast<std::size_t>(i)], i) /
                                       robot.axes.unit_factor[static_cast<std::size_t>(i)];
    return r;
  }

  std::vector<long> interpolate(const Motion& m, double now) const {
    double elapsed = now - m.start;
    if (m.stall) elapsed = std::min(elapsed, 0.5 * m.duration);
    const double s = m.length > 0.0
                         ? trapezoid_distance(m.length, m.feed, m.acceleration, elapsed) / m.length
                         : 1.0;
    std::vector<long> c(m.from.size());
    for (std::size_t i = 0; i < c.size(); ++i)
      c[i] = m.from[i] + std::lround(s * static_cast<double>(m.to[i] - m.from[i]));
    return c;
  }

  void finish_motion(const Motion& m, const std::vector<long>& reached, bool stopped) {
    // Backlash: an axis that reverses loses `backlash` of motion; the physical position lags the
    // counted one by half the backlash against the direction of travel. Repeatability noise is
    // drawn once per move.
    std::normal_distribution<double> noise(0.0, 1.0);
    for (int i = 0; i < robot.axes.size(); ++i) {
      const auto k = static_cast<std::size_t>(i);
      const long d = reached[k] - m.from[k];
      if (d != 0) last_direction[k] = d > 0 ? 1 : -1;
      physical_offset[i] =
          -0.5 * robot.backlash * last_direction[k] + robot.noise_sigma * noise(noise_rng);
    }
    counts = reached;
    write_log({{"ev", "motion_end"}, {"id", m.id}, {"counts", reached}, {"stopped", stopped}});
  }

  void advance_motion(double now) {
    while (!queue.empty()) {
      start_next_motion(now);
      Motion& m = queue.front();
      if (m.stall || now < m.start + m.duration) {
        counts = interpolate(m, now);
        return;
      }
      const Motion done = m;
      queue.pop_front();
      finish_motion(done, done.to, false);
      if (!queue.empty()) queue.front().start = -1.0;
      start_next_motion(done.start + done.duration);
    }
  }

  // M410 / M112: motion stops where it is, the queue is dropped.
  void quick_stop(const std::string& how) {
    const double now = now_seconds();
    if (!queue.empty() && queue.front().start >= 0.0) {
      const Motion m = queue.front();
      finish_motion(m, interpolate(m, now), true);
    }
    queue.clear();
    ++counters.stops;
    write_log({{"ev", "stop"}, {"cmd", how}, {"counts", counts}});
  }

  Eigen::VectorXd true_readings(double now) const {
    std::vector<long> c = counts;
    if (!queue.empty() && queue.front().start >= 0.0) c = interpolate(queue.front(), now);
    const std::vector<double> r = readings_of(c);
    Eigen::VectorXd out(static_cast<Eigen::Index>(r.size()));
    for (std::size_t i = 0; i < r.size(); ++i)
      out[static_cast<Eigen::Index>(i)] = r[i] + physical_offset[static_cast<Eigen::Index>(i)];
    return out;
  }

  // ---- G-code --------------------------------------------------------------------------------

  std::string position_report(bool partial) const {
    std::string pos, cnt;
    for (int i = 0; i < robot.axes.size(); ++i) {
      const auto k = static_cast<std::size_t>(i);
      const char letter = robot.axes.letters[k];
      const double v = units_of(counts[k], i);
      if (options.dialect == Firmware::kRepRapFirmware) {
        pos += fmt::format("{}:{:.3f} ", letter, v);
        cnt += fmt::format(" {}", counts[k]);
      } else {
        pos += fmt::format("{}:{:.2f} ", letter, v);
        cnt += fmt::format(" {}:{}", letter, counts[k]);
      }
    }
    std::string line = options.dialect == Firmware::kRepRapFirmware
                           ? pos + "E:0.000 Count" + cnt + " Machine " + pos + "Bed comp 0.000"
                           : pos + "E:0.00 Count" + cnt;
    if (partial) line.resize(line.find("Count") / 2);  // cut mid-report, as a lost USB packet
    return line;
  }

  std::string firmware_report() const {
    if (!options.firmware_name.empty()) return "FIRMWARE_NAME:" + options.firmware_name;
    if (options.dialect == Firmware::kRepRapFirmware)
      return "FIRMWARE_NAME: RepRapFirmware for Duet 3 MB6HC FIRMWARE_VERSION: 3.4.5 "
             "ELECTRONICS: Duet 3 MB6HC v1.01 FIRMWARE_DATE: 2022-11-30 (robocal simulator)";
    return "FIRMWARE_NAME:Marlin 2.1.2.1 (robocal simulator) SOURCE_CODE_URL:"
           "github.com/MarlinFirmware/Marlin PROTOCOL_VERSION:1.0 MACHINE_TYPE:" +
           robot.model.name + " KINEMATICS:Cartesian EXTRUDER_COUNT:0";
  }

  static std::optional<double> word(const std::string& cmd, char letter) {
    std::stringstream ss(cmd);
    std::string tok;
    ss >> tok;  // the command itself
    while (ss >> tok)
      if (tok.size() > 1 && tok[0] == letter) {
        try {
          return std::stod(tok.substr(1));
        } catch (const std::exception&) {
          return std::nullopt;
        }
      }
    return std::nullopt;
  }

  void reply_ok(Channel& c, bool lost) {
    if (lost) {
      write_log({{"ev", "ok_dropped"}, {"ch", c.name}});
      return;
    }
    send(c, "ok");
  }

  void block(Channel& c, bool lost_ok) {
    c.blocked = true;
    c.blocked_lost_ok = lost_ok;
    c.next_busy = now_seconds() + busy_interval;
  }

  // Executes one accepted command; `fault` may alter the reply.
  void execute(Channel& c, const std::string& cmd, long line, std::optional<FaultKind> fault) {
    const bool lost = fault == FaultKind::kLostOk;
    std::string code;
    std::stringstream(cmd) >> code;
    for (char& ch : code) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    if (code == "G0" || code == "G1") {
      if (const auto f = word(cmd, 'F')) feed = *f / 60.0;
      Motion m;
      m.id = ++motion_ids;
      m.line = line;
      m.channel = c.name;
      m.to = queue.empty() ? counts : queue.back().to;
      for (int i = 0; i < robot.axes.size(); ++i) {
        const auto k = static_cast<std::size_t>(i);
        if (const auto v = word(cmd, robot.axes.letters[k]))
          m.to[k] = std::lround(*v * robot.axes.steps_per_unit[k]);
      }
      m.feed = feed;
      m.acceleration = acceleration;
      m.stall = fault == FaultKind::kStall;
      queue.push_back(m);
      advance_motion(now_seconds());
      reply_ok(c, lost);
    } else if (code == "G28") {
      Motion m;
      m.id = ++motion_ids;
      m.line = line;
      m.channel = c.name;
      m.to = counts_of(robot.home_readings);
      m.feed = feed;
      m.acceleration = acceleration;
      m.homing = true;
      queue.push_back(m);
      advance_motion(now_seconds());
      block(c, lost);
    } else if (code == "M400") {
      block(c, lost);
    } else if (code == "M114") {
      send(c, position_report(fault == FaultKind::kPartial));
      reply_ok(c, lost);
    } else if (code == "M115") {
      send(c, firmware_report());
      if (options.dialect == Firmware::kMarlin && options.firmware_name.empty()) {
        send(c, "Cap:EMERGENCY_PARSER:1");
        send(c, "Cap:HOST_ACTION_COMMANDS:0");
      }
      reply_ok(c, lost);
    } else if (code == "M204") {
      if (const auto s = word(cmd, 'S')) acceleration = *s;
      if (const auto p = word(cmd, 'P')) acceleration = *p;
      reply_ok(c, lost);
    } else if (code == "M113") {
      if (const auto s = word(cmd, 'S')) busy_interval = std::max(0.1, *s);
      reply_ok(c, lost);
    } else if (code == "M105") {
      send(c, "ok T:24.80 /0.00 B:25.10 /0.00 @:0 B@:0");
    } else if (code == "G91") {
      send(c, "Error:relative positioning (G91) is not simulated");
      reply_ok(c, lost);
    } else if (code == "M410" || code == "M112" || code == "G90" || code == "G21" ||
               code == "M155" || code == "M84" || code == "M110" || code == "M999") {
      reply_ok(c, lost);  // stops acted on when received (emergency parser)
    } else {
      send(c, "echo:Unknown command: \"" + cmd + "\"");
      reply_ok(c, lost);
    }
  }

  std::optional<FaultKind> roll_fault(const std::string& cmd) {
    ++commands_received;
    const auto scripted = options.faults.script.find(commands_received);
    std::optional<FaultKind> f;
    if (scripted != options.faults.script.end()) {
      f = scripted->second;
    } else {
      std::uniform_real_distribution<double> u(0.0, 1.0);
      for (std::size_t k = 0; k < kFaultNames.size() && !f; ++k) {
        const double r = u(fault_rng);  // always drawn: the sequence does not depend on hits
        if (r < options.faults.rate[k]) f = static_cast<FaultKind>(k);
      }
    }
    if (!f) return f;
    const bool is_move = cmd.rfind("G1", 0) == 0 || cmd.rfind("G0", 0) == 0;
    // Faults that only make sense for some commands fall back to none elsewhere.
    if (*f == FaultKind::kStall && !is_move) return std::nullopt;
    if (*f == FaultKind::kPartial && cmd.rfind("M114", 0) != 0) return std::nullopt;
    // A stop must always get through: never fault the commands that stop the robot.
    if (cmd.rfind("M410", 0) == 0 || cmd.rfind("M112", 0) == 0 || cmd.rfind("M110", 0) == 0)
      return std::nullopt;
    return f;
  }

  // A fault drawn for a line the firmware then rejects (a duplicate line number after a lost ok)
  // never takes effect: it is logged as void and not counted.
  void void_fault(Channel& c, std::optional<FaultKind> fault) {
    if (!fault || *fault == FaultKind::kBusy || *fault == FaultKind::kGarbage ||
        *fault == FaultKind::kSlow)
      return;  // these happened before the line was judged
    --counters.faults[static_cast<std::size_t>(*fault)];
    write_log({{"ev", "fault_void"}, {"kind", to_string(*fault)}, {"ch", c.name}});
  }

  void handle_line(Channel& c, Pending& item) {
    ReceivedLine rl = split_received_line(item.text);
    if (item.fault == FaultKind::kCorrupt && rl.has_checksum) rl.valid = false;
    const std::optional<FaultKind> fault = item.fault;
    if (fault) {
      ++counters.faults[static_cast<std::size_t>(*fault)];
      write_log({{"ev", "fault"},
                 {"kind", to_string(*fault)},
                 {"ch", c.name},
                 {"line", rl.number},
                 {"cmd", rl.command}});
    }
    if (halted) {
      if (rl.command.rfind("M999", 0) == 0) {
        halted = false;
        c.last_n = 0;
        write_log({{"ev", "reset"}});
        send(c, "ok");
      }
      return;  // a killed firmware answers nothing
    }
    if (rl.command.empty() && !rl.has_number) return;
    if (fault == FaultKind::kGarbage) send(c, "\x02\x7f\x1b[0;~\x7f\x01");
    if (fault == FaultKind::kBusy)
      for (int i = 0; i < options.faults.busy_lines; ++i) send(c, "echo:busy: processing");
    if (rl.has_number) {
      const bool m110 = rl.command.rfind("M110", 0) == 0;
      if (!rl.valid || fault == FaultKind::kResend) {
        if (fault != FaultKind::kCorrupt && fault != FaultKind::kResend) void_fault(c, fault);
        send(c, fmt::format("Error:checksum mismatch, Last Line: {}", c.last_n));
        send(c, resend_request(options.dialect, c.last_n + 1));
        send(c, "ok");
        return;
      }
      if (m110) {
        const auto n = word(rl.command, 'N');
        c.last_n = n ? static_cast<long>(*n) : rl.number;
        send(c, "ok");
        return;
      }
      if (rl.number != c.last_n + 1) {
        void_fault(c, fault);
        send(c,
             fmt::format("Error:Line Number is not Last Line Number+1, Last Line: {}", c.last_n));
        send(c, resend_request(options.dialect, c.last_n + 1));
        send(c, "ok");
        return;
      }
      if (fault == FaultKind::kDrop) {
        // Half the drops lose the line on the wire, half happen after the firmware took it.
        std::uniform_int_distribution<int> coin(0, 1);
        if (coin(fault_rng) == 1) {
          c.last_n = rl.number;
          execute(c, rl.command, rl.number, std::nullopt);
          write_log({{"ev", "drop"}, {"ch", c.name}, {"executed", true}});
        } else {
          write_log({{"ev", "drop"}, {"ch", c.name}, {"executed", false}});
        }
        close_channel(c, true);
        return;
      }
      c.last_n = rl.number;
    }
    if (fault == FaultKind::kError) {
      send(c, fmt::format("Error:command rejected (injected fault), line {}", rl.number));
      send(c, "ok");
      return;
    }
    execute(c, rl.command, rl.number, fault);
  }

  // Bytes arrived on a channel: split lines, act on emergency commands at once.
  void receive(Channel& c) {
    char buf[4096];
    const ssize_t n = ::read(c.fd, buf, sizeof buf);
    if (n < 0 && (errno == EINTR || errno == EAGAIN)) return;
    if (n <= 0) {
      // TCP: the client left. pty: the master never sees EOF while we hold the slave open.
      close_channel(c, false);
      return;
    }
    c.inbuf.append(buf, static_cast<std::size_t>(n));
    std::size_t eol;
    while ((eol = c.inbuf.find_first_of("\r\n")) != std::string::npos) {
      std::string line = c.inbuf.substr(0, eol);
      c.inbuf.erase(0, eol + 1);
      if (line.empty()) continue;
      ++counters.lines;
      write_log({{"ev", "rx"}, {"ch", c.name}, {"line", line}});
      if (options.mute) continue;
      const ReceivedLine rl = split_received_line(line);
      // Emergency parser: stops act on receipt, even while the firmware waits in M400.
      if (rl.valid && (rl.command.rfind("M410", 0) == 0 || rl.command.rfind("M112", 0) == 0)) {
        const bool kill = rl.command.rfind("M112", 0) == 0;
        quick_stop(kill ? "M112" : "M410");
        if (kill) {
          halted = true;
          for (Channel* ch : {&tcp, &pty}) {
            ch->pending.clear();
            ch->blocked = false;
          }
          send(c, "Error:Printer halted. kill() called!");
          continue;
        }
      }
      c.pending.push_back({line, false, std::nullopt});
    }
  }

  void process(Channel& c, double now) {
    if (!c.open()) return;
    if (c.blocked) {
      if (queue.empty()) {
        c.blocked = false;
        reply_ok(c, c.blocked_lost_ok);
      } else if (now >= c.next_busy) {
        if (options.dialect == Firmware::kMarlin) send(c, "echo:busy: processing");
        c.next_busy = now + busy_interval;
      }
    }
    while (c.open() && !c.blocked && !c.pending.empty() && now >= c.hold_until) {
      Pending& item = c.pending.front();
      if (!item.rolled) {
        item.rolled = true;
        const ReceivedLine rl = split_received_line(item.text);
        if (rl.has_number && !halted) item.fault = roll_fault(rl.command);
        if (item.fault == FaultKind::kSlow) {
          c.hold_until = now + options.faults.slow_seconds;
          continue;
        }
      }
      Pending taken = std::move(item);
      c.pending.pop_front();
      handle_line(c, taken);
    }
    if (c.open() && options.temperature_interval > 0.0 && t() >= c.next_temperature &&
        !options.mute) {
      send(c, " T:24.80 /0.00 B:25.10 /0.00 @:0 B@:0");
      c.next_temperature = t() + options.temperature_interval;
    }
  }

  double next_event(double now) const {
    double next = now + 0.05;
    if (!queue.empty() && queue.front().start >= 0.0 && !queue.front().stall)
      next = std::min(next, queue.front().start + queue.front().duration);
    for (const Channel* c : {&tcp, &pty}) {
      if (!c->open()) continue;
      if (c->blocked) next = std::min(next, c->next_busy);
      if (!c->pending.empty() && c->hold_until > now) next = std::min(next, c->hold_until);
    }
    return next;
  }

  void serve_pose(std::size_t i) {
    char buf[512];
    const ssize_t n = ::read(pose_clients[i], buf, sizeof buf);
    if (n <= 0) {
      ::close(pose_clients[i]);
      pose_clients.erase(pose_clients.begin() + static_cast<long>(i));
      pose_buffers.erase(pose_buffers.begin() + static_cast<long>(i));
      return;
    }
    pose_buffers[i].append(buf, static_cast<std::size_t>(n));
    std::size_t eol;
    while ((eol = pose_buffers[i].find('\n')) != std::string::npos) {
      pose_buffers[i].erase(0, eol + 1);
      const double now = now_seconds();
      advance_motion(now);
      const bool moving = !queue.empty();
      const std::string reply =
          pose_channel_reply(robot, true_readings(now), t(), moving, motion_ids) + "\n";
      write_all(pose_clients[i], reply);
    }
  }

  void accept_on(int listen_fd, Channel* channel) {
    const int fd = ::accept4(listen_fd, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) return;
    const int one = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    if (channel == nullptr) {
      pose_clients.push_back(fd);
      pose_buffers.emplace_back();
      return;
    }
    close_channel(*channel, false);  // one host at a time, the newest wins
    channel->fd = fd;
    reset_channel(*channel);
    greet(*channel);
  }
};

SimController::SimController(SimRobot robot, SimOptions options)
    : impl_(std::make_unique<Impl>(std::move(robot), std::move(options))) {}

SimController::~SimController() = default;

void SimController::start() {
  Impl& s = *impl_;
  if (!s.options.log_path.empty()) {
    s.log = std::fopen(s.options.log_path.c_str(), "w");
    if (s.log == nullptr)
      throw std::runtime_error(s.options.log_path +
                               ": cannot write the log: " + std::strerror(errno));
  }
  if (s.options.tcp_port >= 0) s.tcp_listen = listen_tcp(s.options.tcp_port, &s.tcp_port);
  if (s.options.pose_port >= 0) s.pose_listen = listen_tcp(s.options.pose_port, &s.pose_port);
  if (s.options.pty) {
    s.open_pty();
    s.greet(s.pty);
  }
  s.write_log({{"ev", "start"},
               {"robot", s.robot.model.name},
               {"firmware", to_string(s.options.dialect)},
               {"tcp", tcp_address()},
               {"pty", s.pty_path},
               {"pose", pose_address()},
               {"axes", s.robot.axes.letters},
               {"steps_per_unit", s.robot.axes.steps_per_unit},
               {"unit_factor", s.robot.axes.unit_factor}});
}

std::string SimController::tcp_address() const {
  return impl_->tcp_listen >= 0 ? fmt::format("127.0.0.1:{}", impl_->tcp_port) : "";
}
std::string SimController::pty_path() const {
  return impl_->pty_path;
}
std::string SimController::pose_address() const {
  return impl_->pose_listen >= 0 ? fmt::format("127.0.0.1:{}", impl_->pose_port) : "";
}
SimCounters SimController::counters() const {
  return impl_->counters;
}

void SimController::run(const std::atomic<bool>& stop) {
  Impl& s = *impl_;
  const double end = s.options.max_seconds > 0.0 ? now_seconds() + s.options.max_seconds : 1e300;
  bool parent_gone = false;
  while (!stop.load() && now_seconds() < end) {
    std::vector<pollfd> fds;
    enum Src { kTcpListen, kPoseListen, kTcp, kPty, kPose, kParent };
    std::vector<std::pair<Src, std::size_t>> src;
    auto add = [&](int fd, Src what, std::size_t i = 0) {
      if (fd < 0) return;
      fds.push_back({fd, POLLIN, 0});
      src.emplace_back(what, i);
    };
    add(s.tcp_listen, kTcpListen);
    add(s.pose_listen, kPoseListen);
    add(s.tcp.fd, kTcp);
    add(s.pty.fd, kPty);
    for (std::size_t i = 0; i < s.pose_clients.size(); ++i) add(s.pose_clients[i], kPose, i);
    if (s.options.exit_with_parent) add(STDIN_FILENO, kParent);
    const double now = now_seconds();
    const double wait = std::max(0.0, std::min(s.next_event(now), end) - now);
    timespec ts{static_cast<time_t>(wait), static_cast<long>((wait - std::floor(wait)) * 1e9)};
    const int ready = ::ppoll(fds.data(), fds.size(), &ts, nullptr);
    if (ready < 0 && errno != EINTR)
      throw std::runtime_error(std::string("poll: ") + std::strerror(errno));
    // Pose clients are served first and highest index first, so erasing one keeps the others'
    // indices valid.
    for (std::size_t k = fds.size(); k-- > 0;) {
      if (ready <= 0 || fds[k].revents == 0) continue;
      switch (src[k].first) {
        case kTcpListen:
          s.accept_on(s.tcp_listen, &s.tcp);
          break;
        case kPoseListen:
          s.accept_on(s.pose_listen, nullptr);
          break;
        case kTcp:
          if (s.tcp.fd == fds[k].fd) s.receive(s.tcp);
          break;
        case kPty:
          if (s.pty.fd == fds[k].fd) s.receive(s.pty);
          break;
        case kPose:
          s.serve_pose(src[k].second);
          break;
        case kParent: {
          char buf[256];
          if (::read(STDIN_FILENO, buf, sizeof buf) <= 0) parent_gone = true;
          break;
        }
      }
    }
    if (parent_gone) break;
    const double after = now_seconds();
    s.advance_motion(after);
    s.process(s.tcp, after);
    s.process(s.pty, after);
  }
  s.write_log({{"ev", "exit"},
               {"lines", s.counters.lines},
               {"motions", s.counters.motions},
               {"parent_gone", parent_gone}});
}

}  // namespace robocal::robotio
