#include "robocal/vision/image_detection.hpp"

#include <fmt/core.h>
#include "robocal/core/files.hpp"
#include "robocal/core/parallel.hpp"

#include <memory>
#include <mutex>
#include <utility>
#include <vector>

namespace robocal::vision {

AprilTagDetectorOptions detector_options_for(const TargetBoard& board,
                                             AprilTagDetectorOptions options) {
  if (board.spec.kind == TargetKind::kAprilTagGrid) options.family = board.spec.family;
  return options;
}

namespace {

// Detectors shared by the workers of one call, one per worker at a time (building a tag family's
// decode table costs tens of ms).
class DetectorPool {
 public:
  explicit DetectorPool(AprilTagDetectorOptions options) : options_(std::move(options)) {}
  std::unique_ptr<AprilTagDetector> take() {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (!idle_.empty()) {
        auto detector = std::move(idle_.back());
        idle_.pop_back();
        return detector;
      }
    }
    return std::make_unique<AprilTagDetector>(options_);
  }
  void give_back(std::unique_ptr<AprilTagDetector> detector) {
    const std::lock_guard<std::mutex> lock(mutex_);
    idle_.push_back(std::move(detector));
  }

 private:
  AprilTagDetectorOptions options_;
  std::mutex mutex_;
  std::vector<std::unique_ptr<AprilTagDetector>> idle_;
};

std::string wrong_size(const DetectionRequest& request, int width, int height) {
  if (request.width <= 0 || (width == request.width && height == request.height)) return {};
  return fmt::format("{}: image is {}x{} but {} for {}x{}", request.image.string(), width, height,
                     request.expected_by, request.width, request.height);
}

// The recorded detection of the request's image, when the file is the one it was made from.
const RecordedDetection* recorded_detection(const DetectionRequest& request) {
  if (request.record == nullptr || request.record->empty()) return nullptr;
  try {
    return matching_entry(*request.record, request.image, core::read_text_file(request.image));
  } catch (const std::exception&) {
    return nullptr;  // unreadable: the detection says why
  }
}

// One image: read, size checked, the board detected, or (an AprilTag board and a `reference`
// detection of the same view) its tags refined where the reference had them.
ImageDetection detect_one(const DetectionRequest& request, const TargetBoard& board,
                          DetectorPool& detectors, const TargetDetection* reference) {
  ImageDetection result;
  if (const RecordedDetection* recorded = recorded_detection(request)) {
    result.width = recorded->width;
    result.height = recorded->height;
    if (const std::string wrong = wrong_size(request, result.width, result.height);
        !wrong.empty()) {
      result.problem = wrong;
      return result;
    }
    result.detection = recorded->detection;
    if (result.detection.status == DetectionStatus::kRejected)
      result.problem = fmt::format("{}: target not detected ({})", request.image.string(),
                                   result.detection.reason);
    return result;
  }
  const LoadedImage img = load_gray_image(request.image);
  if (!img.error.empty()) {
    result.problem = img.error;
    return result;
  }
  result.width = img.gray.cols;
  result.height = img.gray.rows;
  if (const std::string wrong = wrong_size(request, result.width, result.height); !wrong.empty()) {
    result.problem = wrong;
    return result;
  }
  std::unique_ptr<AprilTagDetector> detector = detectors.take();
  result.detection = reference != nullptr && board.spec.kind == TargetKind::kAprilTagGrid
                         ? redetect_apriltag_board(img.gray, board, *reference, *detector)
                         : detect_target(img.gray, board, *detector);
  detectors.give_back(std::move(detector));
  if (result.detection.status == DetectionStatus::kRejected)
    result.problem = fmt::format("{}: target not detected ({})", request.image.string(),
                                 result.detection.reason);
  return result;
}

}  // namespace

std::vector<ImageDetection> detect_in_images(const std::vector<DetectionRequest>& requests,
                                             const TargetBoard& board, int threads,
                                             const std::function<void()>& done,
                                             const AprilTagDetectorOptions& detector) {
  std::vector<ImageDetection> out(requests.size());
  DetectorPool detectors(detector_options_for(board, detector));
  std::mutex done_mutex;
  core::parallel_for(static_cast<int>(requests.size()), threads, [&](int i) {
    const auto k = static_cast<std::size_t>(i);
    out[k] = detect_one(requests[k], board, detectors, nullptr);
    if (done) {
      const std::lock_guard<std::mutex> lock(done_mutex);
      done();
    }
  });
  return out;
}

std::vector<std::vector<ImageDetection>> detect_in_image_series(
    const std::vector<std::vector<DetectionRequest>>& series, const TargetBoard& board, int threads,
    const std::function<void()>& done, const AprilTagDetectorOptions& detector) {
  std::vector<std::vector<ImageDetection>> out(series.size());
  DetectorPool detectors(detector_options_for(board, detector));
  std::mutex done_mutex;
  core::parallel_for(static_cast<int>(series.size()), threads, [&](int i) {
    const auto& requests = series[static_cast<std::size_t>(i)];
    auto& results = out[static_cast<std::size_t>(i)];
    results.reserve(requests.size());  // `reference` points into it
    const TargetDetection* reference = nullptr;
    for (const DetectionRequest& request : requests) {
      results.push_back(detect_one(request, board, detectors, reference));
      if (reference == nullptr && results.back().problem.empty())
        reference = &results.back().detection;
      if (done) {
        const std::lock_guard<std::mutex> lock(done_mutex);
        done();
      }
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
