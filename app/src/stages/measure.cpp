// The measure stage on a session: intrinsics per camera, the rig, the board pose per robot pose
// (stages/measure_steps.hpp), written to results/ (session/results_files.hpp).
#include "cli/cli_common.hpp"
#include "session/json_values.hpp"
#include "session/results_files.hpp"
#include "session/results_transaction.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "stages/measure_steps.hpp"
#include "stages/pose_bridge.hpp"
#include "stages/stage_log.hpp"
#include "stages/stages.hpp"

#include "robocal/calib/measurements_file.hpp"
#include "robocal/calib/plausibility.hpp"
#include "robocal/core/files.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/image_detection.hpp"
#include "robocal/vision/intrinsics_pipeline.hpp"
#include "robocal/vision/measurement_gate.hpp"
#include "robocal/vision/target_detection.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <memory>
#include <set>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

std::string relative_to(const fs::path& p, const fs::path& base) {
  return fs::relative(p, base).generic_string();
}

std::vector<fs::path> calibration_images(const fs::path& folder) {
  std::error_code ec;
  return fs::is_directory(folder, ec) ? vision::list_image_files(folder) : std::vector<fs::path>{};
}

// Whether `step` was calibrated from `files`: as many images, and every view one of them.
bool from_files(const IntrinsicsStep& step, const std::vector<fs::path>& files) {
  if (step.images != files.size()) return false;
  std::set<std::string> stems;
  for (const auto& f : files) stems.insert(f.stem().string());
  return std::all_of(step.views.begin(), step.views.end(),
                     [&](const vision::CalibrationView& v) { return stems.count(v.name) != 0; });
}

// Whether `early` was made from these very inputs (the same camera models and corner sigmas,
// the same view files).
bool made_from(const CalibratedRig& early, const std::vector<vision::RigCamera>& cameras,
               const std::vector<double>& corner_sigma, const std::vector<ImageSet>& views) {
  if (early.cameras.size() != cameras.size() || early.corner_sigma_px != corner_sigma ||
      early.files != rig_view_files(views))
    return false;
  for (std::size_t c = 0; c < cameras.size(); ++c) {
    const vision::CameraModel& a = early.cameras[c].model;
    const vision::CameraModel& b = cameras[c].model;
    if (early.cameras[c].name != cameras[c].name || a.kind != b.kind || a.width != b.width ||
        a.height != b.height || a.params != b.params)
      return false;
  }
  return true;
}

}  // namespace

void rig_inputs(const std::vector<std::string>& names,
                const std::vector<vision::IntrinsicCalibrationResult>& intrinsics,
                std::vector<vision::RigCamera>& cameras, std::vector<double>& corner_sigma_px) {
  cameras.clear();
  corner_sigma_px.clear();
  for (std::size_t c = 0; c < names.size(); ++c) {
    cameras.push_back({names[c], intrinsics[c].camera, Eigen::Isometry3d::Identity(),
                       Eigen::Matrix<double, 6, 6>::Zero()});
    corner_sigma_px.push_back(std::max(intrinsics[c].residual_sigma_px, 0.01));
  }
}

std::vector<std::string> rig_view_files(const std::vector<ImageSet>& views) {
  std::vector<std::string> files;
  for (const ImageSet& v : views)
    for (const auto& frames : v.frames_of_camera)
      for (const fs::path& f : frames) files.push_back(v.name + "/" + f.filename().string());
  return files;
}

CalibratedRig calibrate_rig_before_measure(const std::vector<std::string>& names,
                                           const CalibratedIntrinsics& intrinsics,
                                           const fs::path& rig_views,
                                           const vision::TargetBoard& board, int threads) {
  std::vector<vision::IntrinsicCalibrationResult> results;
  results.reserve(names.size());
  for (const std::string& n : names) results.push_back(intrinsics.at(n).result);
  CalibratedRig out;
  rig_inputs(names, results, out.cameras, out.corner_sigma_px);
  const auto views = scan_image_folder(rig_views, names);
  out.files = rig_view_files(views);
  RigStepOptions options;
  options.corner_sigma_px = out.corner_sigma_px;
  out.step = calibrate_rig_from_views(out.cameras, board, views, options, {nullptr, threads});
  return out;
}

