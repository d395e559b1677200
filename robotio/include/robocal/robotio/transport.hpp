#pragma once
// Line transports to a controller: a serial port (termios, configurable baud; a USB printer
// board or a pseudo-terminal) and TCP (network-attached controllers). Every read takes a
// deadline, so nothing waits forever.
#include <chrono>
#include <memory>
#include <optional>
#include <string>

namespace robocal::robotio {

using Clock = std::chrono::steady_clock;

class Transport {
 public:
  virtual ~Transport() = default;
  // Opens (or re-opens after a loss) the connection. Throws LinkError naming the device.
  virtual void open() = 0;
  virtual void close() = 0;
  virtual bool is_open() const = 0;
  // Writes one line (a '\n' is appended). Throws LinkError when the connection is gone.
  virtual void write_line(const std::string& line) = 0;
  // Next complete line (without "\r\n"), or nullopt when the deadline passes first. Throws
  // LinkError when the connection is closed by the other end.
  virtual std::optional<std::string> read_line(Clock::time_point deadline) = 0;
  // Discards whatever was received and not yet read (stale replies after a reconnect).
  virtual void drain() = 0;
  // "serial /dev/ttyACM0 @115200", "tcp 127.0.0.1:5000": for messages.
  virtual std::string device() const = 0;
};

// Shared line buffering over a file descriptor (serial and TCP both are byte streams).
class FdTransport : public Transport {
 public:
  void close() override;
  bool is_open() const override { return fd_ >= 0; }
  void write_line(const std::string& line) override;
  std::optional<std::string> read_line(Clock::time_point deadline) override;
  void drain() override;
  ~FdTransport() override;
  // Byte streams (binary protocols such as RTDE): all of `data`, and whatever arrived (at least
  // one byte) or nullopt when the deadline passes first. Both throw LinkError like the line forms.
  void write_bytes(const std::string& data);
  std::optional<std::string> read_some(Clock::time_point deadline);

 protected:
  int fd_ = -1;
  std::string buffer_;
};

class SerialTransport final : public FdTransport {
 public:
  // `baud`: one of the standard termios rates (9600 ... 4000000); others throw LinkError.
  SerialTransport(std::string path, int baud);
  void open() override;
  std::string device() const override;

 private:
  std::string path_;
  int baud_;
};

class TcpTransport final : public FdTransport {
 public:
  TcpTransport(std::string host, int port,
               std::chrono::milliseconds connect_timeout = std::chrono::milliseconds(2000));
  void open() override;
  std::string device() const override;

 private:
  std::string host_;
  int port_;
  std::chrono::milliseconds connect_timeout_;
};

// "tcp:HOST:PORT" -> TcpTransport; anything else is a serial device path at `baud`.
std::unique_ptr<Transport> make_transport(const std::string& address, int baud = 115200);

}  // namespace robocal::robotio
