#pragma once
// Board-level detection: image file loading with clear per-file errors, and AprilTag detections
// mapped onto a TargetBoard's corner ids with a per-image status.
#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/intrinsic_calibration.hpp"
#include "robocal/vision/target.hpp"

namespace robocal::vision {

/// An 8-bit grey image, or why the file cannot be used (missing, unreadable, truncated, wrong
/// bit depth). Colour images are converted to grey.
struct LoadedImage {
  cv::Mat gray;
  std::string error;  ///< "<file>: <problem>", empty on success
};
LoadedImage load_gray_image(const std::filesystem::path& path);

enum class DetectionStatus { kFound, kPartial, kRejected };

/// The corners of one board found in one image.
struct TargetDetection {
  DetectionStatus status = DetectionStatus::kRejected;
  std::string reason;                   ///< why rejected; what is missing when partial
  std::vector<int> missing_marker_ids;  ///< board markers not seen (partial)
  std::vector<int> corner_ids;          ///< TargetBoard corner ids
  std::vector<Eigen::Vector3d> board_points;
  std::vector<Eigen::Vector2d> pixels;  ///< OpenCV convention
  /// Median fitted edge spread over the detected markers (px, ~0.3 when perfectly sharp); NaN if
  /// no marker could be refined.
  double edge_blur_px = 0.0;
};

/// Detects an AprilTag grid board. Tags of other boards are ignored; a tag id seen twice rejects
/// the image (a second board or a false decode makes its corners ambiguous).
TargetDetection detect_apriltag_board(const cv::Mat& gray, const TargetBoard& board,
                                      AprilTagDetector& detector);

/// Observations for calibrate_intrinsics().
CalibrationView to_calibration_view(const TargetDetection& detection, std::string name);

std::string detection_status_name(DetectionStatus status);

}  // namespace robocal::vision
