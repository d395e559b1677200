#pragma once
// Images -> board detections on worker threads: the one loop behind every caller (intrinsics
// from a folder of views, the rig's shared views, the end-effector board at each robot pose).
// One bad image never stops the others: it comes back with its problem in words.
#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/detection_record.hpp"
#include "robocal/vision/observations.hpp"
#include "robocal/vision/target.hpp"
#include "robocal/vision/target_detection.hpp"

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace robocal::vision {

struct DetectionRequest {
  std::filesystem::path image;
  // Expected image size (0 = not checked) and who expects it, for the message
  // "<file>: image is 640x400 but <expected_by> for 640x480" (e.g. "camera 'left' is
  // calibrated").
  int width = 0;
  int height = 0;
  std::string expected_by;
  // Detections recorded with the image's folder (detection_record.hpp; owned by the caller), or
  // none. The image's entry is taken instead of detecting when it was made from this very file
  // by the same detector (the caller reads the record with detection_signature()).
  const DetectionRecord* record = nullptr;
};

// The detector options a board is detected with: `options` with the board's tag family.
AprilTagDetectorOptions detector_options_for(const TargetBoard& board,
                                             AprilTagDetectorOptions options = {});

struct ImageDetection {
  // "<file>: <why>" when the image is unreadable, has the wrong size or the target was not
  // found (detection status kRejected); empty when the target was found (kFound / kPartial).
  std::string problem;
  TargetDetection detection;  // as detected (also when rejected); empty when not read
  int width = 0;              // of the image read; 0 when unreadable
  int height = 0;
};

// Detects `board` in every requested image on up to `threads` workers, each with its own
// detector (`detector` options; the family is the board's). `done` (optional) is called once per
// image, from the worker that finished it. Results are in request order.
std::vector<ImageDetection> detect_in_images(const std::vector<DetectionRequest>& requests,
                                             const TargetBoard& board, int threads,
                                             const std::function<void()>& done = {},
                                             const AprilTagDetectorOptions& detector = {});

// The same for series of images of one unchanging view each (the frames one camera took at one
// robot pose while it stood still): one series per job. In each series the first image where the
// board is found is detected in full, and in the images after it an AprilTag board's tags are
// refined where that detection had them (redetect_apriltag_board: about a third of the time;
// a tag it missed is not looked for, one that moved more than 2 px is missing); other boards are
// detected in full. Results are [series][image], in request order.
std::vector<std::vector<ImageDetection>> detect_in_image_series(
    const std::vector<std::vector<DetectionRequest>>& series, const TargetBoard& board, int threads,
    const std::function<void()>& done = {}, const AprilTagDetectorOptions& detector = {});

// A detection as the estimators read it: the corners (sigma unknown: 0), the edge blur and the
// per-tag joint corner covariances. Empty for a rejected detection.
CameraFrame camera_frame(const TargetDetection& detection);

}  // namespace robocal::vision
