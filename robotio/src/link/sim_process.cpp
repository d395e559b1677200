#include "robocal/robotio/sim_process.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <thread>

extern char** environ;

namespace robocal::robotio {

SimControllerProcess::SimControllerProcess(const std::string& robocal,
                                           const std::vector<std::string>& args,
                                           std::chrono::milliseconds timeout) {
  int pipe_fds[2];
  if (::pipe2(pipe_fds, O_CLOEXEC) != 0)
    throw std::runtime_error(std::string("pipe: ") + std::strerror(errno));
  // Its standard input is a pipe only this process writes to: when this process ends in any way
  // (a crash included) the pipe closes and the simulator exits (--exit-with-parent).
  int parent_fds[2];
  if (::pipe2(parent_fds, O_CLOEXEC) != 0) {
    ::close(pipe_fds[0]);
    ::close(pipe_fds[1]);
    throw std::runtime_error(std::string("pipe: ") + std::strerror(errno));
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, pipe_fds[1], 1);
  posix_spawn_file_actions_adddup2(&actions, parent_fds[0], 0);
  std::vector<std::string> argv_s = {robocal, "sim-controller", "--exit-with-parent"};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::vector<char*> argv;
  argv.reserve(argv_s.size() + 1);
  for (std::string& a : argv_s) argv.push_back(a.data());
  argv.push_back(nullptr);
  const int rc = ::posix_spawn(&pid_, robocal.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  ::close(pipe_fds[1]);
  ::close(parent_fds[0]);
  out_ = pipe_fds[0];
  parent_ = parent_fds[1];
  if (rc != 0) {
    ::close(out_);
    ::close(parent_);
    parent_ = -1;
    throw std::runtime_error(robocal + ": cannot start: " + std::strerror(rc));
  }
  std::string text;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    std::size_t eol;
    while ((eol = text.find('\n')) != std::string::npos) {
      const std::string line = text.substr(0, eol);
      text.erase(0, eol + 1);
      if (line.rfind("tcp ", 0) == 0) tcp_ = "tcp:" + line.substr(4);
      if (line.rfind("pty ", 0) == 0) pty_ = line.substr(4);
      if (line.rfind("pty-link ", 0) == 0) pty_ = line.substr(9);  // survives a re-plug
      if (line.rfind("pose ", 0) == 0) pose_ = line.substr(5);
      if (line.rfind("ur ", 0) == 0) ur_ = line.substr(3);
      if (line == "ready") return;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    pollfd p{out_, POLLIN, 0};
    if (left.count() <= 0 || ::poll(&p, 1, static_cast<int>(left.count())) <= 0) {
      stop();
      throw std::runtime_error("sim-controller did not announce ready within " +
                               std::to_string(timeout.count()) + " ms; it printed: " + text);
    }
    char buf[1024];
    const ssize_t n = ::read(out_, buf, sizeof buf);
    if (n <= 0) {
      const int status = stop();
      throw std::runtime_error("sim-controller exited (status " + std::to_string(status) +
                               ") before ready; it printed: " + text);
    }
    text.append(buf, static_cast<std::size_t>(n));
  }
}

SimControllerProcess::~SimControllerProcess() {
  stop();
}

void SimControllerProcess::signal(int sig) const {
  if (pid_ > 0) ::kill(pid_, sig);
}

int SimControllerProcess::stop(std::chrono::milliseconds timeout) {
  if (out_ >= 0) ::close(out_);
  out_ = -1;
  if (parent_ >= 0) ::close(parent_);
  parent_ = -1;
  if (pid_ <= 0) return -1;
  ::kill(pid_, SIGTERM);
  int status = 0;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const pid_t r = ::waitpid(pid_, &status, WNOHANG);
    if (r == pid_) break;
    if (std::chrono::steady_clock::now() >= deadline) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, &status, 0);
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  pid_ = -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

std::vector<double> simulated_motion_seconds(const std::filesystem::path& log) {
  std::ifstream in(log);
  if (!in) {
    throw std::runtime_error(log.string() + ": cannot read the sim-controller log");
  }
  std::vector<double> seconds;
  for (std::string line; std::getline(in, line);) {
    const nlohmann::json event = nlohmann::json::parse(line, nullptr, false);
    if (event.is_object() && event.value("ev", "") == "motion_start" &&
        !event.value("homing", false)) {
      seconds.push_back(event.value("duration_s", 0.0));
    }
  }
  return seconds;
}

}  // namespace robocal::robotio
