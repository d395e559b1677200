#pragma once
// Opening a camera from the text an operator types or a file holds: the one place that knows
// the source kinds robocal reads live frames from.
//
//   aravis:ID       a GigE Vision / USB3 Vision camera through Aravis: its device id (as
//                   `discover_aravis_cameras` lists it), serial number, or IP address
//   v4l2:/dev/videoN  a UVC / V4L2 camera (frames converted to 8-bit grey)
#include "robocal/robotio/camera_source.hpp"

#include <memory>
#include <string>

namespace robocal::robotio {

struct CameraSourceSpec {
  std::string kind;    // "aravis" or "v4l2"
  std::string device;  // what the driver opens
};

// Parses "KIND:DEVICE". Throws std::invalid_argument naming the text and the kinds accepted.
CameraSourceSpec parse_camera_source(const std::string& text);

// Opens the camera `text` names, calling it `name` in messages and files. Throws
// std::invalid_argument (malformed text) or CameraError (not found: the message lists the
// cameras that were found; cannot be opened).
std::unique_ptr<CameraSource> open_camera_source(const std::string& text, const std::string& name);

}  // namespace robocal::robotio