vision::DetectionRecord detect_unrecorded_shots(const fs::path& pose_folder,
                                                const vision::TargetBoard& board) {
  const vision::AprilTagDetectorOptions options = vision::detector_options_for(board);
  const vision::DetectionRecord record = vision::read_detection_record(
      pose_folder / vision::kDetectionRecordFile, vision::detection_signature(board, options));
  vision::DetectionRecord out;
  std::unique_ptr<vision::AprilTagDetector> detector;
  for (const auto& [file, entry] : record) {
    // A first shot (CAMERA_0.png) that showed nothing: measure detects the later ones in full.
    const auto stem = file.size() > 6 ? file.substr(0, file.size() - 6) : std::string();
    if (stem.empty() || file.substr(file.size() - 6) != "_0.png" ||
        entry.detection.status != vision::DetectionStatus::kRejected)
      continue;
    for (int shot = 1;; ++shot) {
      const std::string later = fmt::format("{}_{}.png", stem, shot);
      const fs::path path = pose_folder / later;
      if (!fs::exists(path)) break;
      if (record.count(later) != 0) continue;
      const std::string bytes = core::read_text_file(path);
      const vision::LoadedImage image = vision::load_gray_image(path);
      if (!image.error.empty()) continue;
      if (!detector) detector = std::make_unique<vision::AprilTagDetector>(options);
      out[later] = {bytes.size(), vision::content_hash(bytes), image.gray.cols, image.gray.rows,
                    vision::detect_target(image.gray, board, *detector)};
    }
  }
  return out;
}

