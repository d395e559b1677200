#include "robocal/robotio/camera_aravis.hpp"

#include <arv.h>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <mutex>
#include <utility>

namespace robocal::robotio {
namespace {

// GigE Vision bootstrap register: the time (ms) the camera keeps its controller's privilege
// without a heartbeat from it.
constexpr guint64 kHeartbeatTimeoutRegister = 0x0938;

// Aravis (GLib) reports errors through GError; each becomes a CameraError naming the camera.
class GErrorGuard {
 public:
  GErrorGuard() = default;
  GErrorGuard(const GErrorGuard&) = delete;
  GErrorGuard& operator=(const GErrorGuard&) = delete;
  GErrorGuard(GErrorGuard&&) = delete;
  GErrorGuard& operator=(GErrorGuard&&) = delete;
  ~GErrorGuard() { g_clear_error(&error_); }
  GError** out() {
    g_clear_error(&error_);
    return &error_;
  }
  [[nodiscard]] bool failed() const { return error_ != nullptr; }
  // The device did not answer at all (as opposed to refusing the request).
  [[nodiscard]] bool no_answer() const {
    return error_ != nullptr && error_->domain == arv_device_error_quark() &&
           (error_->code == ARV_DEVICE_ERROR_TIMEOUT ||
            error_->code == ARV_DEVICE_ERROR_NOT_CONNECTED ||
            error_->code == ARV_DEVICE_ERROR_TRANSFER_ERROR);
  }
  [[nodiscard]] std::string message() const {
    return error_ != nullptr ? std::string(error_->message) : std::string();
  }
  void check(CameraError::Kind kind, const std::string& camera, const std::string& what) const {
    if (error_ != nullptr) {
      throw CameraError(kind, camera, what + ": " + error_->message);
    }
  }

 private:
  GError* error_ = nullptr;
};

std::string or_empty(const char* text) {
  return text != nullptr ? std::string(text) : std::string();
}

std::vector<std::string> take_strings(const char** strings, guint count) {
  std::vector<std::string> out;
  if (strings == nullptr) {
    return out;
  }
  out.reserve(count);
  for (guint i = 0; i < count; ++i) {
    out.emplace_back(or_empty(strings[i]));
  }
  g_free(static_cast<void*>(strings));
  return out;
}

const char* buffer_status_text(ArvBufferStatus status) {
  switch (status) {
    case ARV_BUFFER_STATUS_SUCCESS:
      return "complete";
    case ARV_BUFFER_STATUS_CLEARED:
      return "cleared";
    case ARV_BUFFER_STATUS_TIMEOUT:
      return "timed out while receiving (packets lost)";
    case ARV_BUFFER_STATUS_MISSING_PACKETS:
      return "missing packets after resend requests";
    case ARV_BUFFER_STATUS_WRONG_PACKET_ID:
      return "wrong packet id";
    case ARV_BUFFER_STATUS_SIZE_MISMATCH:
      return "frame larger than the stream buffer (the region changed?)";
    case ARV_BUFFER_STATUS_FILLING:
      return "still filling";
    case ARV_BUFFER_STATUS_ABORTED:
      return "aborted";
    default:
      return "failed";
  }
}

// Converts one delivered image to the frame types of camera_source.hpp.
cv::Mat convert_buffer(const unsigned char* data, int width, int height, ArvPixelFormat format) {
  switch (format) {
    case ARV_PIXEL_FORMAT_MONO_8:
      return cv::Mat(height, width, CV_8UC1, const_cast<unsigned char*>(data)).clone();
    case ARV_PIXEL_FORMAT_MONO_16:
      return cv::Mat(height, width, CV_16UC1, const_cast<unsigned char*>(data)).clone();
    case ARV_PIXEL_FORMAT_RGB_8_PACKED: {
      cv::Mat bgr;
      cv::cvtColor(cv::Mat(height, width, CV_8UC3, const_cast<unsigned char*>(data)), bgr,
                   cv::COLOR_RGB2BGR);
      return bgr;
    }
    default:
      break;
  }
  // Bayer: OpenCV names the pattern by the second row's first two pixels.
  int code = -1;
  if (format == ARV_PIXEL_FORMAT_BAYER_RG_8) {
    code = cv::COLOR_BayerBG2BGR;
  } else if (format == ARV_PIXEL_FORMAT_BAYER_BG_8) {
    code = cv::COLOR_BayerRG2BGR;
  } else if (format == ARV_PIXEL_FORMAT_BAYER_GR_8) {
    code = cv::COLOR_BayerGB2BGR;
  } else if (format == ARV_PIXEL_FORMAT_BAYER_GB_8) {
    code = cv::COLOR_BayerGR2BGR;
  }
  cv::Mat bgr;
  cv::cvtColor(cv::Mat(height, width, CV_8UC1, const_cast<unsigned char*>(data)), bgr, code);
  return bgr;
}

int bytes_per_pixel(ArvPixelFormat format) {
  return static_cast<int>(ARV_PIXEL_FORMAT_BIT_PER_PIXEL(format) / 8);
}

const std::vector<std::string>& supported_formats() {
  static const std::vector<std::string> formats = {"Mono8",    "Mono16",   "RGB8",    "BayerRG8",
                                                   "BayerBG8", "BayerGR8", "BayerGB8"};
  return formats;
}

}  // namespace

bool aravis_pixel_format_supported(const std::string& format) {
  const auto& formats = supported_formats();
  return std::find(formats.begin(), formats.end(), format) != formats.end();
}

std::vector<CameraInfo> discover_aravis_cameras() {
  arv_update_device_list();
  std::vector<CameraInfo> cameras;
  const unsigned int count = arv_get_n_devices();
  for (unsigned int i = 0; i < count; ++i) {
    CameraInfo info;
    info.driver = "aravis";
    info.id = or_empty(arv_get_device_id(i));
    info.vendor = or_empty(arv_get_device_vendor(i));
    info.model = or_empty(arv_get_device_model(i));
    info.serial = or_empty(arv_get_device_serial_nbr(i));
    info.address = or_empty(arv_get_device_address(i));
    cameras.push_back(std::move(info));
  }
  return cameras;
}

struct AravisCamera::Impl {
  std::string name;
  AravisOptions options;
  ArvCamera* camera = nullptr;
  ArvStream* stream = nullptr;
  TriggerMode mode = TriggerMode::kFreeRunning;
  Region streaming_region;
  ArvPixelFormat streaming_format = ARV_PIXEL_FORMAT_MONO_8;
  std::atomic<bool> control_lost{false};
  gulong control_lost_handler = 0;
  CameraInfo info;

