#pragma once
// AprilTag detection (AprilTag 3.3) with our own sub-pixel corner refinement.
//
// Tags are found on a decimated image by the library; each tag's four outer border edges are then
// fitted on the full-resolution image (edge_fit.hpp) and intersected. All coordinates follow the
// project's pixel convention (OpenCV's: (0,0) is the centre of the top-left pixel); AprilTag's
// own corners (origin at the top-left pixel *corner*) are shifted by -0.5 px on the way out.
#include <Eigen/Core>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

namespace robocal::vision {

/// AprilTag reports (0,0) at the top-left corner of the first pixel; we use its centre.
inline constexpr double kAprilTagToOpenCvOffset = -0.5;

struct AprilTagDetectorOptions {
  std::string family = "tag36h11";  ///< tag36h11, tag25h9, tag16h5, tagStandard41h12, ...
  float quad_decimate = 2.0f;       ///< detection runs on an image decimated by this factor
  int threads = 1;
  float quad_sigma = 0.0f;   ///< Gaussian pre-blur for quad detection (0 = none)
  bool refine_edges = true;  ///< the library's own edge snapping (keep on)
  double decode_sharpening = 0.25;
  int max_hamming = 1;          ///< bit errors corrected when decoding (0..2)
  bool subpixel_refine = true;  ///< our full-resolution edge-fit corner refinement
  /// Detections with a lower decision margin are dropped (weak decodes are mostly false ones).
  double min_decision_margin = 20.0;
  /// The library's min_white_black_diff (DN): image tiles whose neighbourhood spans less grey than
  /// this are left out of the quad search. 0: set for each image from its noise
  /// (min_white_black_diff_for). The library's fixed default (5) suits clean images; on a camera
  /// with 2 DN of noise the noise itself then spans more than that almost everywhere, and the
  /// quad search spends ~90 % of its time on clusters of noise.
  int min_white_black_diff = 0;
};

/// Standard deviation of an 8-bit image's pixel noise (DN), before rounding to whole DN: from the
/// median of the absolute differences of horizontally adjacent pixels, read as a rounded Gaussian
/// difference. Edges and shading occupy few of the pairs, so the median is the noise's. 0 for a
/// noise-free image or one narrower than 2 pixels. Throws std::invalid_argument for an image that
/// is not 8-bit grey.
double pixel_noise_sigma(const cv::Mat& gray);

/// min_white_black_diff for an image with noise `noise_sigma`: 8 sigma, which the noise spans in
/// almost no 12x12-pixel tile neighbourhood (a sample of 144 spans ~5 sigma on average, 8 with a
/// probability of 1.5e-4), so the quad search visits only real contrast. Never below the
/// library's default 5, and never above 2 x `min_decision_margin`: a tag kept has at least that
/// contrast between its black and white cells, so a higher threshold could only lose tags.
int min_white_black_diff_for(double noise_sigma, double min_decision_margin);

/// One decoded tag. Corner order is AprilTag's: counter-clockwise in the image starting at the
/// tag's bottom-left (tag frame corners (-1,+1), (+1,+1), (+1,-1), (-1,-1), y down the pattern).
struct TagDetection {
  int id = -1;
  int hamming = 0;
  double decision_margin = 0.0;
  std::array<Eigen::Vector2d, 4> corners;          ///< best estimate (refined when `refined`)
  std::array<Eigen::Vector2d, 4> library_corners;  ///< AprilTag's corners, OpenCV convention
  bool refined = false;
  /// Fitted edge spread in px (lens blur and pixel integration combined; ~0.3 for a perfectly
  /// sharp image). Grows monotonically with defocus. NaN when refinement was off or failed.
  double edge_blur_px = 0.0;
  double edge_contrast = 0.0;  ///< DN between the black border and the white surround (or NaN)
  /// Joint covariance of the refined corners (u0, v0, ..., u3, v3; px^2) from the edge fits'
  /// pixel noise (edge_fit.hpp); zero when not refined.
  Eigen::Matrix<double, 8, 8> corner_covariance = Eigen::Matrix<double, 8, 8>::Zero();
};

/// Reusable detector (building the tag family's decode table costs tens of ms). Not thread safe:
/// use one per thread.
class AprilTagDetector {
 public:
  /// Throws std::invalid_argument for an unknown family or out-of-range option.
  explicit AprilTagDetector(AprilTagDetectorOptions options = {});
  ~AprilTagDetector();
  AprilTagDetector(const AprilTagDetector&) = delete;
  AprilTagDetector& operator=(const AprilTagDetector&) = delete;
  AprilTagDetector(AprilTagDetector&&) noexcept;
  AprilTagDetector& operator=(AprilTagDetector&&) noexcept;

  /// Detects tags in an 8-bit single-channel image (throws std::invalid_argument otherwise).
  /// Sorted by id. Duplicated ids are all returned; the caller decides (board detection rejects).
  std::vector<TagDetection> detect(const cv::Mat& gray);

  /// The tags of an earlier detection looked for again in a later image of the same view, by
  /// refining each one's corners where they were (no quad search, no decoding: a fraction of
  /// detect()'s time). The second look of the settled-frame test. Only refined tags are returned:
  /// a tag whose edges are no longer within the refinement's reach of its old corners
  /// (QuadRefineOptions::max_shift_px, 2 px), because the target moved or was covered, is left out.
  /// The ids are those of `previous`, trusted, not decoded again. Throws as detect() does.
  std::vector<TagDetection> refine_at(const cv::Mat& gray,
                                      const std::vector<TagDetection>& previous);

  /// The library alone (same options, no refinement, corners converted to OpenCV convention):
  /// used by benchmarks and tests as the baseline.
  std::vector<TagDetection> detect_library_only(const cv::Mat& gray);

  [[nodiscard]] const AprilTagDetectorOptions& options() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace robocal::vision
