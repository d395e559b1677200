#include "stages/hand_eye.hpp"

#include "session/image_folders.hpp"
#include "session/results_layout.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "stages/measure_steps.hpp"

#include "robocal/calib/closure.hpp"

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

#include <algorithm>
#include <map>

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

// The images of one camera with, for each, its name in messages and the flange pose (none: why
// not, in `problem`).
struct ViewSources {
  std::vector<fs::path> images;
  std::vector<std::string> names;
  std::vector<std::optional<Eigen::Isometry3d>> poses;
  std::vector<std::string> problems;
};

// Detects the board in the images and solves; the views' rejections say why an image gave
// nothing.
vision::HandEyeResult solve_views(const ViewSources& sources, const vision::TargetBoard& board,
                                  std::optional<vision::CameraModel> camera,
                                  const std::string& camera_source, const HandEyeRequest& request,
                                  const PipelineLog& log) {
  const std::vector<fs::path>& images = sources.images;
  std::vector<vision::DetectionRequest> requests;
  for (const fs::path& image : images) {
    vision::DetectionRequest r;
    r.image = image;
    if (camera) {
      r.width = camera->width;
      r.height = camera->height;
      r.expected_by = fmt::format("the camera of {} is calibrated", camera_source);
    }
    requests.push_back(r);
  }
  const auto detections = vision::detect_in_images(requests, board, log.threads);
  if (!camera) camera = camera_from_views(detections, images, log);
  std::vector<vision::HandEyeView> views;
  for (std::size_t i = 0; i < images.size(); ++i) {
    vision::HandEyeView v;
    v.name = sources.names[i];
    if (sources.poses[i]) v.base_T_flange = *sources.poses[i];
    if (detections[i].problem.empty() && sources.poses[i])
      v.frame = vision::camera_frame(detections[i].detection);
    views.push_back(v);
  }
  vision::HandEyeOptions options;
  options.mount = request.mount;
  options.estimate_intrinsics = request.estimate_intrinsics;
  vision::HandEyeResult result =
      vision::calibrate_hand_eye(*camera, board_points(board), views, options);
  // The detector and the pose source know better than "not seen" why a view is missing.
  for (std::size_t i = 0; i < images.size(); ++i) {
    if (!sources.problems[i].empty())
      result.views[i].rejection = sources.problems[i];
    else if (!detections[i].problem.empty())
      result.views[i].rejection = detections[i].problem;
  }
  return result;
}

// A session: each camera's first frame at every pose, the measured frame's nominal pose for the
// recorded readings as the flange.
std::vector<HandEyeOutcome> session_hand_eye(const HandEyeRequest& request,
                                             const PipelineLog& log) {
  const Session session = load_session(request.images);
  const SessionRobot robot = session_robot(session, "");
  const vision::TargetBoard board = load_board(session.path(session.ee_target));
  std::map<std::string, PoseRecord> records;
  for (PoseRecord& r : load_pose_records(session)) records[r.name] = std::move(r);
  const std::vector<std::string> names = session.camera_names();
  const std::vector<ImageSet> sets = scan_image_folder(session.path(session.poses), names);
  std::vector<std::optional<Eigen::Isometry3d>> poses;
  std::vector<std::string> problems;
  for (const ImageSet& set : sets) {
    const auto it = records.find(set.name);
    if (it == records.end() || !it->second.problem.empty()) {
      poses.emplace_back();
      problems.push_back(it == records.end() ? "no pose.yaml" : it->second.problem);
      continue;
    }
    const auto fk =
        calib::forward_kinematics(robot.model, robot.nominal, it->second.actuators, robot.frame);
    if (fk.closure.status != calib::SolveStatus::kConverged) {
      poses.emplace_back();
      problems.emplace_back(
          "the robot file's model cannot place the measured frame for these readings");
      continue;
    }
    poses.emplace_back(fk.pose);
    problems.emplace_back();
  }
  std::vector<HandEyeOutcome> out;
  for (std::size_t c = 0; c < names.size(); ++c) {
    const fs::path camera_file = ResultsLayout{session.dir}.camera(names[c]);
    if (!request.camera && !fs::exists(camera_file))
      throw core::InputError(fmt::format(
          "{}: camera '{}' has no calibrated intrinsics ({}): run `robocal measure {}` first",
          session.dir.string(), names[c], camera_file.string(), session.dir.string()));
    const fs::path source = request.camera ? *request.camera : camera_file;
    ViewSources sources;
    for (std::size_t k = 0; k < sets.size(); ++k) {
      if (sets[k].frames_of_camera[c].empty()) continue;
      sources.images.push_back(sets[k].frames_of_camera[c].front());
      sources.names.push_back(sets[k].name + "/" + sources.images.back().filename().string());
      sources.poses.push_back(poses[k]);
      sources.problems.push_back(problems[k]);
    }
    fmt::print(log.out, "camera {}: {} poses\n", names[c], sources.images.size());
    HandEyeOutcome o;
    o.camera = names[c];
    o.file = names.size() == 1
                 ? request.out
                 : request.out.parent_path() / (request.out.stem().string() + "_" + names[c] +
                                                request.out.extension().string());
    o.result = solve_views(sources, board, vision::load_camera_file(source), source.string(),
                           request, log);
    out.push_back(std::move(o));
  }
  return out;
}

}  // namespace

std::vector<HandEyeOutcome> run_hand_eye(const HandEyeRequest& request, const PipelineLog& log) {
  std::vector<HandEyeOutcome> outcomes;
  if (is_session(request.images)) {
    outcomes = session_hand_eye(request, log);
  } else {
    if (request.poses.empty() || request.target.empty())
      throw core::InputError(fmt::format(
          "{}: an image folder needs --poses and --target (a session folder has its own)",
          request.images.string()));
    ViewSources sources;
    sources.images = vision::list_image_files(request.images);
    if (sources.images.empty())
      throw core::InputError(fmt::format("{}: no images in this folder", request.images.string()));
    for (const auto& p : vision::read_flange_poses(request.poses, sources.images))
      sources.poses.emplace_back(p);
    for (const fs::path& image : sources.images) sources.names.push_back(image.filename().string());
    sources.problems.resize(sources.images.size());
    std::optional<vision::CameraModel> camera;
    if (request.camera) camera = vision::load_camera_file(*request.camera);
    HandEyeOutcome o;
    o.camera = "camera";
    o.file = request.out;
    o.result = solve_views(sources, vision::load_target_file(request.target), camera,
                           request.camera ? request.camera->string() : "", request, log);
    outcomes.push_back(std::move(o));
  }
  // Written only when every camera's estimate was accepted: a partial answer is not written.
  const bool all_ok = std::all_of(outcomes.begin(), outcomes.end(), [](const HandEyeOutcome& o) {
    return o.result.status == vision::HandEyeStatus::kOk;
  });
  if (all_ok)
    for (const HandEyeOutcome& o : outcomes)
      core::write_file_atomic(o.file, vision::hand_eye_to_yaml(o.result));
  return outcomes;
}

}  // namespace robocal::app
