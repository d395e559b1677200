#pragma once
// Runs `robocal sim-controller` as a separate process (tests, benches, the demo) and reads the
// endpoints it announces on stdout ("tcp 127.0.0.1:P", "pty /dev/pts/N", "pose 127.0.0.1:P",
// "ur ur:127.0.0.1:R:S:D", "ready"). The process is stopped (SIGTERM, then SIGKILL) when this
// object goes away.
#include <sys/types.h>
#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

namespace robocal::robotio {

class SimControllerProcess {
 public:
  // `robocal` = path of the robocal binary; `args` after "sim-controller". Throws
  // std::runtime_error (with what the process printed) when it does not announce "ready"
  // within `timeout`.
  SimControllerProcess(const std::string& robocal, const std::vector<std::string>& args,
                       std::chrono::milliseconds timeout = std::chrono::milliseconds(20000));
  ~SimControllerProcess();
  SimControllerProcess(const SimControllerProcess&) = delete;
  SimControllerProcess& operator=(const SimControllerProcess&) = delete;

  const std::string& tcp() const { return tcp_; }  // "tcp:127.0.0.1:P" (a link address)
  // "/dev/pts/N", or the stable --pty-link when one was asked for.
  const std::string& pty() const { return pty_; }
  const std::string& pose() const { return pose_; }  // "127.0.0.1:P"
  // --protocol ur: the UR link address of the three ports ("ur:127.0.0.1:R:S:D"), else "".
  const std::string& ur() const { return ur_; }
  pid_t pid() const { return pid_; }
  // Stops the process and returns its exit status (waits at most `timeout`).
  int stop(std::chrono::milliseconds timeout = std::chrono::milliseconds(5000));
  // Sends a signal (e.g. SIGTERM) without waiting.
  void signal(int sig) const;

 private:
  pid_t pid_ = -1;
  int out_ = -1;
  int parent_ = -1;  // write end of the simulator's standard input, never written
  std::string tcp_, pty_, pose_, ur_;
};

// The durations (s) of the motions a sim-controller logged (its --log JSONL file), in order,
// homing left out: the robot's own time, which benches and the live demo subtract from the wall
// time to get robocal's. A line that is not a JSON object (a log cut short while it is written)
// is skipped. Throws std::runtime_error when the file cannot be read.
std::vector<double> simulated_motion_seconds(const std::filesystem::path& log);

}  // namespace robocal::robotio
