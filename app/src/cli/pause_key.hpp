#pragma once
// The operator's pause key while a robot moves: on a terminal, pressing 'p' (or the space bar)
// toggles the same pause as SIGUSR1 (robotio::StopSignals), honoured between poses. The terminal
// is put in non-canonical, no-echo mode for the lifetime of the object and restored after (also
// when the program stops by an exception). Ctrl-C keeps working: the terminal still turns it
// into SIGINT. Without a terminal on stdin it does nothing (scripts pause with SIGUSR1).
#include <termios.h>

#include <atomic>
#include <thread>

namespace robocal::app {

class PauseKey {
 public:
  PauseKey();
  ~PauseKey();
  PauseKey(const PauseKey&) = delete;
  PauseKey& operator=(const PauseKey&) = delete;
  PauseKey(PauseKey&&) = delete;
  PauseKey& operator=(PauseKey&&) = delete;

  // Whether the key is being watched (stdin is a terminal).
  [[nodiscard]] bool active() const { return active_; }

 private:
  void watch();
  bool active_ = false;
  termios saved_{};
  std::atomic<bool> done_{false};
  std::thread watcher_;
};

}  // namespace robocal::app
