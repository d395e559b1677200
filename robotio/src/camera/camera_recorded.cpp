#include "robocal/robotio/camera_recorded.hpp"

#include <yaml-cpp/yaml.h>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cmath>
#include <system_error>

namespace robocal::robotio {
namespace fs = std::filesystem;

namespace {

YAML::Node load_yaml(const fs::path& file, const std::string& camera) {
  try {
    return YAML::LoadFile(file.string());
  } catch (const YAML::Exception& error) {
    throw CameraError(CameraError::Kind::kIo, camera,
                      file.string() + ":" + std::to_string(error.mark.line + 1) + ": " + error.msg);
  }
}

// The frames of `camera` in one pose folder: <camera>.png, or <camera>_0.png, <camera>_1.png...
std::vector<fs::path> pose_frames(const fs::path& pose_dir, const std::string& camera) {
  std::vector<fs::path> files;
  std::error_code error;
  if (fs::is_regular_file(pose_dir / (camera + ".png"), error)) {
    files.push_back(pose_dir / (camera + ".png"));
    return files;
  }
  for (int k = 0;; ++k) {
    const fs::path file = pose_dir / (camera + "_" + std::to_string(k) + ".png");
    if (!fs::is_regular_file(file, error)) {
      break;
    }
    files.push_back(file);
  }
  return files;
}

}  // namespace

RecordedSessionCamera::RecordedSessionCamera(const fs::path& session_dir, const std::string& camera)
    : name_(camera) {
  const fs::path session_file = session_dir / "session.yaml";
  std::error_code error;
  if (!fs::is_regular_file(session_file, error)) {
    throw CameraError(CameraError::Kind::kNotFound, name_,
                      session_dir.string() + " is not a session folder (no session.yaml)");
  }
  const YAML::Node session = load_yaml(session_file, name_);
  std::string known;
  bool found = false;
  for (const YAML::Node& entry : session["cameras"]) {
    const auto entry_name = entry["name"].as<std::string>("");
    known += (known.empty() ? "" : ", ") + entry_name;
    if (entry_name == camera) {
      width_ = entry["width"].as<int>(0);
      height_ = entry["height"].as<int>(0);
      found = true;
    }
  }
  if (!found) {
    throw CameraError(CameraError::Kind::kNotFound, name_,
                      "no camera '" + camera + "' in " + session_file.string() + " (it has " +
                          (known.empty() ? std::string("none") : known) + ")");
  }
  const std::string poses_folder = session["folders"] && session["folders"]["poses"]
                                       ? session["folders"]["poses"].as<std::string>("poses")
                                       : std::string("poses");
  std::vector<fs::path> pose_dirs;
  for (const auto& entry : fs::directory_iterator(session_dir / poses_folder, error)) {
    if (entry.is_directory()) {
      pose_dirs.push_back(entry.path());
    }
  }
  std::sort(pose_dirs.begin(), pose_dirs.end());
  for (const fs::path& pose_dir : pose_dirs) {
    double timestamp = 0.0;
    if (fs::is_regular_file(pose_dir / "pose.yaml", error)) {
      const YAML::Node pose = load_yaml(pose_dir / "pose.yaml", name_);
      timestamp = pose["timestamp"].as<double>(0.0);
    }
    int shot = 0;
    for (const fs::path& file : pose_frames(pose_dir, camera)) {
      frames_.push_back({file, pose_dir.filename().string(), timestamp, shot++});
    }
  }
  if (frames_.empty()) {
    throw CameraError(CameraError::Kind::kNotFound, name_,
                      "no recorded frame of camera '" + camera + "' under " +
                          (session_dir / poses_folder).string());
  }
  info_.driver = "recorded";
  info_.id = session_dir.string() + ":" + camera;
  info_.model = "recorded session";
  info_.serial = camera;
  info_.address = session_dir.string();
  info_.sensor_width = width_;
  info_.sensor_height = height_;
  info_.pixel_formats = {"Mono8", "Mono16"};
}

void RecordedSessionCamera::refuse(const std::string& what) const {
  throw CameraError(CameraError::Kind::kUnsupported, name_,
                    what + ": a recorded session replays its frames as they were recorded");
}

void RecordedSessionCamera::set_exposure_us(double /*exposure_us*/) {
  refuse("exposure");
}
double RecordedSessionCamera::exposure_us() const {
  return std::nan("");
}
void RecordedSessionCamera::set_gain(double /*gain*/) {
  refuse("gain");
}
double RecordedSessionCamera::gain() const {
  return std::nan("");
}
void RecordedSessionCamera::set_pixel_format(const std::string& format) {
  if (format != pixel_format_) {
    refuse("pixel format " + format);
  }
}
void RecordedSessionCamera::set_region(const Region& region) {
  if (!(region == this->region())) {
    refuse("region");
  }
}
void RecordedSessionCamera::start(TriggerMode /*mode*/) {
  if (closed_) {
    throw CameraError(CameraError::Kind::kIo, name_, "camera already closed");
  }
}

Frame RecordedSessionCamera::receive(std::chrono::milliseconds /*timeout*/) {
  if (closed_) {
    throw CameraError(CameraError::Kind::kIo, name_, "camera already closed");
  }
  if (next_ >= frames_.size()) {
    throw CameraError(CameraError::Kind::kIo, name_,
                      "all " + std::to_string(frames_.size()) + " recorded frames replayed");
  }
  const RecordedFrameFile& recorded = frames_[next_++];
  Frame frame;
  frame.image = cv::imread(recorded.file.string(), cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE);
  if (frame.image.empty()) {
    throw CameraError(CameraError::Kind::kIncompleteFrame, name_,
                      recorded.file.string() + ": unreadable or not an image");
  }
  if (frame.image.cols != width_ || frame.image.rows != height_) {
    throw CameraError(CameraError::Kind::kIncompleteFrame, name_,
                      recorded.file.string() + ": frame is " + std::to_string(frame.image.cols) +
                          "x" + std::to_string(frame.image.rows) + ", session.yaml says " +
                          std::to_string(width_) + "x" + std::to_string(height_));
  }
  pixel_format_ = frame.image.depth() == CV_16U ? "Mono16" : "Mono8";
  frame.pixel_format = pixel_format_;
  frame.frame_id = next_ - 1;
  // The pose's time; several shots of one pose 1 ms apart keep the stamps increasing.
  frame.timestamp_ns = static_cast<std::int64_t>(std::llround(recorded.timestamp_s * 1e9)) +
                       static_cast<std::int64_t>(recorded.shot) * 1'000'000;
  frame.host_time_ns = host_time_ns();
  return frame;
}

}  // namespace robocal::robotio
