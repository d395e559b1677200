#pragma once
// The steps of the measure stage, each one function over images and calibrated cameras. Session
// mode (`robocal measure SESSION`, stages/measure.cpp) and folder mode (`robocal rig`, `robocal
// measure --rig`) both run exactly these.
#include "cli/progress.hpp"
#include "session/image_folders.hpp"

#include "robocal/vision/detection_record.hpp"
#include "robocal/vision/intrinsic_calibration.hpp"
#include "robocal/vision/measurement_gate.hpp"
#include "robocal/vision/observations.hpp"
#include "robocal/vision/pose_measurement.hpp"
#include "robocal/vision/rig_calibration.hpp"
#include "robocal/vision/target.hpp"

#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace robocal::app {

// Where a step reports progress: a bar on `out` (nullptr: silent) and `threads` detection workers.
struct StepLog {
  std::FILE* out = stdout;
  int threads = 2;
};

vision::BoardPoints board_points(const vision::TargetBoard& board);

// 1. Intrinsics of one camera from its calibration views (image files).
struct IntrinsicsStep {
  std::size_t images = 0;
  std::vector<std::string> problems;  // per image that could not be used
  std::vector<vision::CalibrationView> views;
  vision::IntrinsicCalibrationResult result;
};
IntrinsicsStep calibrate_camera(const std::string& camera, int width, int height,
                                const std::vector<std::filesystem::path>& files,
                                const vision::TargetBoard& board, const StepLog& log);

// The same for several cameras. Their images are detected one camera after the other (each on
// `log.threads` workers, with its progress bar); then their bundle adjustments, each
// single-threaded and independent of the others, run side by side on up to `log.threads`
// threads: the same results as one camera at a time, in less time (each one solve of 96 views
// takes about 7 s). Steps in the order of `cameras`.
struct CameraViews {
  std::string camera;
  int width = 0;
  int height = 0;
  std::vector<std::filesystem::path> files;
};
std::vector<IntrinsicsStep> calibrate_cameras(const std::vector<CameraViews>& cameras,
                                              const vision::TargetBoard& board, const StepLog& log);

// 2. The rig: the cameras' relative poses from views they share.
struct RigStepOptions {
  vision::RigCalibrationOptions calibration;
  std::vector<double> corner_sigma_px;  // per camera, set on every detected corner; empty: unset
};
struct RigStep {
  std::vector<std::vector<vision::CameraFrame>> views;  // [view][camera]
  std::vector<std::vector<std::string>> problems;       // [view][camera]; empty: seen
  vision::RigCalibrationResult result;
};
RigStep calibrate_rig_from_views(const std::vector<vision::RigCamera>& cameras,
                                 const vision::TargetBoard& board,
                                 const std::vector<ImageSet>& views, const RigStepOptions& options,
                                 const StepLog& log);

// 3. The board's pose at every robot pose (one image set per pose; several frames per camera
// are a settled-pose check).
struct PoseStepOptions {
  vision::PoseMeasurementOptions measurement;
  std::vector<double> corner_sigma_px;  // per camera, set on every detected corner; empty: unset
};
struct PoseImages {
  std::vector<std::vector<vision::CameraFrame>> frames;  // [frame][camera]
  std::vector<std::string> problems;                     // missing / unreadable images
  // In a camera array (more than two cameras), the cameras whose image shows no part of the
  // board: each pose is seen by the cameras facing it, so this is expected, not a problem.
  std::vector<int> out_of_view;
  vision::PoseMeasurement measurement;
};
// `early`: detections made before (by pose folder name), taken like the pose folders' own
// records: an entry only for the very file it was made from.
std::vector<PoseImages> measure_board_poses(
    const std::vector<vision::RigCamera>& rig, const vision::TargetBoard& board,
    const std::vector<ImageSet>& poses, const PoseStepOptions& options, const StepLog& log,
    const std::map<std::string, vision::DetectionRecord>* early = nullptr);

// 4. Plausibility of the board fits (vision/measurement_gate.hpp), the same for a session and for
// `measure --rig`: the whole set against the stated corner noise, then single poses whose cameras
// disagree (images swapped, a board that moved between exposures) against the set's median.
struct BoardFitGate {
  vision::BoardFitVerdict verdict;
  std::vector<std::string> pose_problem;  // per pose; empty: consistent (or not fitted)
  int inconsistent() const;
};
BoardFitGate judge_pose_fits(const std::vector<PoseImages>& measured);

}  // namespace robocal::app
