#include "robocal/robotio/camera_v4l2.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <fcntl.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/select.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <utility>

namespace robocal::robotio {
namespace {

std::string fourcc_text(std::uint32_t code) {
  std::string text(4, ' ');
  for (int i = 0; i < 4; ++i) {
    text[static_cast<std::size_t>(i)] = static_cast<char>((code >> (8 * i)) & 0xffU);
  }
  return text;
}

std::uint32_t fourcc_code(const std::string& text) {
  if (text.size() != 4) {
    return 0;
  }
  return v4l2_fourcc(text[0], text[1], text[2], text[3]);
}

unsigned char clamp_byte(double value) {
  return static_cast<unsigned char>(std::clamp(std::lround(value), 0L, 255L));
}

// YUYV (YUV 4:2:2, BT.601 limited range): Y0 U Y1 V for each pair of pixels.
cv::Mat yuyv_to_bgr(const unsigned char* data, int width, int height, std::size_t stride) {
  cv::Mat bgr(height, width, CV_8UC3);
  const auto columns = static_cast<std::size_t>(width);
  for (int row = 0; row < height; ++row) {
    const unsigned char* in = data + static_cast<std::size_t>(row) * stride;
    auto* out = bgr.ptr<unsigned char>(row);
    for (std::size_t col = 0; col < columns; ++col) {
      const std::size_t pair = col / 2;
      const double luma = 1.164383 * (in[pair * 4 + (col % 2) * 2] - 16.0);
      const double u = in[pair * 4 + 1] - 128.0;
      const double v = in[pair * 4 + 3] - 128.0;
      out[col * 3 + 0] = clamp_byte(luma + 2.017232 * u);
      out[col * 3 + 1] = clamp_byte(luma - 0.391762 * u - 0.812968 * v);
      out[col * 3 + 2] = clamp_byte(luma + 1.596027 * v);
    }
  }
  return bgr;
}

cv::Mat yuyv_to_grey(const unsigned char* data, int width, int height, std::size_t stride) {
  cv::Mat grey(height, width, CV_8UC1);
  const auto columns = static_cast<std::size_t>(width);
  for (int row = 0; row < height; ++row) {
    const unsigned char* in = data + static_cast<std::size_t>(row) * stride;
    auto* out = grey.ptr<unsigned char>(row);
    for (std::size_t col = 0; col < columns; ++col) {
      out[col] = in[col * 2];
    }
  }
  return grey;
}

CameraError incomplete(const std::string& camera, const std::string& message) {
  return {CameraError::Kind::kIncompleteFrame, camera, message};
}

}  // namespace

bool v4l2_format_supported(const std::string& fourcc) {
  return fourcc == "GREY" || fourcc == "YUYV" || fourcc == "MJPG";
}

cv::Mat convert_v4l2_frame(const V4l2RawFrame& raw, V4l2Output output, const std::string& camera) {
  if (raw.width <= 0 || raw.height <= 0) {
    throw incomplete(camera, "frame size " + std::to_string(raw.width) + "x" +
                                 std::to_string(raw.height) + " is empty");
  }
  const auto width = static_cast<std::size_t>(raw.width);
  const auto height = static_cast<std::size_t>(raw.height);
  if (raw.fourcc == "GREY" || raw.fourcc == "YUYV") {
    const std::size_t packed = width * (raw.fourcc == "GREY" ? 1U : 2U);
    const std::size_t stride =
        raw.bytes_per_line > 0 ? static_cast<std::size_t>(raw.bytes_per_line) : packed;
    if (stride < packed) {
      throw incomplete(camera, raw.fourcc + " row of " + std::to_string(stride) + " bytes, a " +
                                   std::to_string(width) + " pixel row needs " +
                                   std::to_string(packed));
    }
    const std::size_t needed = stride * (height - 1) + packed;
    if (raw.data.size() < needed) {
      throw incomplete(camera, raw.fourcc + " frame of " + std::to_string(raw.data.size()) +
                                   " bytes, " + std::to_string(width) + "x" +
                                   std::to_string(height) + " needs " + std::to_string(needed) +
                                   " (truncated)");
    }
    if (raw.fourcc == "YUYV" && width % 2 != 0) {
      throw incomplete(camera, "YUYV frame of odd width " + std::to_string(width));
    }
    if (raw.fourcc == "YUYV") {
      return output == V4l2Output::kGrey
                 ? yuyv_to_grey(raw.data.data(), raw.width, raw.height, stride)
                 : yuyv_to_bgr(raw.data.data(), raw.width, raw.height, stride);
    }
    cv::Mat grey(raw.height, raw.width, CV_8UC1);
    for (int row = 0; row < raw.height; ++row) {
      std::memcpy(grey.ptr(row), raw.data.data() + static_cast<std::size_t>(row) * stride, width);
    }
    if (output == V4l2Output::kGrey) {
      return grey;
    }
    cv::Mat bgr;
    cv::cvtColor(grey, bgr, cv::COLOR_GRAY2BGR);
    return bgr;
  }
  if (raw.fourcc == "MJPG") {
    // A UVC MJPEG frame is one baseline JPEG, often without Huffman tables (libjpeg uses the
    // standard ones then). A frame cut short fails to decode or lacks its end marker.
    const bool has_end = raw.data.size() >= 4 && raw.data[raw.data.size() - 2] == 0xff &&
                         raw.data[raw.data.size() - 1] == 0xd9;
    const bool has_start = raw.data.size() >= 2 && raw.data[0] == 0xff && raw.data[1] == 0xd8;
    if (!has_start || !has_end) {
      throw incomplete(camera, "MJPEG frame of " + std::to_string(raw.data.size()) +
                                   " bytes is not a whole JPEG image (" +
                                   (has_start ? "no end marker: truncated" : "no start marker") +
                                   ")");
    }
    const cv::Mat encoded(1, static_cast<int>(raw.data.size()), CV_8UC1,
                          const_cast<unsigned char*>(raw.data.data()));
    cv::Mat image = cv::imdecode(
        encoded, output == V4l2Output::kGrey ? cv::IMREAD_GRAYSCALE : cv::IMREAD_COLOR);
    if (image.empty()) {
      throw incomplete(
          camera, "MJPEG frame of " + std::to_string(raw.data.size()) + " bytes does not decode");
    }
    if (image.cols != raw.width || image.rows != raw.height) {
      throw incomplete(camera, "MJPEG frame decodes to " + std::to_string(image.cols) + "x" +
                                   std::to_string(image.rows) + ", the stream is " +
                                   std::to_string(width) + "x" + std::to_string(height));
    }
    return image;
  }
  throw CameraError(CameraError::Kind::kUnsupported, camera,
                    "pixel format " + raw.fourcc + " cannot be converted (GREY, YUYV or MJPG)");
}

// ---------------------------------------------------------------------------------------------
// Devices

namespace {

int xioctl(int fd, unsigned long request, void* argument) {
  int result = 0;
  do {
    result = ioctl(fd, request, argument);
  } while (result == -1 && errno == EINTR);
  return result;
}

std::vector<std::string> device_formats(int fd) {
  std::vector<std::string> formats;
  v4l2_fmtdesc description{};
  description.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  while (xioctl(fd, VIDIOC_ENUM_FMT, &description) == 0) {
    formats.push_back(fourcc_text(description.pixelformat));
    ++description.index;
  }
  return formats;
}

// Largest frame size the driver lists for a format (discrete or stepwise).
std::pair<int, int> largest_frame_size(int fd, std::uint32_t format) {
  v4l2_frmsizeenum size{};
  size.pixel_format = format;
  std::pair<int, int> best{0, 0};
  while (xioctl(fd, VIDIOC_ENUM_FRAMESIZES, &size) == 0) {
    if (size.type == V4L2_FRMSIZE_TYPE_DISCRETE) {
      const auto w = static_cast<int>(size.discrete.width);
      const auto h = static_cast<int>(size.discrete.height);
      if (w * h > best.first * best.second) {
        best = {w, h};
      }
    } else {
      best = {static_cast<int>(size.stepwise.max_width),
              static_cast<int>(size.stepwise.max_height)};
      break;
    }
    ++size.index;
  }
  return best;
}

bool is_capture_device(const v4l2_capability& caps) {
  const std::uint32_t device_caps =
      (caps.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? caps.device_caps : caps.capabilities;
  return (device_caps & V4L2_CAP_VIDEO_CAPTURE) != 0 && (device_caps & V4L2_CAP_STREAMING) != 0;
}

CameraInfo describe(int fd, const std::string& path, const v4l2_capability& caps) {
  CameraInfo info;
  info.driver = "v4l2";
  info.id = path;
  info.vendor = reinterpret_cast<const char*>(caps.driver);
  info.model = reinterpret_cast<const char*>(caps.card);
  info.address = reinterpret_cast<const char*>(caps.bus_info);
  info.serial = info.address;  // UVC exposes no serial through V4L2; the bus path is stable
  info.pixel_formats = device_formats(fd);
  for (const std::string& format : info.pixel_formats) {
    const auto [w, h] = largest_frame_size(fd, fourcc_code(format));
    info.sensor_width = std::max(info.sensor_width, w);
    info.sensor_height = std::max(info.sensor_height, h);
  }
  return info;
}

}  // namespace

std::vector<DeviceHolder> processes_holding(const std::string& path) {
  namespace fs = std::filesystem;
  std::vector<DeviceHolder> holders;
  std::error_code error;
  const fs::path target = fs::weakly_canonical(path, error);
  if (error) return holders;
  for (const auto& process : fs::directory_iterator("/proc", error)) {
    const std::string pid_text = process.path().filename().string();
    if (pid_text.empty() ||
        !std::all_of(pid_text.begin(), pid_text.end(), [](char c) { return c >= '0' && c <= '9'; }))
      continue;
    std::error_code fd_error;
    bool holds = false;
    // Another user's process (not root) or one that exits meanwhile: its fd folder is skipped.
    for (const auto& fd : fs::directory_iterator(process.path() / "fd", fd_error)) {
      std::error_code link_error;
      const fs::path link = fs::read_symlink(fd.path(), link_error);
      if (!link_error && link == target) {
        holds = true;
        break;
      }
    }
    if (!holds) continue;
    DeviceHolder holder;
    holder.pid = std::stoi(pid_text);
    std::ifstream comm(process.path() / "comm");
    std::getline(comm, holder.command);
    holders.push_back(std::move(holder));
  }
  std::sort(holders.begin(), holders.end(),
            [](const DeviceHolder& a, const DeviceHolder& b) { return a.pid < b.pid; });
  return holders;
}

std::string busy_device_explanation(const std::string& path) {
  std::string others;
  for (const DeviceHolder& h : processes_holding(path)) {
    if (h.pid == static_cast<int>(::getpid())) continue;
    others += (others.empty() ? "" : ", ") + std::string("PID ") + std::to_string(h.pid) + " (" +
              h.command + ")";
  }
  if (others.empty())
    return path +
           " is in use by another process (none found among the processes this user may "
           "inspect in /proc: run `fuser -v " +
           path + "` as root to see it); close that program and run the command again";
  return path + " is in use by another process: " + others +
         " holds it open (an earlier `robocal collect` that has not exited yet, or another camera "
         "program); close that program, or end it with `kill PID`, and run the command again";
}

std::vector<CameraInfo> discover_v4l2_cameras() {
  std::vector<CameraInfo> cameras;
  std::error_code error;
  std::vector<std::string> paths;
  for (const auto& entry : std::filesystem::directory_iterator("/dev", error)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("video", 0) == 0) {
      paths.push_back(entry.path().string());
    }
  }
  std::sort(paths.begin(), paths.end());
  for (const std::string& path : paths) {
    const int fd = ::open(path.c_str(), O_RDWR | O_NONBLOCK);
    if (fd < 0) {
      continue;
    }
    v4l2_capability caps{};
    if (xioctl(fd, VIDIOC_QUERYCAP, &caps) == 0 && is_capture_device(caps)) {
      cameras.push_back(describe(fd, path, caps));
    }
    ::close(fd);
  }
  return cameras;
}

struct V4l2Camera::Impl {
  std::string name;
  std::string path;
  V4l2Output output = V4l2Output::kGrey;
  int fd = -1;
  CameraInfo info;
  struct Mapped {
    void* start = nullptr;
    std::size_t length = 0;
  };
  std::vector<Mapped> buffers;
  bool streaming = false;
  TriggerMode mode = TriggerMode::kFreeRunning;
  std::int64_t triggered_monotonic = 0;  // when trigger() was last called (kSoftware)
  std::int64_t triggered_realtime = 0;
  v4l2_pix_format format{};

