#pragma once
// Folder of images + target -> detections -> intrinsic calibration, with a record per image so
// one bad file never stops the rest. Used by `robocal intrinsics`.
#include <filesystem>
#include <string>
#include <vector>

#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/intrinsic_calibration.hpp"
#include "robocal/vision/target.hpp"
#include "robocal/vision/target_detection.hpp"

namespace robocal::vision {

struct ImageRecord {
  std::string file;   ///< file name within the folder
  std::string error;  ///< could not be used at all (unreadable, size mismatch); else empty
  DetectionStatus status = DetectionStatus::kRejected;
  std::string detail;  ///< detection reason (rejected / partial)
  int corners = 0;
  double edge_blur_px = 0.0;
};

struct IntrinsicsPipelineOptions {
  IntrinsicCalibrationOptions calibration;  ///< width/height are taken from the images
  AprilTagDetectorOptions apriltag;
};

struct IntrinsicsRun {
  std::vector<ImageRecord> images;
  IntrinsicCalibrationResult calibration;
  int width = 0;
  int height = 0;
};

/// True for the image file endings the pipeline reads (png, jpg, jpeg, bmp, tif, tiff, pgm, ppm;
/// any case).
bool is_image_file(const std::filesystem::path& file);

/// Image files (is_image_file) of a folder, sorted by name.
/// Throws std::invalid_argument when the folder does not exist.
std::vector<std::filesystem::path> list_image_files(const std::filesystem::path& dir);

/// Throws std::invalid_argument when the folder is missing or has no image files; everything
/// else is reported per image or in the calibration status.
IntrinsicsRun calibrate_from_folder(const std::filesystem::path& dir, const TargetBoard& board,
                                    const IntrinsicsPipelineOptions& options);

/// An SVG of the image area: observed corners (inliers grey, outliers red), the projection
/// uncertainty map as a heat map, and the uncovered 3x3 regions outlined.
std::string coverage_svg(const IntrinsicCalibrationResult& result, int width, int height);

}  // namespace robocal::vision
