#include "cli/pause_key.hpp"

#include "robocal/robotio/stop_signals.hpp"

#include <poll.h>
#include <unistd.h>

#include <cstdio>

namespace robocal::app {

PauseKey::PauseKey() {
  if (::isatty(STDIN_FILENO) == 0 || ::tcgetattr(STDIN_FILENO, &saved_) != 0) return;
  termios raw = saved_;
  raw.c_lflag &= ~static_cast<tcflag_t>(ICANON | ECHO);  // keys one by one, not shown
  raw.c_cc[VMIN] = 0;
  raw.c_cc[VTIME] = 0;
  if (::tcsetattr(STDIN_FILENO, TCSANOW, &raw) != 0) return;
  active_ = true;
  watcher_ = std::thread([this] { watch(); });
}

PauseKey::~PauseKey() {
  if (!active_) return;
  done_ = true;
  watcher_.join();
  ::tcsetattr(STDIN_FILENO, TCSANOW, &saved_);
}

void PauseKey::watch() {
  // Polls with a short timeout so the destructor never waits on a key that does not come.
  while (!done_.load()) {
    pollfd p{STDIN_FILENO, POLLIN, 0};
    if (::poll(&p, 1, 100) <= 0) continue;
    if ((p.revents & (POLLHUP | POLLERR | POLLNVAL)) != 0) return;  // the terminal went away
    char key = 0;
    if ((p.revents & POLLIN) == 0) continue;
    if (::read(STDIN_FILENO, &key, 1) != 1) return;  // end of input: nothing more to watch
    if (key == 'p' || key == 'P' || key == ' ') {
      robotio::StopSignals::toggle_pause();
      // Said at once: the pause itself waits for the pose in progress to be recorded.
      std::fputs(robotio::StopSignals::paused()
                     ? "\r\n[p] pausing after the pose in progress...\r\n"
                     : "\r\n[p] going on...\r\n",
                 stderr);
    }
  }
}

}  // namespace robocal::app
