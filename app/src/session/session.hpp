#pragma once
// Session folders (format: app/SESSION.md): what was recorded at a cell (session.yaml, the robot
// file, target files, calibration views, one folder per robot pose) plus what robocal computed
// from it (results/) and, for simulated sessions only, the hidden truth (truth/).
//
// Recorded data is written once and never replaced or deleted; results are replaced atomically.
// Every file is written under a temporary name and renamed, so a reader never sees half a file.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace robocal::app {

inline constexpr const char* kSessionFormat = "robocal-session-1";

struct SessionCamera {
  std::string name;
  int width = 0;
  int height = 0;
};

struct Session {
  std::filesystem::path dir;
  std::string format = kSessionFormat;
  std::string software;  // robocal version that recorded it
  std::string created;   // ISO 8601 UTC
  std::string source;    // "simulated" | "recorded"
  // Robot: file (relative to dir), name and actuator count as recorded (checked on load).
  std::string robot_file = "robot.yaml";
  std::string robot_name;
  std::string measured_frame;  // body the end-effector board is fixed to
  int actuators = 0;
  // The designed pose of the end-effector board on the measured frame, as values of that frame's
  // parameters (they replace the robot file's nominal values; the file itself stays the
  // manufacturer's, whose tool frame the closed-form seeds refer to).
  std::vector<std::pair<std::string, double>> target_mount;
  std::vector<SessionCamera> cameras;
  std::string ee_target = "targets/end_effector.yaml";
  std::string calibration_target = "targets/calibration.yaml";
  std::string intrinsics_views = "calibration/intrinsics";  // <camera>/<view>.png
  std::string rig_views = "calibration/rig";                // <view>/<camera>.png
  std::string poses = "poses";                              // <pose>/<camera>[_k].png, pose.yaml
  unsigned seed = 1;  // for anything random done when processing (validation sampling)

  [[nodiscard]] std::filesystem::path path(const std::string& relative) const {
    return dir / relative;
  }
  [[nodiscard]] std::filesystem::path results() const { return dir / "results"; }
  [[nodiscard]] std::filesystem::path truth() const { return dir / "truth"; }
  [[nodiscard]] std::vector<std::string> camera_names() const;
};

// True when `dir` is a folder holding a session.yaml.
bool is_session(const std::filesystem::path& dir);

// Reads dir/session.yaml. Throws InputError("<file>:<line>: <problem>").
Session load_session(const std::filesystem::path& dir);
Session parse_session_yaml(const std::string& text, const std::string& source);
std::string session_to_yaml(const Session& session);

// One robot pose folder: the actuator readings the controller reported and when.
struct PoseRecord {
  std::string name;
  std::filesystem::path dir;
  Eigen::VectorXd actuators;
  double timestamp = 0.0;  // s since the session started
  std::string problem;     // non-empty: the pose cannot be used (missing/malformed pose.yaml)
  // The base -> flange pose the controller reported with the readings (pose.yaml
  // `flange_pose`, recorded by collect from a controller that computes it); none in sessions
  // of controllers that report actuator positions only. A malformed one leaves it empty and
  // says why in `flange_problem`: the readings stay usable.
  std::optional<Eigen::Isometry3d> base_T_flange;
  std::string flange_problem;
};
// Pose sub-folders of the session, sorted by name; a bad pose.yaml gives a record with `problem`.
std::vector<PoseRecord> load_pose_records(const Session& session);
std::string pose_record_yaml(const PoseRecord& pose);

// A recorded image as PNG, written atomically, never over an existing file (core/files.hpp).
void write_image_atomic(const std::filesystem::path& path, const cv::Mat& image);

// Current time, ISO 8601 UTC.
std::string utc_now();

}  // namespace robocal::app