  [[nodiscard]] CameraError errno_error(const std::string& what) const {
    const int code = errno;
    // ENODEV / EIO: the USB device went away.
    const CameraError::Kind kind = (code == ENODEV || code == EIO || code == ENXIO)
                                       ? CameraError::Kind::kDisconnected
                                       : CameraError::Kind::kIo;
    // EBUSY: another process streams from the device (or holds its buffers): say which.
    if (code == EBUSY)
      return {kind, name, what + ": " + std::strerror(code) + ": " + busy_device_explanation(path)};
    return {kind, name, what + ": " + std::strerror(code)};
  }
  void require() const {
    if (fd < 0) {
      throw CameraError(CameraError::Kind::kIo, name, "camera already closed");
    }
  }
  void read_format() {
    v4l2_format current{};
    current.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (xioctl(fd, VIDIOC_G_FMT, &current) != 0) {
      throw errno_error("reading the format");
    }
    format = current.fmt.pix;
  }
  void set_control(std::uint32_t id, std::int32_t value, const std::string& what) const {
    require();
    v4l2_queryctrl query{};
    query.id = id;
    if (xioctl(fd, VIDIOC_QUERYCTRL, &query) != 0 || (query.flags & V4L2_CTRL_FLAG_DISABLED) != 0) {
      throw CameraError(CameraError::Kind::kUnsupported, name, "the camera has no " + what);
    }
    if (value < query.minimum || value > query.maximum) {
      throw CameraError(CameraError::Kind::kUnsupported, name,
                        what + " " + std::to_string(value) + " outside the camera's " +
                            std::to_string(query.minimum) + " .. " + std::to_string(query.maximum));
    }
    v4l2_control control{};
    control.id = id;
    control.value = value;
    if (xioctl(fd, VIDIOC_S_CTRL, &control) != 0) {
      throw errno_error("setting " + what);
    }
  }
  [[nodiscard]] std::int32_t get_control(std::uint32_t id, const std::string& what) const {
    require();
    v4l2_control control{};
    control.id = id;
    if (xioctl(fd, VIDIOC_G_CTRL, &control) != 0) {
      throw errno_error("reading " + what);
    }
    return control.value;
  }
  void unmap() {
    for (const Mapped& buffer : buffers) {
      munmap(buffer.start, buffer.length);
    }
    buffers.clear();
    v4l2_requestbuffers request{};
    request.count = 0;
    request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    request.memory = V4L2_MEMORY_MMAP;
    xioctl(fd, VIDIOC_REQBUFS, &request);
  }
};

V4l2Camera::V4l2Camera(const std::string& device, std::string name, V4l2Output output)
    : impl_(std::make_unique<Impl>()) {
  impl_->name = std::move(name);
  impl_->path = device;
  impl_->output = output;
  impl_->fd = ::open(device.c_str(), O_RDWR | O_NONBLOCK);
  if (impl_->fd < 0) {
    const int code = errno;
    throw CameraError(code == ENOENT ? CameraError::Kind::kNotFound : CameraError::Kind::kIo,
                      impl_->name,
                      "cannot open " + device + ": " + std::strerror(code) +
                          (code == EBUSY ? ": " + busy_device_explanation(device) : ""));
  }
  v4l2_capability caps{};
  if (xioctl(impl_->fd, VIDIOC_QUERYCAP, &caps) != 0 || !is_capture_device(caps)) {
    ::close(impl_->fd);
    impl_->fd = -1;
    throw CameraError(CameraError::Kind::kUnsupported, impl_->name,
                      device + " is not a streaming video capture device");
  }
  impl_->info = describe(impl_->fd, device, caps);
  impl_->read_format();
}

V4l2Camera::~V4l2Camera() {
  close();
}

const std::string& V4l2Camera::name() const {
  return impl_->name;
}
CameraInfo V4l2Camera::info() const {
  return impl_->info;
}

void V4l2Camera::set_exposure_us(double exposure_us) {
  impl_->set_control(V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL, "manual exposure mode");
  impl_->set_control(V4L2_CID_EXPOSURE_ABSOLUTE,
                     static_cast<std::int32_t>(std::lround(exposure_us / 100.0)),
                     "exposure (100 us units)");
}
double V4l2Camera::exposure_us() const {
  return 100.0 * impl_->get_control(V4L2_CID_EXPOSURE_ABSOLUTE, "exposure");
}
void V4l2Camera::set_gain(double gain) {
  impl_->set_control(V4L2_CID_GAIN, static_cast<std::int32_t>(std::lround(gain)), "gain");
}
double V4l2Camera::gain() const {
  return impl_->get_control(V4L2_CID_GAIN, "gain");
}

void V4l2Camera::set_pixel_format(const std::string& fourcc) {
  impl_->require();
  const auto& offered = impl_->info.pixel_formats;
  if (std::find(offered.begin(), offered.end(), fourcc) == offered.end()) {
    std::string list;
    for (const std::string& f : offered) {
      list += (list.empty() ? "" : ", ") + f;
    }
    throw CameraError(
        CameraError::Kind::kUnsupported, impl_->name,
        "pixel format " + fourcc + " not offered by the camera (it has " + list + ")");
  }
  if (!v4l2_format_supported(fourcc)) {
    throw CameraError(CameraError::Kind::kUnsupported, impl_->name,
                      "pixel format " + fourcc + " cannot be converted (GREY, YUYV or MJPG)");
  }
  v4l2_format format{};
  format.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  format.fmt.pix = impl_->format;
  format.fmt.pix.pixelformat = fourcc_code(fourcc);
  format.fmt.pix.bytesperline = 0;
  if (xioctl(impl_->fd, VIDIOC_S_FMT, &format) != 0) {
    throw impl_->errno_error("setting pixel format " + fourcc);
  }
  impl_->read_format();
}
std::string V4l2Camera::pixel_format() const {
  return fourcc_text(impl_->format.pixelformat);
}

void V4l2Camera::set_region(const Region& region) {
  impl_->require();
  if (region.x != 0 || region.y != 0) {
    throw CameraError(CameraError::Kind::kUnsupported, impl_->name,
                      "V4L2 frames start at the sensor's corner: region offset must be 0,0");
  }
  v4l2_format format{};
  format.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  format.fmt.pix = impl_->format;
  format.fmt.pix.width = static_cast<std::uint32_t>(region.width);
  format.fmt.pix.height = static_cast<std::uint32_t>(region.height);
  format.fmt.pix.bytesperline = 0;
  if (xioctl(impl_->fd, VIDIOC_S_FMT, &format) != 0) {
    throw impl_->errno_error("setting the frame size");
  }
  impl_->read_format();
  if (static_cast<int>(impl_->format.width) != region.width ||
      static_cast<int>(impl_->format.height) != region.height) {
    throw CameraError(CameraError::Kind::kUnsupported, impl_->name,
                      "frame size " + std::to_string(region.width) + "x" +
                          std::to_string(region.height) + " not offered; the driver chose " +
                          std::to_string(impl_->format.width) + "x" +
                          std::to_string(impl_->format.height));
  }
}
Region V4l2Camera::region() const {
  return {0, 0, static_cast<int>(impl_->format.width), static_cast<int>(impl_->format.height)};
}

void V4l2Camera::start(TriggerMode mode) {
  impl_->require();
  stop();
  impl_->mode = mode;
  v4l2_requestbuffers request{};
  request.count = 4;
  request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  request.memory = V4L2_MEMORY_MMAP;
  if (xioctl(impl_->fd, VIDIOC_REQBUFS, &request) != 0) {
    throw impl_->errno_error("requesting mmap buffers");
  }
  for (std::uint32_t i = 0; i < request.count; ++i) {
    v4l2_buffer buffer{};
    buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer.memory = V4L2_MEMORY_MMAP;
    buffer.index = i;
    if (xioctl(impl_->fd, VIDIOC_QUERYBUF, &buffer) != 0) {
      throw impl_->errno_error("querying buffer " + std::to_string(i));
    }
    void* start = mmap(nullptr, buffer.length, PROT_READ | PROT_WRITE, MAP_SHARED, impl_->fd,
                       buffer.m.offset);
    if (start == MAP_FAILED) {
      throw impl_->errno_error("mapping buffer " + std::to_string(i));
    }
    impl_->buffers.push_back({start, buffer.length});
    if (xioctl(impl_->fd, VIDIOC_QBUF, &buffer) != 0) {
      throw impl_->errno_error("queueing buffer " + std::to_string(i));
    }
  }
  v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(impl_->fd, VIDIOC_STREAMON, &type) != 0) {
    throw impl_->errno_error("starting the stream");
  }
  impl_->streaming = true;
}