  [[nodiscard]] ArvCamera* require() const {
    if (camera == nullptr) {
      throw CameraError(CameraError::Kind::kIo, name, "camera already closed");
    }
    if (control_lost.load()) {
      throw CameraError(CameraError::Kind::kDisconnected, name,
                        "camera lost (its control channel heartbeat failed)");
    }
    return camera;
  }

  // After a failed feature access or a grab timeout: is the camera still there?
  [[nodiscard]] bool answers() const {
    if (control_lost.load()) {
      return false;
    }
    GErrorGuard error;
    arv_camera_get_integer(camera, "PayloadSize", error.out());
    return !error.failed();
  }

  // A feature access failed: a camera that no longer answers is disconnected, otherwise the
  // failure is about the request itself.
  void fail(const std::string& what, const GErrorGuard& error, CameraError::Kind kind) const {
    // Aravis has already retried a request that got no answer: probing again only adds time.
    if (error.no_answer() || !answers()) {
      throw CameraError(CameraError::Kind::kDisconnected, name,
                        what + ": camera not answering (" + error.message() + ")");
    }
    throw CameraError(kind, name, what + ": " + error.message());
  }

  void release_stream() {
    if (stream != nullptr) {
      GErrorGuard error;
      if (!control_lost.load()) {
        arv_camera_stop_acquisition(camera, error.out());
      }
      g_object_unref(stream);
      stream = nullptr;
    }
  }
};

namespace {

void on_control_lost(ArvDevice* /*device*/, gpointer flag) {
  static_cast<std::atomic<bool>*>(flag)->store(true);
}

}  // namespace

AravisCamera::AravisCamera(const std::string& id_or_serial, std::string name, AravisOptions options)
    : impl_(std::make_unique<Impl>()) {
  impl_->name = std::move(name);
  impl_->options = options;
  // Resolve a serial number or an address to Aravis' device id.
  const std::vector<CameraInfo> found = discover_aravis_cameras();
  std::string device_id;
  for (const CameraInfo& camera : found) {
    if (camera.id == id_or_serial || camera.serial == id_or_serial ||
        camera.address == id_or_serial) {
      device_id = camera.id;
      impl_->info = camera;
      break;
    }
  }
  if (device_id.empty()) {
    std::string list;
    for (const CameraInfo& camera : found) {
      list += (list.empty() ? "" : ", ") + camera.id + " (serial " + camera.serial + " at " +
              camera.address + ")";
    }
    throw CameraError(CameraError::Kind::kNotFound, impl_->name,
                      "no GigE Vision / USB3 Vision camera '" + id_or_serial + "'; found " +
                          (list.empty() ? std::string("none") : list));
  }
  GErrorGuard error;
  impl_->camera = arv_camera_new(device_id.c_str(), error.out());
  if (impl_->camera == nullptr) {
    throw CameraError(CameraError::Kind::kIo, impl_->name,
                      "cannot open " + device_id + ": " + error.message());
  }
  // A GigE Vision camera takes commands from one application at a time (its control channel
  // privilege). Aravis opens a camera another application controls read-only, and the first
  // setting or stream then fails with a protocol error; said here, with what to do.
  if (arv_camera_is_gv_device(impl_->camera) != FALSE &&
      arv_gv_device_is_controller(ARV_GV_DEVICE(arv_camera_get_device(impl_->camera))) == FALSE) {
    GErrorGuard read_error;
    guint32 timeout_ms = 0;
    arv_device_read_register(arv_camera_get_device(impl_->camera), kHeartbeatTimeoutRegister,
                             &timeout_ms, read_error.out());
    const std::string when =
        read_error.failed() || timeout_ms == 0
            ? std::string(
                  "when that application's heartbeat times out (GigE Vision's default: "
                  "3000 ms after its last heartbeat; this camera's value could not be "
                  "read)")
            : "when that application's heartbeat times out, " + std::to_string(timeout_ms) +
                  " ms after its last heartbeat (the camera's heartbeat timeout)";
    g_object_unref(impl_->camera);
    impl_->camera = nullptr;
    throw CameraError(
        CameraError::Kind::kIo, impl_->name,
        "camera " + device_id + " (serial " + impl_->info.serial + " at " + impl_->info.address +
            ") is controlled by another application: the camera takes commands from one "
            "application at a time and refused control to this one. The camera releases it " +
            when + ". If that application is an earlier `robocal collect` that was killed, wait " +
            "that long and run the command again; if it is still running (another robocal, a "
            "camera viewer), close it first");
  }
  impl_->control_lost_handler =
      g_signal_connect(arv_camera_get_device(impl_->camera), "control-lost",
                       G_CALLBACK(on_control_lost), &impl_->control_lost);
  ArvCamera* camera = impl_->camera;
  impl_->info.model = or_empty(arv_camera_get_model_name(camera, error.out()));
  impl_->info.vendor = or_empty(arv_camera_get_vendor_name(camera, error.out()));
  arv_camera_get_sensor_size(camera, &impl_->info.sensor_width, &impl_->info.sensor_height,
                             error.out());
  error.check(CameraError::Kind::kIo, impl_->name, "reading the sensor size");
  guint n_formats = 0;
  const char** formats =
      arv_camera_dup_available_pixel_formats_as_strings(camera, &n_formats, error.out());
  impl_->info.pixel_formats = take_strings(formats, n_formats);
  error.check(CameraError::Kind::kIo, impl_->name, "reading the pixel formats");
}

AravisCamera::~AravisCamera() {
  close();
}

const std::string& AravisCamera::name() const {
  return impl_->name;
}
CameraInfo AravisCamera::info() const {
  return impl_->info;
}

void AravisCamera::set_exposure_us(double exposure_us) {
  ArvCamera* camera = impl_->require();
  GErrorGuard error;
  double low = 0.0;
  double high = 0.0;
  arv_camera_get_exposure_time_bounds(camera, &low, &high, error.out());
  if (error.failed()) {
    impl_->fail("exposure time", error, CameraError::Kind::kUnsupported);
  }
  if (!(exposure_us >= low && exposure_us <= high)) {
    throw CameraError(CameraError::Kind::kUnsupported, impl_->name,
                      "exposure " + std::to_string(exposure_us) + " us outside the camera's " +
                          std::to_string(low) + " .. " + std::to_string(high) + " us");
  }
  arv_camera_set_exposure_time(camera, exposure_us, error.out());
  if (error.failed()) {
    impl_->fail("setting the exposure time", error, CameraError::Kind::kIo);
  }
}

double AravisCamera::exposure_us() const {
  ArvCamera* camera = impl_->require();
  GErrorGuard error;
  const double value = arv_camera_get_exposure_time(camera, error.out());
  if (error.failed()) {
    impl_->fail("reading the exposure time", error, CameraError::Kind::kIo);
  }
  return value;
}

void AravisCamera::set_gain(double gain) {
  ArvCamera* camera = impl_->require();
  GErrorGuard error;
  double low = 0.0;
  double high = 0.0;
  arv_camera_get_gain_bounds(camera, &low, &high, error.out());
  if (error.failed()) {
    impl_->fail("gain", error, CameraError::Kind::kUnsupported);
  }
  if (!(gain >= low && gain <= high)) {
    throw CameraError(CameraError::Kind::kUnsupported, impl_->name,
                      "gain " + std::to_string(gain) + " outside the camera's " +
                          std::to_string(low) + " .. " + std::to_string(high));
  }
  arv_camera_set_gain(camera, gain, error.out());
  if (error.failed()) {
    impl_->fail("setting the gain", error, CameraError::Kind::kIo);
  }
}

double AravisCamera::gain() const {
  ArvCamera* camera = impl_->require();
  GErrorGuard error;
  const double value = arv_camera_get_gain(camera, error.out());
  if (error.failed()) {
    impl_->fail("reading the gain", error, CameraError::Kind::kIo);
  }
  return value;
}

void AravisCamera::set_pixel_format(const std::string& format) {
  ArvCamera* camera = impl_->require();
  const auto& available = impl_->info.pixel_formats;
  if (std::find(available.begin(), available.end(), format) == available.end()) {
    std::string list;
    for (const std::string& name : available) {
      list += (list.empty() ? "" : ", ") + name;
    }
    throw CameraError(
        CameraError::Kind::kUnsupported, impl_->name,
        "pixel format " + format + " not offered by the camera (it has " + list + ")");
  }
  if (!aravis_pixel_format_supported(format)) {
    throw CameraError(CameraError::Kind::kUnsupported, impl_->name,
                      "pixel format " + format +
                          " cannot be converted by robocal (use Mono8, "
                          "Mono16, RGB8 or an 8-bit Bayer format)");
  }
  GErrorGuard error;
  arv_camera_set_pixel_format_from_string(camera, format.c_str(), error.out());
  if (error.failed()) {
    impl_->fail("setting pixel format " + format, error, CameraError::Kind::kIo);
  }
}

std::string AravisCamera::pixel_format() const {
  ArvCamera* camera = impl_->require();
  GErrorGuard error;
  std::string format = or_empty(arv_camera_get_pixel_format_as_string(camera, error.out()));
  if (error.failed()) {
    impl_->fail("reading the pixel format", error, CameraError::Kind::kIo);
  }
  return format;
}

void AravisCamera::set_region(const Region& region) {
  ArvCamera* camera = impl_->require();
  const CameraInfo& info = impl_->info;
  if (region.x < 0 || region.y < 0 || region.width <= 0 || region.height <= 0 ||
      region.x + region.width > info.sensor_width ||
      region.y + region.height > info.sensor_height) {
    throw CameraError(CameraError::Kind::kUnsupported, impl_->name,
                      "region " + std::to_string(region.width) + "x" +
                          std::to_string(region.height) + "+" + std::to_string(region.x) + "+" +
                          std::to_string(region.y) + " outside the " +
                          std::to_string(info.sensor_width) + "x" +
                          std::to_string(info.sensor_height) + " sensor");
  }
  GErrorGuard error;
  arv_camera_set_region(camera, region.x, region.y, region.width, region.height, error.out());
  if (error.failed()) {
    impl_->fail("setting the region", error, CameraError::Kind::kUnsupported);
  }
  const Region now = this->region();
  if (!(now == region)) {
    throw CameraError(CameraError::Kind::kUnsupported, impl_->name,
                      "region " + std::to_string(region.width) + "x" +
                          std::to_string(region.height) + "+" + std::to_string(region.x) + "+" +
                          std::to_string(region.y) + " became " + std::to_string(now.width) + "x" +
                          std::to_string(now.height) + "+" + std::to_string(now.x) + "+" +
                          std::to_string(now.y) + " (the camera's increments)");
  }
}

Region AravisCamera::region() const {
  ArvCamera* camera = impl_->require();
  GErrorGuard error;
  Region region;
  arv_camera_get_region(camera, &region.x, &region.y, &region.width, &region.height, error.out());
  if (error.failed()) {
    impl_->fail("reading the region", error, CameraError::Kind::kIo);
  }
  return region;
}

void AravisCamera::start(TriggerMode mode) {
  ArvCamera* camera = impl_->require();
  impl_->release_stream();
  GErrorGuard error;
  impl_->streaming_region = region();
  impl_->streaming_format = arv_camera_get_pixel_format(camera, error.out());
  if (error.failed()) {
    impl_->fail("reading the pixel format", error, CameraError::Kind::kIo);
  }
  arv_camera_set_acquisition_mode(camera, ARV_ACQUISITION_MODE_CONTINUOUS, error.out());
  if (error.failed()) {
    impl_->fail("continuous acquisition", error, CameraError::Kind::kUnsupported);
  }
  if (mode == TriggerMode::kSoftware) {
    if (arv_camera_is_software_trigger_supported(camera, error.out()) == FALSE) {
      throw CameraError(CameraError::Kind::kUnsupported, impl_->name,
                        "the camera has no software trigger");
    }
    arv_camera_set_trigger(camera, "Software", error.out());
  } else {
    arv_camera_clear_triggers(camera, error.out());
  }
  if (error.failed()) {
    impl_->fail("setting the trigger", error, CameraError::Kind::kUnsupported);
  }
  impl_->mode = mode;
  if (arv_camera_is_gv_device(camera) != FALSE) {
    if (impl_->options.packet_size > 0) {
      arv_camera_gv_set_packet_size(camera, impl_->options.packet_size, error.out());
    } else {
      arv_camera_gv_auto_packet_size(camera, error.out());
    }
    if (error.failed()) {
      impl_->fail("setting the packet size", error, CameraError::Kind::kIo);
    }
  }
  impl_->stream = arv_camera_create_stream(camera, nullptr, nullptr, error.out());
  if (impl_->stream == nullptr) {
    impl_->fail("creating the stream", error, CameraError::Kind::kIo);
  }
  const guint payload = arv_camera_get_payload(camera, error.out());
  if (error.failed()) {
    impl_->fail("reading the payload size", error, CameraError::Kind::kIo);
  }
  for (int i = 0; i < std::max(1, impl_->options.stream_buffers); ++i) {
    arv_stream_push_buffer(impl_->stream, arv_buffer_new_allocate(payload));
  }
  arv_camera_start_acquisition(camera, error.out());
  if (error.failed()) {
    impl_->fail("starting acquisition", error, CameraError::Kind::kIo);
  }
}

void AravisCamera::trigger() {
  ArvCamera* camera = impl_->require();
  if (impl_->stream == nullptr) {
    throw CameraError(CameraError::Kind::kIo, impl_->name, "trigger before start()");
  }
  if (impl_->mode != TriggerMode::kSoftware) {
    return;
  }
  // Frames left from earlier triggers are not the one asked for: give their buffers back.
  while (ArvBuffer* stale = arv_stream_try_pop_buffer(impl_->stream)) {
    arv_stream_push_buffer(impl_->stream, stale);
  }
  GErrorGuard error;
  arv_camera_software_trigger(camera, error.out());
  if (error.failed()) {
    impl_->fail("software trigger", error, CameraError::Kind::kIo);
  }
}

Frame AravisCamera::receive(std::chrono::milliseconds timeout) {
  ArvCamera* camera = impl_->require();
  if (impl_->stream == nullptr) {
    throw CameraError(CameraError::Kind::kIo, impl_->name, "receive before start()");
  }
  const auto timeout_us =
      static_cast<guint64>(std::chrono::duration_cast<std::chrono::microseconds>(timeout).count());
  ArvBuffer* buffer = arv_stream_timeout_pop_buffer(impl_->stream, timeout_us);
  if (buffer == nullptr) {
    if (!impl_->answers()) {
      throw CameraError(CameraError::Kind::kDisconnected, impl_->name,
                        "no frame within " + std::to_string(timeout.count()) +
                            " ms and the camera no longer answers (disconnected?)");
    }
    throw CameraError(CameraError::Kind::kTimeout, impl_->name,
                      "no frame within " + std::to_string(timeout.count()) + " ms");
  }
  // From here the buffer goes back to the stream whatever happens.
  struct Requeue {
    ArvStream* stream;
    ArvBuffer* buffer;
    Requeue(ArvStream* s, ArvBuffer* b) : stream(s), buffer(b) {}
    Requeue(const Requeue&) = delete;
    Requeue& operator=(const Requeue&) = delete;
    Requeue(Requeue&&) = delete;
    Requeue& operator=(Requeue&&) = delete;
    ~Requeue() { arv_stream_push_buffer(stream, buffer); }
  } requeue{impl_->stream, buffer};

  const ArvBufferStatus status = arv_buffer_get_status(buffer);
  if (status != ARV_BUFFER_STATUS_SUCCESS) {
    throw CameraError(CameraError::Kind::kIncompleteFrame, impl_->name,
                      std::string("frame ") + std::to_string(arv_buffer_get_frame_id(buffer)) +
                          " incomplete: " + buffer_status_text(status));
  }
  const int width = arv_buffer_get_image_width(buffer);
  const int height = arv_buffer_get_image_height(buffer);
  const ArvPixelFormat format = arv_buffer_get_image_pixel_format(buffer);
  size_t size = 0;
  const auto* data = static_cast<const unsigned char*>(arv_buffer_get_image_data(buffer, &size));
  const Region& expected = impl_->streaming_region;
  const std::size_t expected_size = static_cast<std::size_t>(expected.width) *
                                    static_cast<std::size_t>(expected.height) *
                                    static_cast<std::size_t>(bytes_per_pixel(format));
  if (width != expected.width || height != expected.height || format != impl_->streaming_format ||
      size < expected_size) {
    throw CameraError(
        CameraError::Kind::kIncompleteFrame, impl_->name,
        "frame of the wrong size: " + std::to_string(width) + "x" + std::to_string(height) + ", " +
            std::to_string(size) + " bytes, expected " + std::to_string(expected.width) + "x" +
            std::to_string(expected.height) + ", " + std::to_string(expected_size) + " bytes");
  }
  Frame frame;
  const char* format_name = arv_camera_get_pixel_format_as_string(camera, nullptr);
  frame.pixel_format = or_empty(format_name);
  frame.image = convert_buffer(data, width, height, format);
  frame.frame_id = arv_buffer_get_frame_id(buffer);
  frame.timestamp_ns = static_cast<std::int64_t>(arv_buffer_get_timestamp(buffer));
  frame.host_time_ns = static_cast<std::int64_t>(arv_buffer_get_system_timestamp(buffer));
  return frame;
}

void AravisCamera::stop() {
  if (impl_->camera != nullptr) {
    impl_->release_stream();
  }
}

void AravisCamera::close() {
  if (impl_->camera == nullptr) {
    return;
  }
  impl_->release_stream();
  if (impl_->control_lost_handler != 0) {
    g_signal_handler_disconnect(arv_camera_get_device(impl_->camera), impl_->control_lost_handler);
  }
  g_object_unref(impl_->camera);
  impl_->camera = nullptr;
}

StreamStatistics AravisCamera::statistics() const {
  StreamStatistics stats;
  if (impl_->stream == nullptr) {
    return stats;
  }
  guint64 completed = 0;
  guint64 failures = 0;
  guint64 underruns = 0;
  arv_stream_get_statistics(impl_->stream, &completed, &failures, &underruns);
  stats.completed_frames = completed;
  stats.failed_frames = failures;
  stats.underruns = underruns;
  if (ARV_IS_GV_STREAM(impl_->stream)) {
    stats.resent_packets = arv_stream_get_info_uint64_by_name(impl_->stream, "n_resent_packets");
    stats.missing_packets = arv_stream_get_info_uint64_by_name(impl_->stream, "n_missing_packets");
    stats.resend_requests = arv_stream_get_info_uint64_by_name(impl_->stream, "n_resend_requests");
  }
  return stats;
}

}  // namespace robocal::robotio
