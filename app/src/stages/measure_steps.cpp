#include "stages/measure_steps.hpp"

#include "robocal/core/parallel.hpp"
#include "robocal/vision/image_detection.hpp"
#include "robocal/vision/intrinsics_pipeline.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <atomic>
#include <future>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

// Sets a known corner noise on every detected corner (0 = leave it unknown).
void set_corner_sigma(vision::CameraFrame& frame, const std::vector<double>& sigma_of_camera,
                      std::size_t camera) {
  if (camera >= sigma_of_camera.size()) return;
  for (auto& corner : frame.corners) corner.sigma_px = sigma_of_camera[camera];
}

std::string camera_is_calibrated(const vision::RigCamera& camera) {
  return fmt::format("camera '{}' is calibrated", camera.name);
}

}  // namespace

vision::BoardPoints board_points(const vision::TargetBoard& board) {
  vision::BoardPoints pts;
  for (const auto& c : board.corners) pts[c.id] = c.point;
  return pts;
}

namespace {

// The views of one camera's calibration images (detection only; `result` left empty).
IntrinsicsStep detect_calibration_views(const std::string& camera, int width, int height,
                                        const std::vector<fs::path>& files,
                                        const vision::TargetBoard& board, const StepLog& log) {
  IntrinsicsStep out;
  out.images = files.size();
  std::vector<vision::DetectionRequest> requests;
  requests.reserve(files.size());
  for (const auto& f : files)
    requests.push_back({f, width, height, fmt::format("camera '{}' is recorded", camera)});
  StageProgress bar(log.out, fmt::format("{} intrinsics", camera), files.size());
  const auto detected =
      vision::detect_in_images(requests, board, log.threads, [&] { bar.advance(); });
  for (std::size_t i = 0; i < files.size(); ++i) {
    if (detected[i].problem.empty())
      out.views.push_back(
          vision::to_calibration_view(detected[i].detection, files[i].stem().string()));
    else
      out.problems.push_back(detected[i].problem);
  }
  bar.finish(fmt::format("board found in {} of {} images", out.views.size(), files.size()));
  return out;
}

vision::IntrinsicCalibrationResult calibrate_views(
    const std::vector<vision::CalibrationView>& views, int width, int height) {
  vision::IntrinsicCalibrationOptions options;
  options.width = width;
  options.height = height;
  return vision::calibrate_intrinsics(views, options);
}

}  // namespace

IntrinsicsStep calibrate_camera(const std::string& camera, int width, int height,
                                const std::vector<fs::path>& files,
                                const vision::TargetBoard& board, const StepLog& log) {
  IntrinsicsStep out = detect_calibration_views(camera, width, height, files, board, log);
  out.result = calibrate_views(out.views, width, height);
  return out;
}

std::vector<IntrinsicsStep> calibrate_cameras(const std::vector<CameraViews>& cameras,
                                              const vision::TargetBoard& board,
                                              const StepLog& log) {
  std::vector<IntrinsicsStep> steps;
  steps.reserve(cameras.size());
  for (const auto& c : cameras)
    steps.push_back(detect_calibration_views(c.camera, c.width, c.height, c.files, board, log));
  // Each worker takes the next camera not yet taken; a solve's exception reaches the caller.
  std::atomic<std::size_t> next{0};
  const auto work = [&] {
    for (std::size_t k = next++; k < cameras.size(); k = next++)
      steps[k].result = calibrate_views(steps[k].views, cameras[k].width, cameras[k].height);
  };
  const std::size_t workers =
      std::min<std::size_t>(cameras.size(), static_cast<std::size_t>(std::max(log.threads, 1)));
  std::vector<std::future<void>> running;
  for (std::size_t w = 1; w < workers; ++w) running.push_back(std::async(std::launch::async, work));
  work();
  for (auto& r : running) r.get();
  return steps;
}

