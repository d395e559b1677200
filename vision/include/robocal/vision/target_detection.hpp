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
#include "robocal/vision/observations.hpp"
#include "robocal/vision/target.hpp"

namespace robocal::vision {

/// An 8-bit grey image, or why the file cannot be used (missing, unreadable, truncated, wrong
/// bit depth). Colour images are converted to grey.
struct LoadedImage {
  cv::Mat gray;
  std::string error;  ///< "<file>: <problem>", empty on success
};
LoadedImage load_gray_image(const std::filesystem::path& path);
/// The same for an image already in memory (a camera's frame): what load_gray_image makes of the
/// file it would be written to. `name` prefixes the error.
LoadedImage gray_image(const cv::Mat& image, const std::string& name);

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
  /// Joint covariances of the corners of each refined tag (by corner id; see observations.hpp).
  /// Empty for chessboards, ChArUco boards and unrefined tags.
  std::vector<CornerGroup> corner_groups;
};

/// Detects an AprilTag grid board. Tags of other boards are ignored; a tag id seen twice rejects
/// the image (a second board or a false decode makes its corners ambiguous).
TargetDetection detect_apriltag_board(const cv::Mat& gray, const TargetBoard& board,
                                      AprilTagDetector& detector);

/// The AprilTag board of `previous` (a detection of the same view, typically the first of a
/// series of frames) found again in a later image, at a fraction of the cost of a detection: each
/// of its complete tags refined where it was (AprilTagDetector::refine_at). For telling whether
/// the target stayed still between frames, not for finding it: a tag the earlier detection missed
/// is not looked for; tags that moved beyond the refinement's reach (2 px) are missing (partial);
/// none found again: rejected, saying so.
TargetDetection redetect_apriltag_board(const cv::Mat& gray, const TargetBoard& board,
                                        const TargetDetection& previous,
                                        AprilTagDetector& detector);

/// OpenCV 4.6's interpolateCornersCharuco returns corners +0.5 px off in both axes (measured on
/// rendered boards, see vision.md); detect_charuco_board adds this before its own refinement.
inline constexpr double kOpenCv46CharucoOffset = -0.5;

struct ChessboardDetectorOptions {
  /// cornerSubPix half window as a fraction of the local square size in px (clamped to 2..10).
  double subpix_window_fraction = 0.3;
  /// A ChArUco corner further than this (px, or 0.15 square, whichever is larger) from where
  /// its neighbouring markers predict it is dropped (OpenCV 4.6 misplaces some; issues 3301,
  /// 3367 of opencv_contrib).
  double max_marker_disagreement_px = 2.0;
};

/// Chessboard: cv::findChessboardCorners + cv::cornerSubPix, ordered onto the board's ids (the
/// black top-left square disambiguates 180 deg unless the board is symmetric). A mirrored
/// chessboard image is indistinguishable from a real view and cannot be rejected here.
TargetDetection detect_chessboard_board(const cv::Mat& gray, const TargetBoard& board,
                                        const ChessboardDetectorOptions& options = {});

/// ChArUco (OpenCV 4.6 layout): aruco markers, interpolated corners with the 4.6 offset
/// removed, each corner re-refined (cornerSubPix) and checked against a local homography of the
/// neighbouring markers.
TargetDetection detect_charuco_board(const cv::Mat& gray, const TargetBoard& board,
                                     const ChessboardDetectorOptions& options = {});

/// Dispatches on the board kind (AprilTag detector used only for AprilTag grids).
TargetDetection detect_target(const cv::Mat& gray, const TargetBoard& board,
                              AprilTagDetector& apriltag_detector);

/// Observations for calibrate_intrinsics().
CalibrationView to_calibration_view(const TargetDetection& detection, std::string name);

std::string detection_status_name(DetectionStatus status);

}  // namespace robocal::vision
