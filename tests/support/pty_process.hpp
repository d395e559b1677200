#pragma once
// A program run on a real pseudo-terminal (forkpty), as an operator at a terminal runs it: the
// test reads what it prints, waits for a prompt, and types keys (Ctrl-C included: the terminal's
// line discipline turns it into SIGINT for the program, as a real terminal does).
#include <poll.h>
#include <pty.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <string>
#include <vector>

namespace robocal::test {

class PtyProcess {
 public:
  PtyProcess(const std::string& program, const std::vector<std::string>& args) {
    std::vector<std::string> all{program};
    all.insert(all.end(), args.begin(), args.end());
    struct winsize ws {};
    ws.ws_row = 50;
    ws.ws_col = 200;
    pid_ = ::forkpty(&master_, nullptr, nullptr, &ws);
    if (pid_ == 0) {
      ::setenv("TERM", "dumb", 1);
      std::vector<char*> argv;
      for (auto& a : all) argv.push_back(a.data());
      argv.push_back(nullptr);
      ::execv(program.c_str(), argv.data());
      ::_exit(127);
    }
  }
  ~PtyProcess() {
    if (pid_ > 0 && !done_) {
      ::kill(pid_, SIGKILL);
      int status = 0;
      ::waitpid(pid_, &status, 0);
    }
    if (master_ >= 0) ::close(master_);
  }
  PtyProcess(const PtyProcess&) = delete;
  PtyProcess& operator=(const PtyProcess&) = delete;
  PtyProcess(PtyProcess&&) = delete;
  PtyProcess& operator=(PtyProcess&&) = delete;

  // Reads until `text` appears after what earlier expects consumed; false after `timeout` or
  // when the program ends without printing it.
  bool expect(const std::string& text, std::chrono::seconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      const auto at = output_.find(text, consumed_);
      if (at != std::string::npos) {
        consumed_ = at + text.size();
        return true;
      }
      if (std::chrono::steady_clock::now() > end || !pump(100)) return false;
    }
  }
  // Types `keys` (a line: end it with "\r", as the Enter key sends).
  void type(const std::string& keys) const { (void)::write(master_, keys.data(), keys.size()); }
  // Waits for the exit (reading what it prints meanwhile); exit code, 128 + signal, or -1.
  int wait(std::chrono::seconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      pump(50);
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        done_ = true;
        while (pump(50)) {
        }
        if (WIFEXITED(status)) return WEXITSTATUS(status);
        if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
        return -1;
      }
    }
    return -1;
  }
  [[nodiscard]] const std::string& output() const { return output_; }

  // Reads what is there within `ms` (a program whose terminal is not read blocks once the
  // terminal's buffer is full); false when the terminal is closed (the program ended).
  bool pump(int ms) {
    struct pollfd p {
      master_, POLLIN, 0
    };
    if (::poll(&p, 1, ms) <= 0) return true;
    char buf[4096];
    const ssize_t n = ::read(master_, buf, sizeof buf);
    if (n <= 0) return false;
    output_.append(buf, static_cast<std::size_t>(n));
    return true;
  }

 private:
  int master_ = -1;
  pid_t pid_ = -1;
  bool done_ = false;
  std::string output_;
  std::size_t consumed_ = 0;
};

}  // namespace robocal::test