namespace {

// The cameras' intrinsics: each camera's result, its row in measure.json, and why calibration
// stopped ("" when every camera was calibrated).
struct IntrinsicsPhase {
  std::vector<vision::IntrinsicCalibrationResult> results;  // per camera
  nlohmann::json report = nlohmann::json::array();
  std::string failure;
};

// Intrinsics of each camera from its calibration views. The cameras calibrated before from these
// very views keep that result; the others are calibrated here, side by side. Each camera file
// is written as its camera is calibrated; the first camera that fails stops the phase.
IntrinsicsPhase measure_intrinsics(const Session& s, const std::vector<std::string>& names,
                                   const CalibratedIntrinsics& calibrated,
                                   const vision::TargetBoard& cal_board,
                                   const ResultsLayout& results, const PipelineLog& log) {
  const std::size_t n_cams = s.cameras.size();
  IntrinsicsPhase out;
  std::vector<std::vector<fs::path>> files_of(n_cams);
  std::vector<bool> reused(n_cams, false);
  std::vector<CameraViews> to_calibrate;
  for (std::size_t c = 0; c < n_cams; ++c) {
    files_of[c] = calibration_images(s.path(s.intrinsics_views) / names[c]);
    const auto earlier = calibrated.find(names[c]);
    reused[c] = earlier != calibrated.end() && from_files(earlier->second, files_of[c]);
    if (!reused[c])
      to_calibrate.push_back({names[c], s.cameras[c].width, s.cameras[c].height, files_of[c]});
  }
  std::vector<IntrinsicsStep> fresh = calibrate_cameras(to_calibrate, cal_board, step_log(log));
  for (std::size_t c = 0, k = 0; c < n_cams; ++c) {
    const auto& files = files_of[c];
    const bool reuse = reused[c];
    IntrinsicsStep step;
    if (reuse)
      step = calibrated.at(names[c]);
    else
      step = std::move(fresh.at(k++));
    if (reuse) say(log, "  {}: calibrated before collection from these views\n", names[c]);
    const auto& result = step.result;
    nlohmann::json cj{{"camera", names[c]}, {"images", files.size()}, {"views", step.views.size()}};
    if (reuse) cj["calibrated"] = "before collection, from these views";
    cj["problems"] = step.problems;
    if (result.status != vision::CalibrationStatus::kOk) {
      out.report.push_back(cj);
      out.failure =
          fmt::format("camera {} calibration {}: {}", names[c],
                      result.status == vision::CalibrationStatus::kRefused ? "refused" : "failed",
                      result.reason);
      return out;
    }
    const fs::path camera_file = results.camera(names[c]);
    vision::save_camera_file(result.camera, camera_file, names[c]);
    say(log, "  {}: fx {:.2f} ± {:.2f} px, RMS {:.3f} px\n", names[c], result.camera.params[0],
        result.param_stddev[0], result.rms_px);
    for (const auto& w : result.warnings) say(log, "    warning: {}\n", w);
    cj.update({{"rms_px", result.rms_px},
               {"residual_sigma_px", result.residual_sigma_px},
               {"params", result.camera.params},
               {"param_stddev", result.param_stddev},
               {"warnings", result.warnings},
               {"camera_file", relative_to(camera_file, results.session)}});
    out.report.push_back(cj);
    out.results.push_back(result);
  }
  return out;
}

// The measured rig, its entry in measure.json, and why it could not be calibrated ("" when it
// was).
struct RigPhase {
  std::vector<vision::RigCamera> rig;
  nlohmann::json report;
  std::string failure;
};

// The rig: the cameras' relative poses from views they share (rig frame = first camera). A rig
// calibrated before measure from these very inputs is kept. Writes results/rig.json when the
// calibration succeeds.
RigPhase measure_rig(const Session& s, const std::vector<std::string>& names,
                     const std::vector<vision::RigCamera>& rig_cameras,
                     const std::vector<double>& corner_sigma, const CalibratedRig* early_rig,
                     const vision::TargetBoard& cal_board, const ResultsLayout& results,
                     const PipelineLog& log) {
  const std::size_t n_cams = s.cameras.size();
  RigPhase out;
  const auto rig_sets = scan_image_folder(s.path(s.rig_views), names);
  RigStepOptions rig_options;
  rig_options.corner_sigma_px = corner_sigma;
  const bool rig_reused =
      early_rig != nullptr && made_from(*early_rig, rig_cameras, corner_sigma, rig_sets);
  if (rig_reused) say(log, "  rig: calibrated before measure from these views\n");
  const RigStep rig_step = rig_reused ? early_rig->step
                                      : calibrate_rig_from_views(rig_cameras, cal_board, rig_sets,
                                                                 rig_options, step_log(log));
  const auto& rig = rig_step.result;
  double sigma_sum = 0;
  for (double x : corner_sigma) sigma_sum += x;
  nlohmann::json rig_json = rig_file_json(rig, names[0], s.calibration_target,
                                          sigma_sum / static_cast<double>(corner_sigma.size()));
  rig_json["views"] = rig_sets.size();
  if (rig_reused) rig_json["calibrated"] = "before measure, from these views";
  rig_json["problems"] = nlohmann::json::array();
  for (const auto& view : rig_step.problems)
    for (const auto& p : view)
      if (!p.empty()) rig_json["problems"].push_back(p);
  if (!rig.ok) {
    rig_json.erase("corner_sigma_px");
    out.report = rig_json;
    out.failure = "rig calibration failed: " + rig.message;
    return out;
  }
  out.rig = rig.rig();
  write_json(rig_json, results.rig().string());
  if (n_cams > 1)
    say(log, "  baseline {:.5f} ± {:.5f} m, RMS {:.3f} px\n", rig.cameras.at(1).baseline_m,
        rig.cameras.at(1).baseline_sigma_m, rig.rms_px);
  out.report = {{"ok", true},
                {"rms_px", rig.rms_px},
                {"baseline_m", n_cams > 1 ? rig.cameras.at(1).baseline_m : 0.0},
                {"baseline_sigma_m", n_cams > 1 ? rig.cameras.at(1).baseline_sigma_m : 0.0},
                {"file", ResultsLayout::kRig}};
  return out;
}

// What the measured poses become: the identification's measurements, the per-pose records of
// measured_poses.json and pixel_observations.json, and how many were measured and used.
struct PoseRecords {
  calib::MeasurementsFile mfile;
  std::vector<MeasuredPoseRecord> measured_poses;
  std::vector<PixelPoseRecord> pixel_poses;
  int measured = 0, used = 0;
};

// Each pose's record and, when it goes to identification, its measurement; a pose that does not
// is given the reason in words (said on the console unless every pose is refused by the gate).
PoseRecords pose_records(const Session& s, const SessionRobot& robot,
                         const std::vector<std::string>& names,
                         const std::vector<PoseRecord>& records,
                         const std::vector<PoseImages>& measured_images,
                         const std::vector<std::string>& fit_problem, bool accept_implausible,
                         bool refuse_all, const PipelineLog& log) {
  PoseRecords out;
  out.mfile.robot = robot.model.name;
  out.mfile.frame = s.measured_frame;
  for (std::size_t p = 0; p < records.size(); ++p) {
    const auto& rec = records[p];
    const auto& images = measured_images[p];
    const vision::PoseMeasurement& m = images.measurement;
    MeasuredPoseRecord row{rec.name,     m, images.problems, images.frames.size(), rec.timestamp,
                           std::nullopt, ""};
    if (rec.problem.empty()) row.actuators = rec.actuators;
    if (m.status == vision::PoseStatus::kOk || m.status == vision::PoseStatus::kMoving)
      ++out.measured;
    // Why a pose does not go to identification, in words.
    const auto reading_problem =
        rec.problem.empty() ? calib::readings_problem(robot.model, robot.nominal, rec.actuators)
                            : std::nullopt;
    if (!rec.problem.empty())
      row.excluded = rec.problem;
    else if (reading_problem)
      row.excluded = fmt::format("{}/{}/pose.yaml: {}", s.poses, rec.name, *reading_problem);
    else if (!fit_problem[p].empty() && !accept_implausible)
      row.excluded = fit_problem[p];
    else if (!m.usable())
      row.excluded = fmt::format("board pose {}{}", vision::pose_status_name(m.status),
                                 m.message.empty() ? "" : " (" + m.message + ")");
    else if (refuse_all)
      row.excluded = "measurements not plausible (see board_fit_gate in measure.json)";
    if (!row.excluded.empty()) {
      if (!refuse_all || !m.usable() || !rec.problem.empty())
        say(log, "  {} not used: {}\n", rec.name, row.excluded);
    } else {
      ++out.used;
      out.mfile.measurements.poses.push_back({rec.name, rec.actuators, {to_pose_observation(m)}});
      // An image problem that did not stop the pose (measured from the other cameras) is still
      // the operator's to know.
      for (const auto& problem : images.problems)
        if (!problem.empty())
          say(log, "  {}: {} (measured from the other cameras)\n", rec.name, problem);
    }
    // Raw pixel observations (camera-in-the-loop identification), for every pose with readings.
    out.pixel_poses.push_back({rec.name, row.excluded.empty(), row.actuators, rec.problem,
                               corner_observations_json(images.frames, names, 0.0, true)});
    out.measured_poses.push_back(std::move(row));
  }
  return out;
}

}  // namespace

