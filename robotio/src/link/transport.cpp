#include "robocal/robotio/transport.hpp"

#include "robocal/robotio/link_error.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <utility>

namespace robocal::robotio {
namespace {

int millis_until(Clock::time_point deadline) {
  const auto left =
      std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
  return left <= 0 ? 0 : static_cast<int>(left);
}

speed_t baud_constant(int baud) {
  switch (baud) {
    case 9600:
      return B9600;
    case 19200:
      return B19200;
    case 38400:
      return B38400;
    case 57600:
      return B57600;
    case 115200:
      return B115200;
    case 230400:
      return B230400;
    case 460800:
      return B460800;
    case 500000:
      return B500000;
    case 921600:
      return B921600;
    case 1000000:
      return B1000000;
    case 2000000:
      return B2000000;
    case 4000000:
      return B4000000;
    default:
      return B0;
  }
}

}  // namespace

LinkError::LinkError(std::string device, const std::string& problem, std::string controller_said)
    : std::runtime_error(device + ": " + problem +
                         (controller_said.empty()
                              ? std::string()
                              : " (controller said: \"" + controller_said + "\")")),
      device_(std::move(device)),
      said_(std::move(controller_said)) {}

FdTransport::~FdTransport() {
  FdTransport::close();
}

void FdTransport::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  buffer_.clear();
}

void FdTransport::write_line(const std::string& line) {
  write_bytes(line + "\n");
}

void FdTransport::write_bytes(const std::string& data) {
  if (fd_ < 0) throw LinkError(device(), "not connected");
  std::size_t sent = 0;
  while (sent < data.size()) {
    const ssize_t n = ::write(fd_, data.data() + sent, data.size() - sent);
    if (n < 0 && (errno == EINTR || errno == EAGAIN)) {
      pollfd p{fd_, POLLOUT, 0};
      ::poll(&p, 1, 100);
      continue;
    }
    if (n <= 0) {
      const std::string why = std::strerror(errno);
      close();
      throw LinkError(device(), "write failed: " + why);
    }
    sent += static_cast<std::size_t>(n);
  }
}

std::optional<std::string> FdTransport::read_line(Clock::time_point deadline) {
  for (;;) {
    const std::size_t eol = buffer_.find_first_of("\r\n");
    if (eol != std::string::npos) {
      std::string line = buffer_.substr(0, eol);
      std::size_t skip = eol + 1;
      if (buffer_[eol] == '\r' && skip < buffer_.size() && buffer_[skip] == '\n') ++skip;
      buffer_.erase(0, skip);
      if (line.empty()) continue;  // "\r\n" split across reads, or blank keep-alives
      return line;
    }
    if (fd_ < 0) throw LinkError(device(), "not connected");
    pollfd p{fd_, POLLIN, 0};
    const int ready = ::poll(&p, 1, millis_until(deadline));
    if (ready < 0 && errno == EINTR) {
      if (Clock::now() >= deadline) return std::nullopt;
      continue;
    }
    if (ready == 0) return std::nullopt;
    char chunk[4096];
    const ssize_t n = ::read(fd_, chunk, sizeof chunk);
    if (n < 0 && (errno == EINTR || errno == EAGAIN)) continue;
    if (n <= 0) {
      // EOF (TCP peer closed) or EIO (the pty's controller side went away, a USB board
      // unplugged): the connection is lost; what was buffered is incomplete.
      const std::string partial = buffer_;
      close();
      throw LinkError(device(), "connection lost", partial);
    }
    buffer_.append(chunk, static_cast<std::size_t>(n));
    if (buffer_.size() > (1u << 16)) {
      // A line this long is not G-code: a wrong baud rate or a binary protocol on the port.
      const std::string head = buffer_.substr(0, 60);
      buffer_.clear();
      throw LinkError(device(), "no line end in 64 KiB of data (wrong baud rate or protocol?)",
                      head);
    }
  }
}

std::optional<std::string> FdTransport::read_some(Clock::time_point deadline) {
  if (!buffer_.empty()) return std::exchange(buffer_, std::string());
  for (;;) {
    if (fd_ < 0) throw LinkError(device(), "not connected");
    pollfd p{fd_, POLLIN, 0};
    const int ready = ::poll(&p, 1, millis_until(deadline));
    if (ready < 0 && errno == EINTR) {
      if (Clock::now() >= deadline) return std::nullopt;
      continue;
    }
    if (ready == 0) return std::nullopt;
    char chunk[8192];
    const ssize_t n = ::read(fd_, chunk, sizeof chunk);
    if (n < 0 && (errno == EINTR || errno == EAGAIN)) continue;
    if (n <= 0) {
      close();
      throw LinkError(device(), "connection lost");
    }
    return std::string(chunk, static_cast<std::size_t>(n));
  }
}

