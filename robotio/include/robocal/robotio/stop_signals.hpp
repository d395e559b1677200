#pragma once
// The operator's signals while a robot may move, in one place for every command that drives one
// (collect, the live demo, the wizard): SIGINT (Ctrl-C) and SIGTERM ask the safety guard to stop
// (the link waiting for a move sends the controller's stop and throws MotionInterrupted; every
// pose recorded before stays), a second SIGINT while the first is handled kills the process (an
// operator can always get out), and SIGUSR1 toggles a pause the caller honours between poses.
//
// The handlers only store to atomics (async-signal-safe). No SA_RESTART: a blocking read returns
// EINTR and the link notices the stop at once.
#include "robocal/robotio/safety_guard.hpp"

#include <csignal>

namespace robocal::robotio {

class StopSignals {
 public:
  // Installs the handlers for `guard` (which must outlive this object); the previous handlers
  // come back when it is destroyed. One instance at a time per process.
  explicit StopSignals(SafetyGuard& guard);
  ~StopSignals();
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;
  StopSignals(StopSignals&&) = delete;
  StopSignals& operator=(StopSignals&&) = delete;

  // The signal that asked the stop (SIGINT or SIGTERM), 0 while none did.
  [[nodiscard]] static int stop_signal();
  // Whether the operator paused (SIGUSR1 toggles it; a key binding may call toggle_pause).
  [[nodiscard]] static bool paused();
  static void toggle_pause();

 private:
  struct sigaction old_int_ {};
  struct sigaction old_term_ {};
  struct sigaction old_usr1_ {};
};

}  // namespace robocal::robotio