nlohmann::json measure_session(const fs::path& dir, const std::string& robot_override,
                               const PipelineLog& log, const GateOptions& gates,
                               const CalibratedIntrinsics& calibrated,
                               const CalibratedRig* early_rig,
                               const EarlyDetections* early_detections) {
  const Session s = load_session(dir);
  const SessionRobot robot = session_robot(s, robot_override);
  const auto ee_board = load_board(s.path(s.ee_target));
  const auto cal_board = load_board(s.path(s.calibration_target));
  const auto names = s.camera_names();
  // Written into a staged copy of results/ that replaces it when the measurement reaches its
  // verdict (session/results_transaction.hpp). The copy starts without this stage's files and
  // without the results computed from them, which would stand beside new measurements.
  const ResultsLayout current{dir};
  ResultsTransaction transaction(
      dir, {(dir / ResultsLayout::kCamerasFolder).parent_path(), current.rig(),
            current.measured_poses(), current.pixel_observations(), current.measurements(),
            current.report("measure"), current.identification(), current.calibrated_robot(),
            current.calibrated_robot_pixels(), current.report("validation")});
  const ResultsLayout& results = transaction.staged();
  nlohmann::json report{{"stage", "measure"}, {"session", dir.string()}};
  // A step that could not be done: the previous results stay as they were (nothing committed);
  // the reason goes to the console and the returned report.
  const auto fail = [&](const std::string& message) {
    report["status"] = "failed";
    report["message"] = message;
    say(log, "measure failed: {}; the previous results are unchanged\n", message);
    return report;
  };

  // 1. Intrinsics of each camera from its calibration views.
  stage(log, "measure: intrinsics");
  const IntrinsicsPhase intrinsics =
      measure_intrinsics(s, names, calibrated, cal_board, results, log);
  report["intrinsics"] = intrinsics.report;
  if (!intrinsics.failure.empty()) return fail(intrinsics.failure);
  std::vector<vision::RigCamera> rig_cameras;
  std::vector<double> corner_sigma;
  rig_inputs(names, intrinsics.results, rig_cameras, corner_sigma);

  // 2. Rig: the cameras' relative poses from views they share (rig frame = first camera).
  stage(log, "measure: rig");
  const RigPhase rig =
      measure_rig(s, names, rig_cameras, corner_sigma, early_rig, cal_board, results, log);
  report["rig"] = rig.report;
  if (!rig.failure.empty()) return fail(rig.failure);

  // 3. The end-effector board's pose at every robot pose.
  stage(log, "measure: poses");
  const auto records = load_pose_records(s);
  if (records.empty()) return fail(s.path(s.poses).string() + ": no pose folders");
  const auto sets = scan_image_folder(s.path(s.poses), names);  // same folders, same order
  PoseStepOptions pose_options;
  pose_options.corner_sigma_px = corner_sigma;
  const auto measured_images =
      measure_board_poses(rig.rig, ee_board, sets, pose_options, step_log(log), early_detections);

  const BoardFitGate fit_gate = judge_pose_fits(measured_images);
  const vision::BoardFitVerdict& fits = fit_gate.verdict;
  report["board_fit_gate"] = {{"plausible", fits.plausible},
                              {"median_chi2_dof", fits.median_chi2_dof},
                              {"inconsistent_poses", fit_gate.inconsistent()},
                              {"overridden", !fits.plausible && gates.accept_implausible}};
  if (!fits.plausible) {
    report["board_fit_gate"]["reason"] = fits.reason;
    say(log, "  MEASUREMENTS NOT PLAUSIBLE: {}\n", fits.reason);
  }
  const bool refuse_all = !fits.plausible && !gates.accept_implausible;

  const PoseRecords poses =
      pose_records(s, robot, names, records, measured_images, fit_gate.pose_problem,
                   gates.accept_implausible, refuse_all, log);
  std::size_t out_of_view = 0;
  for (const auto& images : measured_images) out_of_view += images.out_of_view.size();
  if (out_of_view > 0)
    say(log,
        "  {} pose images show no part of the board: in a camera array each pose is seen by "
        "the cameras facing it\n",
        out_of_view);
  write_measured_poses(results, poses.measured_poses);
  write_pixel_observations(results, {s.robot_file, s.measured_frame, s.ee_target},
                           poses.pixel_poses);
  core::write_file_atomic(results.measurements(), calib::measurements_to_yaml(poses.mfile));
  say(log, "  {} of {} poses measured, {} used for identification\n", poses.measured,
      records.size(), poses.used);
  report["poses"] = {{"total", records.size()}, {"measured", poses.measured}, {"used", poses.used}};
  if (!refuse_all && poses.used == 0) return fail("no pose could be measured");
  report["status"] = refuse_all ? "implausible" : "ok";
  if (refuse_all) {
    report["message"] = fits.reason;
    say(log,
        "  no pose goes to identification. If the data is right after all, `robocal measure "
        "--accept-implausible` uses it anyway (recorded in measure.json)\n");
  }
  report["files"] = {ResultsLayout::kCamerasFolder, ResultsLayout::kRig,
                     ResultsLayout::kMeasuredPoses, ResultsLayout::kPixelObservations,
                     ResultsLayout::kMeasurements};
  write_json(report, results.report("measure").string());
  transaction.commit();
  return report;
}

}  // namespace robocal::app
