#include "robocal/robotio/camera_fake_gige.hpp"

#include <arv.h>

#include <cstring>
#include <exception>
#include <stdexcept>
#include <string>
#include <utility>

namespace robocal::robotio {
namespace {

std::uint32_t read_register(ArvFakeCamera* fake, std::uint32_t address) {
  guint32 value = 0;
  arv_fake_camera_read_register(fake, address, &value);
  return value;
}

const char* fake_pixel_format_name(ArvPixelFormat format) {
  switch (format) {
    case ARV_PIXEL_FORMAT_MONO_8:
      return "Mono8";
    case ARV_PIXEL_FORMAT_MONO_16:
      return "Mono16";
    case ARV_PIXEL_FORMAT_RGB_8_PACKED:
      return "RGB8";
    default:
      return "other";
  }
}

// Aravis calls this from the fake camera's streaming thread, once per frame.
void fill_callback(ArvBuffer* buffer, void* self, guint32 exposure_us, guint32 gain,
                   ArvPixelFormat pixel_format) {
  FakeGigECamera::fill(buffer, self, exposure_us, gain, pixel_format);
}

}  // namespace

FakeGigECamera::FakeGigECamera(const std::string& address, const std::string& serial,
                               FakeFrameProvider provider)
    : address_(address), serial_(serial), provider_(std::move(provider)) {
  ArvGvFakeCamera* server = arv_gv_fake_camera_new(address.c_str(), serial.c_str());
  if (server == nullptr || arv_gv_fake_camera_is_running(server) == FALSE) {
    if (server != nullptr) {
      g_object_unref(server);
    }
    throw CameraError(CameraError::Kind::kIo, "fake camera " + serial,
                      "cannot serve a fake GigE Vision camera on " + address +
                          " (is that address on a local interface? e.g. ip addr add " + address +
                          "/32 dev lo)");
  }
  server_ = server;
  fake_ = arv_gv_fake_camera_get_fake_camera(server);
  arv_fake_camera_set_fill_pattern(static_cast<ArvFakeCamera*>(fake_), fill_callback, this);
  // In trigger mode the fake camera looks for a software trigger once per "trigger period"
  // (default 25 Hz): up to 40 ms between trigger and exposure that a real camera does not have,
  // and that would be counted as robocal's capture overhead. Not much faster, though: its thread
  // waits out each period in polls of whole milliseconds, and spins (poll with no timeout)
  // through the last one. At 500 Hz that was half a core for every served camera (28 % of all
  // samples in a live Gantry-Tau's collection, taken from the renderer). 100 Hz: at most 10 ms
  // to the exposure, a tenth of a core.
  arv_fake_camera_set_trigger_frequency(static_cast<ArvFakeCamera*>(fake_), 100.0);
}

void FakeGigECamera::set_sensor_size(int width, int height) {
  if (width <= 0 || height <= 0 || width > ARV_FAKE_CAMERA_SENSOR_WIDTH ||
      height > ARV_FAKE_CAMERA_SENSOR_HEIGHT)
    throw std::invalid_argument("fake camera " + serial_ + ": sensor " + std::to_string(width) +
                                "x" + std::to_string(height) + " outside 1x1 .. 2048x2048");
  auto* fake = static_cast<ArvFakeCamera*>(fake_);
  const auto w = static_cast<guint32>(width);
  const auto h = static_cast<guint32>(height);
  arv_fake_camera_write_register(fake, ARV_FAKE_CAMERA_REGISTER_SENSOR_WIDTH, w);
  arv_fake_camera_write_register(fake, ARV_FAKE_CAMERA_REGISTER_SENSOR_HEIGHT, h);
  arv_fake_camera_write_register(fake, ARV_FAKE_CAMERA_REGISTER_X_OFFSET, 0);
  arv_fake_camera_write_register(fake, ARV_FAKE_CAMERA_REGISTER_Y_OFFSET, 0);
  arv_fake_camera_write_register(fake, ARV_FAKE_CAMERA_REGISTER_WIDTH, w);
  arv_fake_camera_write_register(fake, ARV_FAKE_CAMERA_REGISTER_HEIGHT, h);
}

void FakeGigECamera::set_heartbeat_timeout_ms(std::uint32_t timeout_ms) {
  constexpr std::uint32_t kBootstrapHeartbeatTimeout = 0x0938;  // GigE Vision bootstrap register
  arv_fake_camera_write_register(static_cast<ArvFakeCamera*>(fake_), kBootstrapHeartbeatTimeout,
                                 timeout_ms);
}

FakeGigECamera::~FakeGigECamera() {
  disconnect();
}

void FakeGigECamera::disconnect() {
  if (server_ != nullptr) {
    // Joins the fake camera's threads: no callback runs after this.
    g_object_unref(static_cast<ArvGvFakeCamera*>(server_));
    server_ = nullptr;
  }
}

std::string FakeGigECamera::last_error() const {
  const std::lock_guard lock(error_mutex_);
  return last_error_;
}

void FakeGigECamera::fill(void* arv_buffer, void* self_pointer, std::uint32_t exposure_us,
                          std::uint32_t gain, std::uint32_t pixel_format) {
  auto* self = static_cast<FakeGigECamera*>(self_pointer);
  auto* buffer = static_cast<ArvBuffer*>(arv_buffer);
  const auto format = static_cast<ArvPixelFormat>(pixel_format);
  // The buffer reports size 0 until the callback returns; it has room for the whole payload
  // (width x height x bytes per pixel of the current region).
  auto* data = static_cast<unsigned char*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
  FakeFrameRequest request;
  request.region.width = arv_buffer_get_image_width(buffer);
  request.region.height = arv_buffer_get_image_height(buffer);
  auto* fake = static_cast<ArvFakeCamera*>(self->fake_);
  request.region.x = static_cast<int>(read_register(fake, ARV_FAKE_CAMERA_REGISTER_X_OFFSET));
  request.region.y = static_cast<int>(read_register(fake, ARV_FAKE_CAMERA_REGISTER_Y_OFFSET));
  request.pixel_format = fake_pixel_format_name(format);
  request.exposure_us = exposure_us;
  request.gain = gain;
  request.frame_index = self->frames_served_.load();

  const int bytes_per_pixel = format == ARV_PIXEL_FORMAT_MONO_16        ? 2
                              : format == ARV_PIXEL_FORMAT_RGB_8_PACKED ? 3
                                                                        : 1;
  const std::size_t bytes = static_cast<std::size_t>(request.region.width) *
                            static_cast<std::size_t>(request.region.height) *
                            static_cast<std::size_t>(bytes_per_pixel);
  std::string problem;
  cv::Mat image;
  try {
    image = self->provider_(request);
  } catch (const std::exception& error) {
    problem = std::string("frame provider failed: ") + error.what();
  }
  const int expected_type = format == ARV_PIXEL_FORMAT_MONO_16 ? CV_16UC1 : CV_8UC1;
  if (problem.empty() &&
      (format != ARV_PIXEL_FORMAT_MONO_8 && format != ARV_PIXEL_FORMAT_MONO_16)) {
    problem = std::string("pixel format ") + request.pixel_format + " is not served";
  } else if (problem.empty() &&
             (image.rows != request.region.height || image.cols != request.region.width ||
              image.type() != expected_type)) {
    problem = "frame provider returned " + std::to_string(image.cols) + "x" +
              std::to_string(image.rows) + " type " + std::to_string(image.type()) + ", expected " +
              std::to_string(request.region.width) + "x" + std::to_string(request.region.height) +
              " type " + std::to_string(expected_type);
  }
  if (!problem.empty()) {
    std::memset(data, 0, bytes);
    const std::lock_guard lock(self->error_mutex_);
    self->last_error_ = problem;
  } else {
    const std::size_t row_bytes = static_cast<std::size_t>(request.region.width) * bytes_per_pixel;
    for (int row = 0; row < image.rows; ++row) {
      std::memcpy(data + static_cast<std::size_t>(row) * row_bytes, image.ptr(row), row_bytes);
    }
  }
  self->frames_served_.fetch_add(1);
}

}  // namespace robocal::robotio
