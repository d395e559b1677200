#include "robocal/robotio/camera_source.hpp"

#include <ctime>

namespace robocal::robotio {

const char* camera_error_kind_name(CameraError::Kind kind) {
  switch (kind) {
    case CameraError::Kind::kNotFound:
      return "not found";
    case CameraError::Kind::kUnsupported:
      return "unsupported";
    case CameraError::Kind::kTimeout:
      return "timeout";
    case CameraError::Kind::kIncompleteFrame:
      return "incomplete frame";
    case CameraError::Kind::kDisconnected:
      return "disconnected";
    case CameraError::Kind::kIo:
      return "i/o error";
  }
  return "error";
}

std::int64_t host_time_ns() {
  timespec now{};
  clock_gettime(CLOCK_REALTIME, &now);
  return static_cast<std::int64_t>(now.tv_sec) * 1'000'000'000 + now.tv_nsec;
}

}  // namespace robocal::robotio