void FdTransport::drain() {
  buffer_.clear();
  if (fd_ < 0) return;
  char chunk[4096];
  for (;;) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, 0) <= 0) return;
    if (::read(fd_, chunk, sizeof chunk) <= 0) return;
  }
}

SerialTransport::SerialTransport(std::string path, int baud) : path_(std::move(path)), baud_(baud) {
  if (baud_constant(baud) == B0)
    throw LinkError(device(),
                    "unsupported baud rate " + std::to_string(baud) +
                        " (termios rates: 9600, 19200, 38400, 57600, 115200, 230400, 460800, "
                        "500000, 921600, 1000000, 2000000, 4000000)");
}

std::string SerialTransport::device() const {
  return "serial " + path_ + " @" + std::to_string(baud_);
}

void SerialTransport::open() {
  close();
  const int fd = ::open(path_.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw LinkError(device(), std::string("cannot open: ") + std::strerror(errno));
  termios tio{};
  if (::tcgetattr(fd, &tio) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    throw LinkError(device(), "not a serial port: " + why);
  }
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= ~static_cast<tcflag_t>(CRTSCTS);
  tio.c_cc[VMIN] = 0;
  tio.c_cc[VTIME] = 0;
  ::cfsetispeed(&tio, baud_constant(baud_));
  ::cfsetospeed(&tio, baud_constant(baud_));
  if (::tcsetattr(fd, TCSANOW, &tio) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    throw LinkError(device(), "cannot configure the port: " + why);
  }
  ::tcflush(fd, TCIOFLUSH);
  fd_ = fd;
}

TcpTransport::TcpTransport(std::string host, int port, std::chrono::milliseconds connect_timeout)
    : host_(std::move(host)), port_(port), connect_timeout_(connect_timeout) {}

std::string TcpTransport::device() const {
  return "tcp " + host_ + ":" + std::to_string(port_);
}

void TcpTransport::open() {
  close();
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  const std::string port = std::to_string(port_);
  const int rc = ::getaddrinfo(host_.c_str(), port.c_str(), &hints, &found);
  if (rc != 0) throw LinkError(device(), std::string("unknown host: ") + ::gai_strerror(rc));
  std::string why = "no address";
  for (addrinfo* a = found; a != nullptr; a = a->ai_next) {
    const int fd =
        ::socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, a->ai_protocol);
    if (fd < 0) continue;
    int r = ::connect(fd, a->ai_addr, a->ai_addrlen);
    if (r < 0 && errno == EINPROGRESS) {
      pollfd p{fd, POLLOUT, 0};
      r = ::poll(&p, 1, static_cast<int>(connect_timeout_.count()));
      int err = 0;
      socklen_t len = sizeof err;
      if (r == 1 && ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len) == 0 && err == 0) {
        r = 0;
      } else {
        why = r == 0 ? "connect timed out" : std::strerror(err != 0 ? err : errno);
        r = -1;
      }
    } else if (r < 0) {
      why = std::strerror(errno);
    }
    if (r == 0) {
      const int one = 1;
      ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);  // one line, one packet
      fd_ = fd;
      ::freeaddrinfo(found);
      return;
    }
    ::close(fd);
  }
  ::freeaddrinfo(found);
  throw LinkError(device(), "cannot connect: " + why);
}

std::unique_ptr<Transport> make_transport(const std::string& address, int baud) {
  if (address.rfind("tcp:", 0) == 0) {
    const std::string rest = address.substr(4);
    const std::size_t colon = rest.rfind(':');
    if (colon == std::string::npos) throw LinkError(address, "expected tcp:HOST:PORT");
    int port = 0;
    try {
      port = std::stoi(rest.substr(colon + 1));
    } catch (const std::exception&) {
      throw LinkError(address, "port is not a number");
    }
    if (port <= 0 || port > 65535) throw LinkError(address, "port out of range");
    return std::make_unique<TcpTransport>(rest.substr(0, colon), port);
  }
  return std::make_unique<SerialTransport>(address, baud);
}

}  // namespace robocal::robotio
