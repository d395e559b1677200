#pragma once
// `robocal handeye`'s stage: images of a board + the flange poses the controller reported ->
// where the camera and the board are relative to the robot (vision/hand_eye.hpp), written as
// YAML (vision/hand_eye_io.hpp) only when the estimate is accepted.
#include "stages/stages.hpp"

#include "robocal/vision/hand_eye.hpp"

#include <filesystem>
#include <optional>
#include <string>

namespace robocal::app {

struct HandEyeRequest {
  std::filesystem::path images;                 // folder of images
  std::filesystem::path poses;                  // folder of IMAGE_STEM.yaml or a pairing list
  std::filesystem::path target;                 // board file
  std::optional<std::filesystem::path> camera;  // camera file; none: calibrated from the images
  bool estimate_intrinsics = false;             // refine the intrinsics with the transforms
  vision::HandEyeMount mount = vision::HandEyeMount::kFixedCamera;
  std::filesystem::path out = "handeye.yaml";
};

// The result (status kOk: `out` written; otherwise nothing written, `reason` says why).
vision::HandEyeResult run_hand_eye(const HandEyeRequest& request, const PipelineLog& log);

}  // namespace robocal::app
