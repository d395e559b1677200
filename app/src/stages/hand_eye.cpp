#include "stages/hand_eye.hpp"

#include "session/image_folders.hpp"
#include "session/results_layout.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "stages/measure_steps.hpp"

#include "robocal/calib/closure.hpp"

#include "robocal/core/angles.hpp"
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
#include <cmath>
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

// A session camera's intrinsics: calibrated by `robocal measure` from the session's calibration
// views, or else the camera file collect recorded with the session (the cell's, which the
// wizard's intrinsics step calibrated).
fs::path session_camera_file(const Session& session, const std::string& camera,
                             const PipelineLog& log) {
  fs::path measured = ResultsLayout{session.dir}.camera(camera);
  if (fs::exists(measured)) return measured;
  fs::path recorded = session.dir / "cameras" / (camera + ".yaml");
  if (fs::exists(recorded)) {
    fmt::print(log.out, "camera {}: the intrinsics recorded at collection ({})\n", camera,
               recorded.string());
    return recorded;
  }
  throw core::InputError(fmt::format(
      "{}: camera '{}' has no calibrated intrinsics ({}, or {} from collect): run "
      "`robocal measure {}` first, or give --camera",
      session.dir.string(), camera, measured.string(), recorded.string(), session.dir.string()));
}

// The flange pose of every image set of a session (none: why not, in `problems`).
struct SessionFlanges {
  std::vector<std::optional<Eigen::Isometry3d>> poses;
  std::vector<std::string> problems;
};

// The pose's record when it is usable; otherwise nullptr, with an empty pose and the reason in `f`.
const PoseRecord* usable_record(const ImageSet& set,
                                const std::map<std::string, PoseRecord>& records,
                                SessionFlanges& f) {
  const auto it = records.find(set.name);
  if (it != records.end() && it->second.problem.empty()) return &it->second;
  f.poses.emplace_back();
  f.problems.push_back(it == records.end() ? "no pose.yaml" : it->second.problem);
  return nullptr;
}

// The poses the controller reported, when every usable pose has one: what the robot's own
// (calibrated) controller knows beats the robot file's nominal model, but a mix of the two
// frames (flange, measured frame) would be no rigid hand-eye problem.
std::optional<SessionFlanges> reported_flanges(const std::vector<ImageSet>& sets,
                                               const std::map<std::string, PoseRecord>& records) {
  SessionFlanges f;
  for (const ImageSet& set : sets) {
    const PoseRecord* record = usable_record(set, records, f);
    if (record == nullptr) continue;
    if (!record->base_T_flange) return std::nullopt;
    f.poses.push_back(record->base_T_flange);
    f.problems.emplace_back();
  }
  return f;
}

// The measured frame's pose at the robot file's nominal model for the recorded readings.
SessionFlanges nominal_flanges(const std::vector<ImageSet>& sets,
                               const std::map<std::string, PoseRecord>& records,
                               const SessionRobot& robot) {
  SessionFlanges f;
  for (const ImageSet& set : sets) {
    const PoseRecord* record = usable_record(set, records, f);
    if (record == nullptr) continue;
    const auto fk =
        calib::forward_kinematics(robot.model, robot.nominal, record->actuators, robot.frame);
    if (fk.closure.status != calib::SolveStatus::kConverged) {
      f.poses.emplace_back();
      f.problems.emplace_back(
          "the robot file's model cannot place the measured frame for these readings");
      continue;
    }
    f.poses.emplace_back(fk.pose);
    f.problems.emplace_back();
  }
  return f;
}

// The usable poses without a reported flange pose, named (at most a few) for the message.
std::string poses_without_flange(const std::map<std::string, PoseRecord>& records) {
  std::vector<std::string> names;
  for (const auto& [name, r] : records)
    if (r.problem.empty() && !r.base_T_flange)
      names.push_back(r.flange_problem.empty() ? name : r.flange_problem);
  std::string text;
  for (std::size_t i = 0; i < names.size() && i < 3; ++i) text += (i ? "; " : "") + names[i];
  if (names.size() > 3) text += fmt::format(" and {} more", names.size() - 3);
  return fmt::format("{} of {} poses ({})", names.size(), records.size(), text);
}

