#pragma once
// Shared by the open link tests: a controller stand-in answering from a function (garbage, an
// old version, wrong fields) on a loopback port, and a child process whose first output line is
// read (the Python reference adapter announces its port so).
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
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

// A child process with a pipe on its standard input (never written: it can exit when the pipe
// closes) and its standard output read line by line. Killed when destroyed.
class ChildProcess {
 public:
  explicit ChildProcess(const std::vector<std::string>& argv) {
    int in[2], out[2];
    if (::pipe(in) != 0 || ::pipe(out) != 0) throw std::runtime_error("pipe");
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(in[0], STDIN_FILENO);
      ::dup2(out[1], STDOUT_FILENO);
      ::close(in[1]);
      ::close(out[0]);
      std::vector<char*> args;
      for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
      args.push_back(nullptr);
      ::execvp(args[0], args.data());
      ::_exit(127);
    }
    ::close(in[0]);
    ::close(out[1]);
    stdin_ = in[1];
    stdout_ = out[0];
  }
  ~ChildProcess() {
    ::close(stdin_);
    ::kill(pid_, SIGTERM);
    ::waitpid(pid_, nullptr, 0);
    ::close(stdout_);
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  // The next output line ("" when none comes within `timeout`).
  std::string line(std::chrono::milliseconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    std::string s;
    char c = 0;
    while (std::chrono::steady_clock::now() < end) {
      pollfd p{stdout_, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) continue;
      if (::read(stdout_, &c, 1) != 1) break;
      if (c == '\n') return s;
      s += c;
    }
    return "";
  }

 private:
  pid_t pid_ = -1;
  int stdin_ = -1, stdout_ = -1;
};

// Runs a shell command line; returns its exit status and standard output (and error).
struct CommandResult {
  int status = -1;
  std::string output;
};
inline CommandResult run_command(const std::string& command) {
  CommandResult r;
  FILE* p = ::popen((command + " 2>&1 </dev/null").c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
  const int status = ::pclose(p);
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

}  // namespace robocal::test
