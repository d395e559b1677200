#pragma once
// Synchronised capture of a session's robot poses: at each pose, wait until the robot reports it
// settled, take frames from every camera, reject and retake when the target moved between shots
// (vision's settled-frame test, check_target_still), and record the pose atomically in the
// session format (app/SESSION.md). The first shot of each camera is searched for the target in
// full; the later shots only refine its tags where the first had them (an AprilTag board:
// vision::redetect_apriltag_board), which is all the settled-frame test needs. That test and the
// writing of a pose run while the robot moves on (CaptureOptions::poses_in_flight).
//
// Every file of a pose is written into a staging folder, which is renamed to poses/pose_NNN only
// when complete. A pose folder therefore either exists whole or not at all, and a capture started
// again on the same folder skips the poses already recorded and completes the others (no
// duplicate, no lost pose).
//
// A camera that disappears stops the robot (CaptureRobot::stop) and ends the capture with the
// reason; everything recorded so far stays, and the next run resumes.
#include "robocal/robotio/camera_source.hpp"
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/target.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace robocal::robotio {

// The robot side of capture. LinkCaptureRobot (capture_link.hpp) provides it over a RobotLink:
// move_and_settle = the guarded move_actuators (which returns once the controller reports the
// move finished), read_actuators, stop = the guard's stop request + the controller's stop.
class CaptureRobot {
 public:
  virtual ~CaptureRobot() = default;
  CaptureRobot() = default;
  CaptureRobot(const CaptureRobot&) = delete;
  CaptureRobot& operator=(const CaptureRobot&) = delete;
  CaptureRobot(CaptureRobot&&) = delete;
  CaptureRobot& operator=(CaptureRobot&&) = delete;

  // Moves to `target` (actuator units of the robot file) and returns the controller's readings
  // once it reports the robot settled. Throws (any std::exception) when it cannot.
  virtual Eigen::VectorXd move_and_settle(const Eigen::VectorXd& target) = 0;
  virtual Eigen::VectorXd read_actuators() = 0;
  // The base -> flange pose the controller reported with the last readings (move_and_settle or
  // read_actuators); nullopt when it reports none (robotio::ActuatorReadings::base_T_flange).
  virtual std::optional<Eigen::Isometry3d> flange_pose() const { return std::nullopt; }
  // Stops any motion now and keeps the robot stopped (a camera was lost, a pose failed);
  // `reason` names the pose and the camera.
  virtual void stop(const std::string& reason) = 0;
};

struct CaptureCamera {
  CameraSource* source = nullptr;  // streaming (start() called) in kSoftware mode
  // Intrinsics for the settled-frame test (from the intrinsic calibration before collection);
  // width x height is the size every frame must have.
  vision::CameraModel model;
};

struct PoseCaptureReport;

struct CaptureOptions {
  int shots_per_pose = 2;  // frames per camera per pose; >= 2 for the motion check
  int max_retakes = 3;     // retakes of a pose whose target moved; then recorded as is, flagged
  int frame_retries = 2;   // re-grabs after a timeout or an incomplete frame
  std::chrono::milliseconds grab_timeout{2000};
  double motion_false_alarm = 1e-4;  // of the settled-frame chi-square test
  // Readings after the shots differing from those before by more than this (actuator units):
  // the robot moved during the shots.
  double reading_tolerance = 1e-5;
  std::int64_t session_start_ns = 0;  // pose timestamps are seconds since this (host clock)
  int png_compression = 1;            // 0..9: 1 keeps writing fast (lossless either way)
  // Threads for the settled-frame test and the writing of a pose, which run while the robot moves
  // to the next one: with several cameras one thread outlasts a short move.
  int workers = 2;
  // Poses whose test and writing may still run when the robot is at the next one: with two, a
  // short move is made up by a long one (a camera array's test takes most of an average move,
  // and waiting for it after each short move was most of robocal's time per pose). A pose found
  // moving is taken again all the same: the robot goes back along the moves it made.
  int poses_in_flight = 2;
  // Observers (progress display, tests): every file written into staging (on the writing
  // threads, one call at a time), every pose done.
  std::function<void(const std::filesystem::path&)> on_file_written;
  // Called on the calling thread once a pose is recorded (its folder renamed into place).
  std::function<void(const PoseCaptureReport&)> on_pose_recorded;
};

enum class PoseCaptureStatus { kRecorded, kAlreadyRecorded };

struct PoseCaptureReport {
  int index = 0;
  std::string name;  // pose_NNN
  PoseCaptureStatus status = PoseCaptureStatus::kRecorded;
  int retakes = 0;            // shot series rejected because the target moved
  int frame_retries = 0;      // frames re-grabbed after a timeout / incomplete frame
  bool still_moving = false;  // recorded after max_retakes with the target still moving
  double motion_chi2 = 0.0;   // largest settled-frame chi-square of the recorded series
  std::vector<int> corners;   // per camera: corners detected in the first shot
  double move_s = 0.0;        // move_and_settle (the robot's time)
  double grab_s = 0.0;        // waiting for frames (camera exposure / render / transfer)
  double check_s = 0.0;       // detection and the settled-frame test
  double write_s = 0.0;       // writing the pose folder (images, pose.yaml, rename)
  // Waiting, after this pose's frames were taken, for earlier poses' checks and writing to
  // finish (the oldest, while poses_in_flight are in flight): the part of their check_s and
  // write_s that the motions did not hide.
  double wait_s = 0.0;
};

struct CaptureResult {
  std::vector<PoseCaptureReport> poses;
  bool complete = false;  // every target recorded (now or before)
  // Why the capture stopped early (a lost camera names it); the robot was stopped.
  std::string stop_reason;
  std::optional<CameraError::Kind> camera_error;
  double seconds = 0.0;  // wall time of the capture, from the first move to the last pose written
  [[nodiscard]] int recorded() const;
  [[nodiscard]] int already_recorded() const;
};

// Captures `targets` into session_dir/poses (created if needed). Pose i is named pose_NNN
// (i, 3 digits). `board` is the end-effector target. Throws std::invalid_argument for
// inconsistent arguments (no camera, a camera without source, shots < 1).
CaptureResult capture_poses(const std::filesystem::path& session_dir,
                            const std::vector<Eigen::VectorXd>& targets, CaptureRobot& robot,
                            const std::vector<CaptureCamera>& cameras,
                            const vision::TargetBoard& board, const CaptureOptions& options = {});

// The pose folder name of target i: pose_000, pose_001, ...
std::string pose_folder_name(int index);

}  // namespace robocal::robotio