SessionFlanges session_flanges(const Session& session, const std::vector<ImageSet>& sets,
                               const PipelineLog& log) {
  std::map<std::string, PoseRecord> records;
  for (PoseRecord& r : load_pose_records(session)) records[r.name] = std::move(r);
  if (auto reported = reported_flanges(sets, records)) {
    fmt::print(log.out,
               "flange poses: as the controller reported them (pose.yaml flange_pose): the "
               "camera and board are located relative to its base and flange\n");
    return *reported;
  }
  const SessionRobot robot = session_robot(session, "");
  const bool none = std::none_of(records.begin(), records.end(),
                                 [](const auto& r) { return r.second.base_T_flange.has_value(); });
  fmt::print(log.out,
             "flange poses: {}; the measured frame '{}' at the robot file's nominal model for "
             "the recorded readings is taken as the flange instead\n",
             none ? std::string("the controller reported none")
                  : "no reported flange pose at " + poses_without_flange(records),
             session.measured_frame);
  return nominal_flanges(sets, records, robot);
}

// A session: each camera's first frame at every pose, with the flange the controller reported
// (or the measured frame's nominal pose).
std::vector<HandEyeOutcome> session_hand_eye(const HandEyeRequest& request,
                                             const PipelineLog& log) {
  const Session session = load_session(request.images);
  const vision::TargetBoard board = load_board(session.path(session.ee_target));
  const std::vector<std::string> names = session.camera_names();
  const std::vector<ImageSet> sets = scan_image_folder(session.path(session.poses), names);
  const SessionFlanges flanges = session_flanges(session, sets, log);
  const auto& poses = flanges.poses;
  const auto& problems = flanges.problems;
  std::vector<HandEyeOutcome> out;
  for (std::size_t c = 0; c < names.size(); ++c) {
    const fs::path source =
        request.camera ? *request.camera : session_camera_file(session, names[c], log);
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

std::string transform_line(const char* what, const Eigen::Isometry3d& pose,
                           const core::PoseCovariance& cov) {
  const Eigen::Vector3d t = pose.translation();
  const Eigen::Quaterniond q(pose.linear());
  return fmt::format(
      "  {}: translation ({:.5f}, {:.5f}, {:.5f}) m +- {:.2f} mm, quaternion xyzw ({:.5f}, "
      "{:.5f}, {:.5f}, {:.5f}) +- {:.3f} deg\n",
      what, t.x(), t.y(), t.z(), 1e3 * std::sqrt(cov.topLeftCorner<3, 3>().trace()), q.x(), q.y(),
      q.z(), q.w(), core::degrees(std::sqrt(cov.bottomRightCorner<3, 3>().trace())));
}

}  // namespace

std::string hand_eye_summary(const vision::HandEyeResult& r, const std::string& file) {
  std::string text;
  int used = 0;
  for (const auto& v : r.views) {
    used += v.used ? 1 : 0;
    if (!v.used) text += fmt::format("  {}: not used: {}\n", v.name, v.rejection);
  }
  if (r.status != vision::HandEyeStatus::kOk) return text;
  const bool fixed = r.mount == vision::HandEyeMount::kFixedCamera;
  text += fmt::format("{} of {} views used, reprojection {:.3f} px RMS ({} corners)\n", used,
                      r.views.size(), r.rms_px, r.corners_used);
  text += transform_line(fixed ? "camera in base  " : "camera in flange", r.camera_pose,
                         r.camera_pose_covariance);
  text += transform_line(fixed ? "board in flange " : "board in base   ", r.target_pose,
                         r.target_pose_covariance);
  for (const auto& w : r.warnings) text += fmt::format("warning: {}\n", w);
  text += fmt::format(
      "written: {}\n  {}\n", file,
      vision::ros2_static_transform(r.camera_pose, fixed ? "base" : "flange", "camera"));
  return text;
}

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
