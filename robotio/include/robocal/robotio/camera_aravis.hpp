#pragma once
// GigE Vision / USB3 Vision cameras through Aravis (0.8): discovery, GenICam features, stream
// buffers, software trigger, timeouts, packet loss and lost cameras.
//
// Every grab has a timeout. When none arrives in time the camera is probed over its control
// channel: a camera that still answers gives CameraError kTimeout, one that does not (or whose
// heartbeat Aravis reported lost) gives kDisconnected. A frame with missing packets (after
// Aravis' own packet resend requests) or of another size than the region set gives
// kIncompleteFrame; its buffer goes back to the stream, so the next grab can retake it.
#include "robocal/robotio/camera_source.hpp"

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace robocal::robotio {

struct AravisOptions {
  int stream_buffers = 4;  // buffers queued for the stream thread
  // GigE Vision packet size: 0 negotiates the largest the path carries (jumbo frames, loopback),
  // which cuts the packets per frame; > 0 sets it.
  int packet_size = 0;
  // Time for one control-channel probe after a grab timed out (Aravis retries inside it).
  std::chrono::milliseconds probe_timeout{500};
};

// Cumulative stream counters (Aravis' own, from the start of the stream).
struct StreamStatistics {
  std::uint64_t completed_frames = 0;
  std::uint64_t failed_frames = 0;    // incomplete, wrong size, aborted
  std::uint64_t underruns = 0;        // no buffer free when a frame arrived
  std::uint64_t resend_requests = 0;  // GigE Vision: packet resend requests sent
  std::uint64_t resent_packets = 0;   // GigE Vision: packets recovered by resend requests
  std::uint64_t missing_packets = 0;  // GigE Vision: packets never received
};

// Cameras Aravis sees now on every interface (GigE Vision on every network interface, USB3
// Vision, and Aravis' in-process fake interface when enabled). Sensor size and pixel formats are
// filled only by opening the camera (AravisCamera::info()).
std::vector<CameraInfo> discover_aravis_cameras();

class AravisCamera final : public CameraSource {
 public:
  // `id_or_serial`: an Aravis device id (as discovered), a serial number, or an IP address of a
  // GigE camera. `name` is how messages and capture call it. Throws CameraError kNotFound (with
  // the list of cameras that were found) or kIo.
  AravisCamera(const std::string& id_or_serial, std::string name, AravisOptions options = {});
  ~AravisCamera() override;

  [[nodiscard]] const std::string& name() const override;
  [[nodiscard]] CameraInfo info() const override;
  void set_exposure_us(double exposure_us) override;
  [[nodiscard]] double exposure_us() const override;
  void set_gain(double gain) override;
  [[nodiscard]] double gain() const override;
  void set_pixel_format(const std::string& format) override;
  [[nodiscard]] std::string pixel_format() const override;
  void set_region(const Region& region) override;
  [[nodiscard]] Region region() const override;
  void start(TriggerMode mode) override;
  void trigger() override;
  Frame receive(std::chrono::milliseconds timeout) override;
  void stop() override;
  void close() override;

  [[nodiscard]] StreamStatistics statistics() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// Pixel formats AravisCamera converts (others are refused by set_pixel_format).
bool aravis_pixel_format_supported(const std::string& format);

}  // namespace robocal::robotio