RigStep calibrate_rig_from_views(const std::vector<vision::RigCamera>& cameras,
                                 const vision::TargetBoard& board,
                                 const std::vector<ImageSet>& views, const RigStepOptions& options,
                                 const StepLog& log) {
  const std::size_t n_cams = cameras.size();
  RigStep out;
  out.views.assign(views.size(), std::vector<vision::CameraFrame>(n_cams));
  out.problems.assign(views.size(), std::vector<std::string>(n_cams));
  // One detection per (view, camera) with an image: its first frame.
  std::vector<vision::DetectionRequest> requests;
  std::vector<std::pair<std::size_t, std::size_t>> where;
  for (std::size_t v = 0; v < views.size(); ++v)
    for (std::size_t c = 0; c < n_cams; ++c) {
      if (views[v].frames_of_camera[c].empty()) {
        out.problems[v][c] =
            fmt::format("{}: no image for camera '{}'", views[v].name, cameras[c].name);
        continue;
      }
      requests.push_back({views[v].frames_of_camera[c][0], cameras[c].model.width,
                          cameras[c].model.height, camera_is_calibrated(cameras[c])});
      where.emplace_back(v, c);
    }
  StageProgress bar(log.out, "rig views", views.size() * n_cams);
  for (std::size_t missing = requests.size(); missing < views.size() * n_cams; ++missing)
    bar.advance();
  const auto detected =
      vision::detect_in_images(requests, board, log.threads, [&] { bar.advance(); });
  for (std::size_t k = 0; k < requests.size(); ++k) {
    const auto [v, c] = where[k];
    out.problems[v][c] = detected[k].problem;
    if (!detected[k].problem.empty()) continue;
    out.views[v][c] = vision::camera_frame(detected[k].detection);
    set_corner_sigma(out.views[v][c], options.corner_sigma_px, c);
  }
  bar.finish(fmt::format("{} views", views.size()));
  out.result = vision::calibrate_rig(cameras, board_points(board), out.views, options.calibration);
  if (!out.result.ok) {
    // "camera 'left' sees the board in none of the views" is what the calibration sees; why is
    // in each image's problem (an image of another size than the camera file's, unreadable
    // files): a camera none of whose images gave a detection gets its first problem said here.
    for (std::size_t c = 0; c < n_cams; ++c) {
      std::string first;
      std::size_t failed = 0;
      bool detected_any = false;
      for (std::size_t v = 0; v < views.size(); ++v) {
        if (out.problems[v][c].empty()) {
          detected_any = true;
          continue;
        }
        if (first.empty()) first = out.problems[v][c];
        ++failed;
      }
      if (!detected_any && failed > 0)
        out.result.message += fmt::format(
            "\n  camera '{}': {}{}", cameras[c].name, first,
            failed > 1 ? fmt::format(" (and {} more of its {} images)", failed - 1, views.size())
                       : std::string());
    }
  }
  return out;
}

