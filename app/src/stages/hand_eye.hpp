#pragma once
// `robocal handeye`'s stage: images of a board + the flange poses the controller reported ->
// where the camera and the board are relative to the robot (vision/hand_eye.hpp), written as
// YAML (vision/hand_eye_io.hpp) only when the estimate is accepted.
//
// Two sources: a folder of images with a pose file per image, or a session folder recorded by
// `robocal collect` / the wizard, whose poses are the measured frame at the robot file's nominal
// model for the actuator readings recorded (a robot trusted as it is) and whose cameras are
// solved one by one with the intrinsics `robocal measure` calibrated.
#include "stages/stages.hpp"

#include "robocal/vision/hand_eye.hpp"

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace robocal::app {

struct HandEyeRequest {
  std::filesystem::path images;  // folder of images, or a session folder
  std::filesystem::path poses;   // folder of IMAGE_STEM.yaml or a pairing list (image folders)
  std::filesystem::path target;  // board file (image folders; a session has its own)
  std::optional<std::filesystem::path> camera;  // camera file; none: calibrated from the images
  bool estimate_intrinsics = false;             // refine the intrinsics with the transforms
  vision::HandEyeMount mount = vision::HandEyeMount::kFixedCamera;
  std::filesystem::path out = "handeye.yaml";
};

// One camera's answer and where it was written (nothing written unless status is kOk).
struct HandEyeOutcome {
  std::string camera;
  std::filesystem::path file;
  vision::HandEyeResult result;
};

std::vector<HandEyeOutcome> run_hand_eye(const HandEyeRequest& request, const PipelineLog& log);

// What a person reads of one answer: the views left out and why, the reprojection, both
// transforms with their 1-sigma, the warnings, the file and the ROS 2 static transform command
// (only the views left out when the estimate was not accepted).
std::string hand_eye_summary(const vision::HandEyeResult& result, const std::string& file);

}  // namespace robocal::app
