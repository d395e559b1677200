#pragma once
// USB / UVC cameras through Video4Linux2: enumeration of /dev/video*, memory-mapped streaming,
// GREY / YUYV / MJPEG conversion, and the exposure, gain and focus controls.
//
// The conversions are pure functions over one raw buffer as the driver hands it over (tested on
// small buffers under testdata/camera/v4l2). V4L2 has no sensor offset here: a region is the
// frame size (x = y = 0), chosen among the sizes the driver lists.
#include "robocal/robotio/camera_source.hpp"

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace robocal::robotio {

// One raw V4L2 buffer: the driver's fourcc ("GREY", "YUYV", "MJPG"), the frame size, the bytes
// per row (GREY / YUYV; 0 = tightly packed) and the bytes used.
struct V4l2RawFrame {
  std::string fourcc;
  int width = 0;
  int height = 0;
  int bytes_per_line = 0;
  std::span<const unsigned char> data;
};

enum class V4l2Output {
  kGrey,    // CV_8UC1: luma (GREY as is, YUYV's Y samples, MJPEG decoded to grey)
  kColour,  // CV_8UC3 BGR (BT.601 limited range for YUYV; GREY replicated)
};

// Converts one buffer. Throws CameraError kIncompleteFrame (naming `camera`) for a buffer shorter
// than its format needs, an MJPEG buffer that does not decode, or a decoded size that differs
// from width x height; kUnsupported for another fourcc.
cv::Mat convert_v4l2_frame(const V4l2RawFrame& raw, V4l2Output output, const std::string& camera);

// The fourccs convert_v4l2_frame accepts.
bool v4l2_format_supported(const std::string& fourcc);

// A process that has a device open: its PID and command name (/proc/PID/comm).
struct DeviceHolder {
  int pid = 0;
  std::string command;
};
// The processes this user may inspect (all of them for root) that have `path` open: every
// /proc/PID/fd link that resolves to the same file as `path`. This process included.
std::vector<DeviceHolder> processes_holding(const std::string& path);
// What a device that answered EBUSY is told with: which other process holds it (PID and
// command, from processes_holding, leaving out this process) and what the operator can do.
std::string busy_device_explanation(const std::string& path);

// Video capture devices under /dev (video0, video1, ...) with their card name, bus and formats.
// Devices that are not capture devices (metadata nodes of UVC cameras) are left out.
std::vector<CameraInfo> discover_v4l2_cameras();

class V4l2Camera final : public CameraSource {
 public:
  // `device`: /dev/videoN. Throws CameraError kNotFound (no such device) or kUnsupported (not a
  // streaming capture device).
  V4l2Camera(const std::string& device, std::string name, V4l2Output output = V4l2Output::kGrey);
  ~V4l2Camera() override;

  [[nodiscard]] const std::string& name() const override;
  [[nodiscard]] CameraInfo info() const override;
  // Exposure in microseconds (V4L2_CID_EXPOSURE_ABSOLUTE counts 100 us; auto exposure is
  // switched to manual first).
  void set_exposure_us(double exposure_us) override;
  [[nodiscard]] double exposure_us() const override;
  void set_gain(double gain) override;  // V4L2_CID_GAIN, driver units
  [[nodiscard]] double gain() const override;
  void set_pixel_format(const std::string& fourcc) override;
  [[nodiscard]] std::string pixel_format() const override;
  void set_region(const Region& region) override;
  [[nodiscard]] Region region() const override;
  // UVC cameras have no software trigger: in kSoftware mode, receive() returns the first frame
  // exposed after trigger(), dropping frames queued before it.
  void start(TriggerMode mode) override;
  void trigger() override;
  Frame receive(std::chrono::milliseconds timeout) override;
  void stop() override;
  void close() override;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace robocal::robotio
