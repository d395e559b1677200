#pragma once
// A camera that replays a recorded session folder (app/SESSION.md): the frames of one camera
// from poses/pose_NNN/<camera>.png (or <camera>_0.png, <camera>_1.png ...), pose by pose, with
// the pose's recorded timestamp. It lets capture, live checks and tests run on recorded data
// exactly as on a live camera. Exposure, gain, pixel format and region are what was recorded:
// setting another value is refused.
#include "robocal/robotio/camera_source.hpp"

#include <filesystem>
#include <string>
#include <vector>

namespace robocal::robotio {

struct RecordedFrameFile {
  std::filesystem::path file;
  std::string pose;          // pose folder name
  double timestamp_s = 0.0;  // pose.yaml's timestamp (s since the session started)
  int shot = 0;              // index of the frame within its pose
};

class RecordedSessionCamera final : public CameraSource {
 public:
  // Throws CameraError kNotFound when the folder is not a session, the camera is not in its
  // session.yaml (the message lists the cameras), or no pose has a frame of it.
  RecordedSessionCamera(const std::filesystem::path& session_dir, const std::string& camera);

  [[nodiscard]] const std::string& name() const override { return name_; }
  [[nodiscard]] CameraInfo info() const override { return info_; }
  void set_exposure_us(double exposure_us) override;
  [[nodiscard]] double exposure_us() const override;
  void set_gain(double gain) override;
  [[nodiscard]] double gain() const override;
  void set_pixel_format(const std::string& format) override;
  [[nodiscard]] std::string pixel_format() const override { return pixel_format_; }
  void set_region(const Region& region) override;
  [[nodiscard]] Region region() const override { return {0, 0, width_, height_}; }
  void start(TriggerMode mode) override;
  void trigger() override {}
  // The next recorded frame. Throws kIncompleteFrame (an unreadable image, or one of another
  // size than session.yaml says, naming the file) and kIo after the last frame.
  Frame receive(std::chrono::milliseconds timeout) override;
  void stop() override {}
  void close() override { closed_ = true; }

  [[nodiscard]] const std::vector<RecordedFrameFile>& frames() const { return frames_; }
  [[nodiscard]] std::size_t position() const { return next_; }

 private:
  [[noreturn]] void refuse(const std::string& what) const;

  std::string name_;
  CameraInfo info_;
  int width_ = 0;
  int height_ = 0;
  std::string pixel_format_ = "Mono8";
  std::vector<RecordedFrameFile> frames_;
  std::size_t next_ = 0;
  bool closed_ = false;
};

}  // namespace robocal::robotio
