#pragma once
// Shared by the open link tests: a controller stand-in answering from a function (garbage, an
// old version, wrong fields) on a loopback port.
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <functional>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace robocal::test {

// Answers each line received with `answer(line)` (nothing when it returns ""), one client at a
// time, until destroyed.
class FakeController {
 public:
  explicit FakeController(std::function<std::string(const std::string&)> answer)
      : answer_(std::move(answer)) {
    listen_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::bind(listen_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
        ::listen(listen_, 4) != 0)
      throw std::runtime_error("fake controller: cannot listen");
    socklen_t len = sizeof addr;
    ::getsockname(listen_, reinterpret_cast<sockaddr*>(&addr), &len);
    port_ = ntohs(addr.sin_port);
    thread_ = std::thread([this] { serve(); });
  }
  ~FakeController() {
    stop_ = true;
    thread_.join();
    ::close(listen_);
  }
  FakeController(const FakeController&) = delete;
  FakeController& operator=(const FakeController&) = delete;
  std::string address() const { return "open:127.0.0.1:" + std::to_string(port_); }
  // Lines received so far (for "nothing else was sent" checks).
  std::vector<std::string> received() const {
    const std::lock_guard<std::mutex> lock(mutex_);
    return received_;
  }

 private:
  void serve() {
    int client = -1;
    std::string buffer;
    while (!stop_) {
      pollfd p{client >= 0 ? client : listen_, POLLIN, 0};
      if (::poll(&p, 1, 20) <= 0) continue;
      if (client < 0) {
        client = ::accept(listen_, nullptr, nullptr);
        continue;
      }
      char buf[4096];
      const ssize_t n = ::read(client, buf, sizeof buf);
      if (n <= 0) {
        ::close(client);
        client = -1;
        continue;
      }
      buffer.append(buf, static_cast<std::size_t>(n));
      std::size_t eol;
      while ((eol = buffer.find('\n')) != std::string::npos) {
        const std::string line = buffer.substr(0, eol);
        buffer.erase(0, eol + 1);
        {
          const std::lock_guard<std::mutex> lock(mutex_);
          received_.push_back(line);
        }
        const std::string reply = answer_(line);
        if (reply.empty()) continue;
        const ssize_t written = ::write(client, (reply + "\n").data(), reply.size() + 1);
        (void)written;  // a client that left is noticed by the next read
      }
    }
    if (client >= 0) ::close(client);
  }

  std::function<std::string(const std::string&)> answer_;
  int listen_ = -1;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  mutable std::mutex mutex_;
  std::vector<std::string> received_;
};

}  // namespace robocal::test
