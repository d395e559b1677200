#include "robocal/robotio/camera_open.hpp"

#include "robocal/robotio/camera_aravis.hpp"
#include "robocal/robotio/camera_v4l2.hpp"

#include <stdexcept>

namespace robocal::robotio {

CameraSourceSpec parse_camera_source(const std::string& text) {
  const std::size_t colon = text.find(':');
  const auto malformed = [&](const std::string& why) {
    return std::invalid_argument("camera source '" + text + "': " + why +
                                 " (expected aravis:ID, ID being an Aravis device id, serial "
                                 "number or IP address, or v4l2:/dev/videoN)");
  };
  if (colon == std::string::npos) throw malformed("no kind");
  CameraSourceSpec spec{text.substr(0, colon), text.substr(colon + 1)};
  if (spec.kind != "aravis" && spec.kind != "v4l2")
    throw malformed("unknown kind '" + spec.kind + "'");
  if (spec.device.empty()) throw malformed("no device after '" + spec.kind + ":'");
  return spec;
}

std::unique_ptr<CameraSource> open_camera_source(const std::string& text, const std::string& name) {
  const CameraSourceSpec spec = parse_camera_source(text);
  if (spec.kind == "aravis") return std::make_unique<AravisCamera>(spec.device, name);
  return std::make_unique<V4l2Camera>(spec.device, name);
}

}  // namespace robocal::robotio