void V4l2Camera::trigger() {
  impl_->require();
  // Frames exposed before this call are not the one asked for in kSoftware mode. Drivers stamp
  // with CLOCK_MONOTONIC (flagged) or the wall clock.
  timespec monotonic{};
  clock_gettime(CLOCK_MONOTONIC, &monotonic);
  impl_->triggered_monotonic =
      static_cast<std::int64_t>(monotonic.tv_sec) * 1'000'000'000 + monotonic.tv_nsec;
  impl_->triggered_realtime = host_time_ns();
}

Frame V4l2Camera::receive(std::chrono::milliseconds timeout) {
  impl_->require();
  if (!impl_->streaming) {
    throw CameraError(CameraError::Kind::kIo, impl_->name, "receive before start()");
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  const std::int64_t asked_at_monotonic = impl_->triggered_monotonic;
  const std::int64_t asked_at_realtime = impl_->triggered_realtime;
  while (true) {
    const auto left = std::chrono::duration_cast<std::chrono::microseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      throw CameraError(CameraError::Kind::kTimeout, impl_->name,
                        "no frame within " + std::to_string(timeout.count()) + " ms");
    }
    fd_set readable;
    FD_ZERO(&readable);
    FD_SET(impl_->fd, &readable);
    timeval wait{};
    wait.tv_sec = static_cast<time_t>(left.count() / 1'000'000);
    wait.tv_usec = static_cast<suseconds_t>(left.count() % 1'000'000);
    const int ready = select(impl_->fd + 1, &readable, nullptr, nullptr, &wait);
    if (ready < 0 && errno != EINTR) {
      throw impl_->errno_error("waiting for a frame");
    }
    if (ready <= 0) {
      continue;
    }
    v4l2_buffer buffer{};
    buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer.memory = V4L2_MEMORY_MMAP;
    if (xioctl(impl_->fd, VIDIOC_DQBUF, &buffer) != 0) {
      if (errno == EAGAIN) {
        continue;
      }
      throw impl_->errno_error("dequeuing a frame");
    }
    const Impl::Mapped& mapped = impl_->buffers.at(buffer.index);
    const std::int64_t stamp = static_cast<std::int64_t>(buffer.timestamp.tv_sec) * 1'000'000'000 +
                               static_cast<std::int64_t>(buffer.timestamp.tv_usec) * 1000;
    const bool monotonic_stamp =
        (buffer.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
    const bool stale = impl_->mode == TriggerMode::kSoftware && stamp > 0 &&
                       stamp < (monotonic_stamp ? asked_at_monotonic : asked_at_realtime);
    const bool corrupt = (buffer.flags & V4L2_BUF_FLAG_ERROR) != 0;
    Frame frame;
    std::string problem;
    if (!stale && !corrupt) {
      V4l2RawFrame raw;
      raw.fourcc = fourcc_text(impl_->format.pixelformat);
      raw.width = static_cast<int>(impl_->format.width);
      raw.height = static_cast<int>(impl_->format.height);
      raw.bytes_per_line = static_cast<int>(impl_->format.bytesperline);
      raw.data =
          std::span<const unsigned char>(static_cast<const unsigned char*>(mapped.start),
                                         std::min<std::size_t>(buffer.bytesused, mapped.length));
      try {
        frame.image = convert_v4l2_frame(raw, impl_->output, impl_->name);
      } catch (const CameraError& error) {
        problem = error.what();
      }
      frame.pixel_format = raw.fourcc;
      frame.frame_id = buffer.sequence;
      frame.timestamp_ns = stamp;
      frame.host_time_ns = host_time_ns();
    }
    if (xioctl(impl_->fd, VIDIOC_QBUF, &buffer) != 0) {
      throw impl_->errno_error("requeueing a buffer");
    }
    if (corrupt) {
      throw CameraError(
          CameraError::Kind::kIncompleteFrame, impl_->name,
          "the driver flagged frame " + std::to_string(buffer.sequence) + " as corrupted");
    }
    if (!problem.empty()) {
      throw CameraError(CameraError::Kind::kIncompleteFrame, impl_->name, problem);
    }
    if (!stale) {
      return frame;
    }
  }
}

void V4l2Camera::stop() {
  if (impl_->fd >= 0 && impl_->streaming) {
    v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    xioctl(impl_->fd, VIDIOC_STREAMOFF, &type);
    impl_->streaming = false;
  }
  if (impl_->fd >= 0 && !impl_->buffers.empty()) {
    impl_->unmap();
  }
}

void V4l2Camera::close() {
  if (impl_->fd < 0) {
    return;
  }
  stop();
  ::close(impl_->fd);
  impl_->fd = -1;
}

}  // namespace robocal::robotio
