#include "robocal/vision/image_detection.hpp"

#include <fmt/core.h>
#include "robocal/core/parallel.hpp"

#include <memory>
#include <mutex>

namespace robocal::vision {

namespace {

AprilTagDetectorOptions detector_options(const TargetBoard& board,
                                         AprilTagDetectorOptions options) {
  if (board.spec.kind == TargetKind::kAprilTagGrid) options.family = board.spec.family;
  return options;
}

}  // namespace

std::vector<ImageDetection> detect_in_images(const std::vector<DetectionRequest>& requests,
                                             const TargetBoard& board, int threads,
                                             const std::function<void()>& done,
                                             const AprilTagDetectorOptions& detector) {
  std::vector<ImageDetection> out(requests.size());
  const AprilTagDetectorOptions options = detector_options(board, detector);
  // One detector per worker (building a tag family's decode table costs tens of ms).
  std::mutex detectors_mutex;
  std::vector<std::unique_ptr<AprilTagDetector>> idle;
  std::mutex done_mutex;
  core::parallel_for(static_cast<int>(requests.size()), threads, [&](int i) {
    const auto k = static_cast<std::size_t>(i);
    const DetectionRequest& request = requests[k];
    ImageDetection& result = out[k];
    const LoadedImage img = load_gray_image(request.image);
    if (!img.error.empty()) {
      result.problem = img.error;
    } else {
      result.width = img.gray.cols;
      result.height = img.gray.rows;
      if (request.width > 0 &&
          (img.gray.cols != request.width || img.gray.rows != request.height)) {
        result.problem = fmt::format("{}: image is {}x{} but {} for {}x{}", request.image.string(),
                                     img.gray.cols, img.gray.rows, request.expected_by,
                                     request.width, request.height);
      } else {
        std::unique_ptr<AprilTagDetector> worker_detector;
        {
          const std::lock_guard<std::mutex> lock(detectors_mutex);
          if (!idle.empty()) {
            worker_detector = std::move(idle.back());
            idle.pop_back();
          }
        }
        if (!worker_detector) worker_detector = std::make_unique<AprilTagDetector>(options);
        result.detection = detect_target(img.gray, board, *worker_detector);
        {
          const std::lock_guard<std::mutex> lock(detectors_mutex);
          idle.push_back(std::move(worker_detector));
        }
        if (result.detection.status == DetectionStatus::kRejected)
          result.problem = fmt::format("{}: target not detected ({})", request.image.string(),
                                       result.detection.reason);
      }
    }
    if (done) {
      const std::lock_guard<std::mutex> lock(done_mutex);
      done();
    }
  });
  return out;
}

CameraFrame camera_frame(const TargetDetection& detection) {
  CameraFrame frame;
  if (detection.status == DetectionStatus::kRejected) return frame;
  frame.blur_px = detection.edge_blur_px;
  for (std::size_t i = 0; i < detection.corner_ids.size(); ++i)
    frame.corners.push_back({detection.corner_ids[i], detection.pixels[i], 0.0});
  // Corners of one tag share edge fits: their joint covariance (vision/README.md).
  frame.corner_groups = detection.corner_groups;
  return frame;
}

}  // namespace robocal::vision
