#include "robocal/vision/camera_parameter_names.hpp"

namespace robocal::vision {

std::vector<std::string> camera_param_names(CameraKind kind) {
  std::vector<std::string> names = {"fx", "fy", "cx", "cy"};
  switch (kind) {
    case CameraKind::kPinholeRadtan:
      for (const char* n : {"k1", "k2", "p1", "p2", "k3"}) names.emplace_back(n);
      break;
    case CameraKind::kPinholeRational:
      for (const char* n : {"k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"}) names.emplace_back(n);
      break;
    case CameraKind::kFisheyeKB4:
      for (const char* n : {"k1", "k2", "k3", "k4"}) names.emplace_back(n);
      break;
  }
  return names;
}

}  // namespace robocal::vision
