// The simulated controller's process side: the loopback TCP port and the pseudo-terminal its
// protocol is served on, the true-pose channel, and the poll loop that drives everything.
#include "sim_internal.hpp"

#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pty.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <fmt/core.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <utility>
#include <vector>

namespace robocal::robotio {
int listen_loopback(int port, int* bound_port) {
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

double now_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
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

SimController::Impl::Impl(SimRobot r, SimOptions o)
    : robot(std::move(r)),
      options(std::move(o)),
      noise_rng(options.seed),
      fault_rng(options.faults.seed),
      flange_rng(options.seed + 7919U),
      feed(options.feed / 60.0),
      acceleration(options.acceleration),
      busy_interval(options.busy_interval) {
  counts = counts_of(robot.home_readings);
  physical_offset = Eigen::VectorXd::Zero(robot.axes.size());
  last_direction.assign(static_cast<std::size_t>(robot.axes.size()), 0);
}

SimController::Impl::~Impl() {
  ur_close();
  for (Channel* c : {&tcp, &pty}) close_channel(*c, false);
  if (pty.slave >= 0) ::close(pty.slave);
  for (int fd : pose_clients) ::close(fd);
  if (tcp_listen >= 0) ::close(tcp_listen);
  if (pose_listen >= 0) ::close(pose_listen);
  if (!options.pty_link.empty()) std::filesystem::remove(options.pty_link);
  if (log != nullptr) std::fclose(log);
}

void SimController::Impl::open_pty() {
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

void SimController::Impl::reset_channel(Channel& c) {
  c.inbuf.clear();
  c.pending.clear();
  c.last_n = 0;
  c.blocked = false;
  c.hold_until = 0.0;
  c.next_temperature = t() + options.temperature_interval;
  c.last_id = nullptr;
  c.last_reply.clear();
  c.wait_id = nullptr;
  c.wait_cmd.clear();
  c.notified_motion = motion_ids;
  c.upgraded = false;
  c.script.clear();
  c.script_id = nullptr;
  c.script_lost = false;
}

void SimController::Impl::close_channel(Channel& c, bool reopen) {
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

void SimController::Impl::send(Channel& c, const std::string& line) {
  if (gcode_capture != nullptr) {
    gcode_capture->push_back(line);
    return;
  }
  if (c.fd < 0) return;
  write_log({{"ev", "tx"}, {"ch", c.name}, {"line", line}});
  write_all(c.fd, line + "\n");
}

double SimController::Impl::next_event(double now) const {
  double next = now + 0.05;
  if (!queue.empty() && queue.front().start >= 0.0 && !queue.front().stall)
    next = std::min(next, queue.front().start + queue.front().duration);
  for (const Channel* c : {&tcp, &pty}) {
    if (!c->open()) continue;
    if (c->blocked) next = std::min(next, c->next_busy);
    if (!c->pending.empty() && c->hold_until > now) next = std::min(next, c->hold_until);
  }
  if (options.protocol == SimProtocol::kUr && ur.streaming && tcp.open())
    next = std::min(next, std::max(now, ur.next_package));
  return next;
}

void SimController::Impl::serve_pose(std::size_t i) {
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

void SimController::Impl::accept_on(int listen_fd, Channel* channel) {
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
  on_connect(*channel);
}

void SimController::Impl::on_connect(Channel& c) {
  if (options.protocol == SimProtocol::kGcode) {
    greet(c);
    return;
  }
  if (options.protocol == SimProtocol::kUr) {
    ur_on_connect(c);
    return;
  }
  ++counters.connections;
  write_log({{"ev", "connect"}, {"ch", c.name}});
}

bool SimController::Impl::read_input(Channel& c) {
  char buf[4096];
  const ssize_t n = ::read(c.fd, buf, sizeof buf);
  if (n < 0 && (errno == EINTR || errno == EAGAIN)) return false;
  if (n <= 0) {
    // TCP: the client left. pty: the master never sees EOF while we hold the slave open.
    close_channel(c, false);
    return false;
  }
  c.inbuf.append(buf, static_cast<std::size_t>(n));
  return true;
}

void SimController::Impl::receive_any(Channel& c) {
  if (options.protocol == SimProtocol::kMoonraker) {
    moonraker_receive(c);
  } else if (options.protocol == SimProtocol::kOpen) {
    open_receive(c);
  } else if (options.protocol == SimProtocol::kUr) {
    ur_receive(c);
  } else {
    receive(c);
  }
}

void SimController::Impl::process_any(Channel& c, double now) {
  if (options.protocol == SimProtocol::kMoonraker) {
    moonraker_process(c, now);
  } else if (options.protocol == SimProtocol::kOpen) {
    open_process(c, now);
  } else if (options.protocol == SimProtocol::kUr) {
    ur_process(c, now);
  } else {
    process(c, now);
  }
}
SimController::SimController(SimRobot robot, SimOptions options)
    : impl_(std::make_unique<Impl>(std::move(robot), std::move(options))) {}

SimController::~SimController() = default;

void SimController::start() {
  Impl& s = *impl_;
  if (s.options.protocol == SimProtocol::kMoonraker &&
      (!s.options.delta || s.options.delta->geometry.firmware != Firmware::kKlipper))
    throw std::runtime_error(
        "the simulated Moonraker serves a Klipper delta: it needs the delta "
        "geometry in Klipper's terms");
  if (!s.options.log_path.empty()) {
    s.log = std::fopen(s.options.log_path.c_str(), "w");
    if (s.log == nullptr)
      throw std::runtime_error(s.options.log_path +
                               ": cannot write the log: " + std::strerror(errno));
  }
  if (s.options.tcp_port >= 0) s.tcp_listen = listen_loopback(s.options.tcp_port, &s.tcp_port);
  if (s.options.pose_port >= 0) s.pose_listen = listen_loopback(s.options.pose_port, &s.pose_port);
  if (s.options.protocol == SimProtocol::kUr) s.ur_start();
  if (s.options.pty && s.options.protocol != SimProtocol::kMoonraker) {
    s.open_pty();
    s.greet(s.pty);
  }
  s.write_log({{"ev", "start"},
               {"robot", s.robot.model.name},
               {"protocol", s.options.protocol == SimProtocol::kOpen        ? "open"
                            : s.options.protocol == SimProtocol::kUr        ? "ur"
                            : s.options.protocol == SimProtocol::kMoonraker ? "moonraker"
                                                                            : "gcode"},
               {"ur", ur_address()},
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
std::string SimController::ur_address() const {
  if (impl_->options.protocol != SimProtocol::kUr || impl_->tcp_listen < 0) return "";
  return fmt::format("ur:127.0.0.1:{}:{}:{}", impl_->tcp_port, impl_->ur.secondary_port,
                     impl_->ur.dashboard_port);
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
    enum Src {
      kTcpListen,
      kPoseListen,
      kTcp,
      kPty,
      kPose,
      kParent,
      kSecondaryListen,
      kDashboardListen,
      kSecondary,
      kDashboard
    };
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
    add(s.ur.secondary_listen, kSecondaryListen);
    add(s.ur.dashboard_listen, kDashboardListen);
    add(s.ur.secondary.fd, kSecondary);
    add(s.ur.dashboard.fd, kDashboard);
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
          if (s.tcp.fd == fds[k].fd) s.receive_any(s.tcp);
          break;
        case kPty:
          if (s.pty.fd == fds[k].fd) s.receive_any(s.pty);
          break;
        case kPose:
          s.serve_pose(src[k].second);
          break;
        case kSecondaryListen:
          s.accept_on(s.ur.secondary_listen, &s.ur.secondary);
          break;
        case kDashboardListen:
          s.accept_on(s.ur.dashboard_listen, &s.ur.dashboard);
          break;
        case kSecondary:
          if (s.ur.secondary.fd == fds[k].fd) s.receive_any(s.ur.secondary);
          break;
        case kDashboard:
          if (s.ur.dashboard.fd == fds[k].fd) s.receive_any(s.ur.dashboard);
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
    s.process_any(s.tcp, after);
    s.process_any(s.pty, after);
  }
  s.write_log({{"ev", "exit"},
               {"lines", s.counters.lines},
               {"motions", s.counters.motions},
               {"parent_gone", parent_gone}});
}

}  // namespace robocal::robotio
