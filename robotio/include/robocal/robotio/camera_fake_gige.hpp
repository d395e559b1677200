#pragma once
// A GigE Vision camera served in-process by Aravis' fake camera (ArvGvFakeCamera), whose frames
// come from a callback: tests and simulated cells stream rendered images through the real GVCP /
// GVSP protocol, and AravisCamera reads them exactly as from a real camera.
//
// Each fake camera needs its own IP address (two on one address collide: requests for the second
// reach the first). 127.0.0.1 is always there; further loopback addresses (127.0.0.2, ...) need
// `ip addr add 127.0.0.2/32 dev lo`, normally inside a test's own network namespace.
#include "robocal/robotio/camera_source.hpp"

#include <opencv2/core/mat.hpp>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

namespace robocal::robotio {

// What the client asked the fake sensor for, when a frame is due.
struct FakeFrameRequest {
  Region region;             // offset and size on the sensor (at most 2048 x 2048)
  std::string pixel_format;  // "Mono8" or "Mono16" (others are filled with zeros)
  double exposure_us = 0.0;
  double gain = 0.0;
  std::uint64_t frame_index = 0;  // frames served so far by this camera
};

// Returns the frame: region.height x region.width, CV_8UC1 for Mono8, CV_16UC1 for Mono16. An
// image of another size or type is not sent as is: the frame is filled with zeros and the
// problem is kept in FakeGigECamera::last_error().
using FakeFrameProvider = std::function<cv::Mat(const FakeFrameRequest&)>;

class FakeGigECamera {
 public:
  // Starts serving on `address` (an IPv4 address of this host) with the given serial number.
  // Throws CameraError kIo when Aravis cannot start it (address not on this host).
  FakeGigECamera(const std::string& address, const std::string& serial, FakeFrameProvider provider);
  ~FakeGigECamera();
  FakeGigECamera(const FakeGigECamera&) = delete;
  FakeGigECamera& operator=(const FakeGigECamera&) = delete;
  FakeGigECamera(FakeGigECamera&&) = delete;
  FakeGigECamera& operator=(FakeGigECamera&&) = delete;

  [[nodiscard]] const std::string& address() const { return address_; }
  [[nodiscard]] const std::string& serial() const { return serial_; }
  [[nodiscard]] std::uint64_t frames_served() const { return frames_served_.load(); }
  [[nodiscard]] std::string last_error() const;

  // The camera vanishes (cable pulled): it stops answering and streaming. Idempotent.
  void disconnect();

  // The sensor the camera reports (SensorWidth / SensorHeight, at most 2048 x 2048, Aravis'
  // fake sensor), with its region set to the whole of it: a camera whose lens model covers
  // fewer pixels than the fake sensor says so to the clients that ask for the full frame.
  void set_sensor_size(int width, int height);

  // How long the camera keeps a client's control privilege without a heartbeat from it (the
  // GigE Vision heartbeat timeout register; Aravis' fake camera starts with 3000 ms).
  void set_heartbeat_timeout_ms(std::uint32_t timeout_ms);

  // Aravis' fill callback (ArvBuffer*, this, exposure, gain, ArvPixelFormat); not for callers.
  static void fill(void* buffer, void* self, std::uint32_t exposure_us, std::uint32_t gain,
                   std::uint32_t pixel_format);

 private:
  std::string address_;
  std::string serial_;
  FakeFrameProvider provider_;
  std::atomic<std::uint64_t> frames_served_{0};
  mutable std::mutex error_mutex_;
  std::string last_error_;
  void* server_ = nullptr;  // ArvGvFakeCamera*; only the owner's thread touches it
  void* fake_ = nullptr;    // its ArvFakeCamera*, set before the first frame, read by fill()
};

}  // namespace robocal::robotio