std::vector<PoseImages> measure_board_poses(
    const std::vector<vision::RigCamera>& rig, const vision::TargetBoard& board,
    const std::vector<ImageSet>& poses, const PoseStepOptions& options, const StepLog& log,
    const std::map<std::string, vision::DetectionRecord>* early) {
  const std::size_t n_cams = rig.size();
  std::vector<PoseImages> out(poses.size());
  // One series per pose and camera: its frames show one still view, so after the first the
  // board's tags are refined where they were instead of searched for again.
  struct Series {
    std::size_t pose, camera;
  };
  std::vector<Series> jobs;
  std::vector<std::vector<vision::DetectionRequest>> requests;
  std::size_t images = 0;
  // What collect detected in each pose's images while the robot moved on: taken instead of
  // detecting an unchanged image again (vision/detection_record.hpp).
  const std::string signature =
      vision::detection_signature(board, vision::detector_options_for(board));
  std::vector<vision::DetectionRecord> records(poses.size());
  for (std::size_t p = 0; p < poses.size(); ++p) {
    for (const auto& frames : poses[p].frames_of_camera)
      if (!frames.empty()) {
        records[p] = vision::read_detection_record(
            frames.front().parent_path() / vision::kDetectionRecordFile, signature);
        break;
      }
    if (early == nullptr) continue;
    if (const auto e = early->find(poses[p].name); e != early->end())
      records[p].insert(e->second.begin(), e->second.end());  // the folder's own entries first
  }
  for (std::size_t p = 0; p < poses.size(); ++p) {
    std::size_t n_frames = 0;
    for (std::size_t c = 0; c < n_cams; ++c) {
      if (poses[p].frames_of_camera[c].empty())
        out[p].problems.push_back(
            fmt::format("{}: no image for camera '{}'", poses[p].name, rig[c].name));
      n_frames = std::max(n_frames, poses[p].frames_of_camera[c].size());
    }
    out[p].frames.assign(n_frames, std::vector<vision::CameraFrame>(n_cams));
    for (std::size_t c = 0; c < n_cams; ++c) {
      if (poses[p].frames_of_camera[c].empty()) continue;
      jobs.push_back({p, c});
      requests.emplace_back();
      for (const auto& file : poses[p].frames_of_camera[c])
        requests.back().push_back({file, rig[c].model.width, rig[c].model.height,
                                   camera_is_calibrated(rig[c]), &records[p]});
      images += requests.back().size();
    }
  }
  StageProgress bar(log.out, "pose images", images);
  const auto detected =
      vision::detect_in_image_series(requests, board, log.threads, [&] { bar.advance(); });
  bar.finish(fmt::format("{} images", images));
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    for (std::size_t f = 0; f < detected[i].size(); ++f) {
      const vision::ImageDetection& d = detected[i][f];
      if (!d.problem.empty()) {
        const bool nothing_seen =
            d.detection.status == vision::DetectionStatus::kRejected && d.detection.pixels.empty();
        if (n_cams > 2 && nothing_seen)
          out[jobs[i].pose].out_of_view.push_back(static_cast<int>(jobs[i].camera));
        else
          out[jobs[i].pose].problems.push_back(d.problem);
        continue;
      }
      auto& frame = out[jobs[i].pose].frames[f][jobs[i].camera];
      frame = vision::camera_frame(d.detection);
      set_corner_sigma(frame, options.corner_sigma_px, jobs[i].camera);
    }
  }
  const auto points = board_points(board);
  // Each pose's fit is its own (a pure function of its frames): side by side, the same answers.
  core::parallel_for(static_cast<int>(out.size()), log.threads, [&](int p) {
    PoseImages& pose = out[static_cast<std::size_t>(p)];
    if (pose.frames.empty()) {
      pose.measurement.status = vision::PoseStatus::kNotSeen;
      pose.measurement.message = "no images";
    } else {
      pose.measurement =
          vision::measure_settled_pose(rig, points, pose.frames, options.measurement);
    }
  });
  return out;
}

int BoardFitGate::inconsistent() const {
  return static_cast<int>(std::count_if(pose_problem.begin(), pose_problem.end(),
                                        [](const std::string& w) { return !w.empty(); }));
}

BoardFitGate judge_pose_fits(const std::vector<PoseImages>& measured) {
  std::vector<double> chi2_dof;
  for (const PoseImages& images : measured) {
    const vision::PoseMeasurement& m = images.measurement;
    // Ambiguous fits count too: a board file whose layout is not the printed board's (a column
    // too many) makes nearly every pose's fit bad and ambiguous, and a median over the few
    // unambiguous ones then passes, so each pose was blamed on swapped images instead.
    if (m.dof > 0 && (m.usable() || (m.status == vision::PoseStatus::kOk && m.ambiguous)))
      chi2_dof.push_back(m.chi2 / m.dof);
  }
  BoardFitGate gate{vision::judge_board_fits(chi2_dof), std::vector<std::string>(measured.size())};
  if (!gate.verdict.plausible) return gate;
  // Every pose with a fit, ambiguous ones included (a pose whose cameras saw different board
  // poses has no good fit, so its runner-up is as bad).
  const double pose_limit = vision::inconsistent_pose_limit(gate.verdict.median_chi2_dof);
  for (std::size_t p = 0; p < measured.size(); ++p) {
    const vision::PoseMeasurement& m = measured[p].measurement;
    if (m.dof > 0 && !(m.chi2 / m.dof <= pose_limit))
      gate.pose_problem[p] =
          vision::inconsistent_pose_reason(m.chi2 / m.dof, gate.verdict.median_chi2_dof);
  }
  return gate;
}

}  // namespace robocal::app
