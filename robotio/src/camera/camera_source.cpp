#include "robocal/robotio/camera_source.hpp"

#include <ctime>

namespace robocal::robotio {

std::int64_t host_time_ns() {
  timespec now{};
  clock_gettime(CLOCK_REALTIME, &now);
  return static_cast<std::int64_t>(now.tv_sec) * 1'000'000'000 + now.tv_nsec;
}

}  // namespace robocal::robotio
