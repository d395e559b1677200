#include "stages/hand_eye.hpp"

#include "stages/measure_steps.hpp"

#include "robocal/core/files.hpp"
#include "robocal/core/input_error.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/hand_eye_io.hpp"
#include "robocal/vision/image_detection.hpp"
#include "robocal/vision/intrinsic_calibration.hpp"
#include "robocal/vision/intrinsics_pipeline.hpp"
#include "robocal/vision/target_detection.hpp"
#include "robocal/vision/target_io.hpp"

#include <fmt/core.h>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

// The intrinsics from the same images when no camera file is given: the views where the board
// was found, calibrated as `robocal intrinsics` does.
vision::CameraModel camera_from_views(const std::vector<vision::ImageDetection>& detections,
                                      const std::vector<fs::path>& images, const PipelineLog& log) {
  std::vector<vision::CalibrationView> views;
  int width = 0;
  int height = 0;
  for (std::size_t i = 0; i < detections.size(); ++i) {
    if (!detections[i].problem.empty()) continue;
    views.push_back(
        vision::to_calibration_view(detections[i].detection, images[i].filename().string()));
    width = detections[i].width;
    height = detections[i].height;
  }
  vision::IntrinsicCalibrationOptions options;
  options.width = width;
  options.height = height;
  const auto calibration = vision::calibrate_intrinsics(views, options);
  if (calibration.status != vision::CalibrationStatus::kOk)
    throw core::InputError(fmt::format(
        "the camera's intrinsics cannot be calibrated from these images ({}): give a camera file "
        "(--camera, from `robocal intrinsics`)",
        calibration.reason));
  int used = 0;
  for (const auto& v : calibration.views) used += v.used ? 1 : 0;
  fmt::print(log.out,
             "intrinsics from {} of the images: {:.3f} px RMS (fx {:.1f}, cx {:.1f}, cy {:.1f})\n",
             used, calibration.rms_px, calibration.camera.params[0], calibration.camera.params[2],
             calibration.camera.params[3]);
  return calibration.camera;
}

}  // namespace

vision::HandEyeResult run_hand_eye(const HandEyeRequest& request, const PipelineLog& log) {
  const std::vector<fs::path> images = vision::list_image_files(request.images);
  if (images.empty())
    throw core::InputError(fmt::format("{}: no images in this folder", request.images.string()));
  const std::vector<Eigen::Isometry3d> poses = vision::read_flange_poses(request.poses, images);
  const vision::TargetBoard board = vision::load_target_file(request.target);
  std::optional<vision::CameraModel> camera;
  if (request.camera) camera = vision::load_camera_file(*request.camera);

  std::vector<vision::DetectionRequest> requests;
  for (const fs::path& image : images) {
    vision::DetectionRequest r;
    r.image = image;
    if (camera) {
      r.width = camera->width;
      r.height = camera->height;
      r.expected_by = fmt::format("the camera of {} is calibrated", request.camera->string());
    }
    requests.push_back(r);
  }
  const auto detections = vision::detect_in_images(requests, board, log.threads);
  if (!camera) camera = camera_from_views(detections, images, log);

  std::vector<vision::HandEyeView> views;
  for (std::size_t i = 0; i < images.size(); ++i) {
    vision::HandEyeView v;
    v.name = images[i].filename().string();
    v.base_T_flange = poses[i];
    if (detections[i].problem.empty()) v.frame = vision::camera_frame(detections[i].detection);
    views.push_back(v);
  }
  vision::HandEyeOptions options;
  options.mount = request.mount;
  options.estimate_intrinsics = request.estimate_intrinsics;
  vision::HandEyeResult result =
      vision::calibrate_hand_eye(*camera, board_points(board), views, options);
  // The detector knows better than "not seen" why a board is missing from an image.
  for (std::size_t i = 0; i < images.size(); ++i)
    if (!detections[i].problem.empty()) result.views[i].rejection = detections[i].problem;
  if (result.status == vision::HandEyeStatus::kOk)
    core::write_file_atomic(request.out, vision::hand_eye_to_yaml(result));
  return result;
}

}  // namespace robocal::app
