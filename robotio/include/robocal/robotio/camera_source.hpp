#pragma once
// One interface for every camera robocal captures from: GigE Vision / USB3 Vision cameras through
// Aravis (camera_aravis.hpp), USB/UVC cameras through V4L2 (camera_v4l2.hpp), rendered cameras
// served through Aravis' fake GigE camera (camera_simulated.hpp) and recorded session folders
// (camera_recorded.hpp). Capture (capture.hpp) sees only this interface.
//
// Errors are CameraError exceptions that name the camera and say what kind of failure it was, so
// a caller can act on it: a timeout or an incomplete frame may be retaken, a disconnected camera
// stops the robot and leaves the session resumable.
#include <opencv2/core/mat.hpp>

#include <chrono>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace robocal::robotio {

// What a camera is, as discovery reports it (before or after opening it).
struct CameraInfo {
  std::string driver;  // "aravis", "v4l2", "recorded", "simulated"
  std::string id;      // what open_*() takes: Aravis device id, /dev/videoN, folder:camera
  std::string vendor;
  std::string model;
  std::string serial;
  std::string address;  // network address (GigE), bus info (V4L2), folder (recorded)
  int sensor_width = 0;
  int sensor_height = 0;
  std::vector<std::string> pixel_formats;  // GenICam names: Mono8, Mono16, YUYV, MJPEG, ...
};

// Sensor region of interest, pixels.
struct Region {
  int x = 0;
  int y = 0;
  int width = 0;
  int height = 0;
  bool operator==(const Region&) const = default;
};

// One image as delivered, converted to what the pipeline reads: CV_8UC1 or CV_16UC1 grey, or
// CV_8UC3 BGR for colour formats.
struct Frame {
  cv::Mat image;
  std::string pixel_format;       // the camera's format the image was converted from
  std::uint64_t frame_id = 0;     // the camera's (or stream's) frame counter
  std::int64_t timestamp_ns = 0;  // the camera's clock (device timestamp); 0 if it has none
  std::int64_t host_time_ns = 0;  // host CLOCK_REALTIME when the frame was complete
};

class CameraError : public std::runtime_error {
 public:
  enum class Kind {
    kNotFound,         // no such camera (id, serial, device node, folder)
    kUnsupported,      // a pixel format, region or feature the camera lacks
    kTimeout,          // no frame within the timeout; the camera still answers
    kIncompleteFrame,  // a frame arrived with missing packets / wrong size: retake it
    kDisconnected,     // the camera stopped answering: stop the robot, resume later
    kIo,               // anything else the driver reported
  };
  CameraError(Kind kind, std::string camera, const std::string& message)
      : std::runtime_error(camera + ": " + message), kind_(kind), camera_(std::move(camera)) {}
  [[nodiscard]] Kind kind() const { return kind_; }
  [[nodiscard]] const std::string& camera() const { return camera_; }

 private:
  Kind kind_;
  std::string camera_;
};

enum class TriggerMode {
  kFreeRunning,  // the camera streams at its frame rate; grab() returns the next frame
  kSoftware,     // each grab() sends a software trigger and waits for that frame
};

class CameraSource {
 public:
  virtual ~CameraSource() = default;
  CameraSource() = default;
  CameraSource(const CameraSource&) = delete;
  CameraSource& operator=(const CameraSource&) = delete;
  CameraSource(CameraSource&&) = delete;
  CameraSource& operator=(CameraSource&&) = delete;

  // A short name for messages and file names (e.g. the session's camera name).
  [[nodiscard]] virtual const std::string& name() const = 0;
  [[nodiscard]] virtual CameraInfo info() const = 0;

  // Features. Setters throw CameraError kUnsupported when the camera lacks the feature or the
  // value is outside its range (the message says the range); getters read back what the camera
  // holds now (after its own rounding).
  virtual void set_exposure_us(double exposure_us) = 0;
  [[nodiscard]] virtual double exposure_us() const = 0;
  virtual void set_gain(double gain) = 0;
  [[nodiscard]] virtual double gain() const = 0;
  virtual void set_pixel_format(const std::string& format) = 0;
  [[nodiscard]] virtual std::string pixel_format() const = 0;
  virtual void set_region(const Region& region) = 0;
  [[nodiscard]] virtual Region region() const = 0;

  // Streaming. start() allocates buffers and starts acquisition. trigger() sends a software
  // trigger in kSoftware mode (nothing in kFreeRunning); receive() waits at most `timeout` (never
  // forever) for the next frame. Triggering every camera before receiving from any takes their
  // frames at the same time. grab() is both for one camera.
  virtual void start(TriggerMode mode) = 0;
  virtual void trigger() = 0;
  virtual Frame receive(std::chrono::milliseconds timeout) = 0;
  Frame grab(std::chrono::milliseconds timeout) {
    trigger();
    return receive(timeout);
  }
  virtual void stop() = 0;
  // Releases the device; further calls throw. Safe to call twice.
  virtual void close() = 0;
};

// CLOCK_REALTIME in nanoseconds (host timestamps of frames).
std::int64_t host_time_ns();

}  // namespace robocal::robotio
