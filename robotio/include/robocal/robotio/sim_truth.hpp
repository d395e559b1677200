#pragma once
// The simulated controller's true-pose channel (robotio/README.md, "True-pose channel") as the
// TruePoseSource of simulated cameras: each rendered frame shows the board where the simulated
// robot really is, read from `robocal sim-controller` itself, never from the link or the
// measurement pipeline. Nothing but simulated cameras may use it: it is the hidden truth.
#include "robocal/robotio/camera_simulated.hpp"
#include "robocal/robotio/transport.hpp"

#include <Eigen/Geometry>

#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace robocal::robotio {

// One answer of the channel.
struct TruePoseReading {
  double t = 0.0;                                                 // simulator seconds since start
  bool moving = false;                                            // a motion is running
  long motion = 0;                                                // motions started so far
  std::string frame;                                              // the task frame's body name
  Eigen::Isometry3d base_T_task = Eigen::Isometry3d::Identity();  // true pose, robot base frame
  std::vector<double> actuators_true;                             // physical actuator positions
};

// Parses one reply line. Throws std::runtime_error naming `source` and quoting the line when it
// is not a pose (malformed JSON, missing fields, or the simulator's "error": the true robot
// cannot assemble there).
TruePoseReading parse_true_pose_reply(const std::string& line, const std::string& source);

// Where the board sits in the camera world: the robot base placed in the world, the board
// mounted on the task frame.
struct BoardMounting {
  Eigen::Isometry3d world_T_base = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d task_T_board = Eigen::Isometry3d::Identity();
};

class SimControllerTruth final : public TruePoseSource {
 public:
  // `address` = "HOST:PORT" as sim-controller announces it ("pose 127.0.0.1:P"). Connects at
  // once; throws LinkError naming the channel when it cannot.
  SimControllerTruth(const std::string& address, const BoardMounting& mounting,
                     std::chrono::milliseconds timeout = std::chrono::milliseconds(2000));

  // One round trip (thread-safe: several cameras render at once). Throws std::runtime_error
  // (no answer within the timeout, connection lost, malformed or error reply).
  TruePoseReading read();
  Eigen::Isometry3d world_T_board() override;

 private:
  std::mutex mutex_;
  std::unique_ptr<Transport> channel_;
  BoardMounting mounting_;
  std::chrono::milliseconds timeout_;
};

}  // namespace robocal::robotio
