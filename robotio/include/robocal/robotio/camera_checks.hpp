#pragma once
// Live checks a wizard shows while the operator sets up a camera: is the target found, how many
// of its corners, is it sharp (edge spread of the detected tags), is the exposure right
// (clipped and dark fractions, histogram). Each check has a threshold and advice in plain words.
#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/target.hpp"

#include <opencv2/core/mat.hpp>

#include <string>
#include <vector>

namespace robocal::robotio {

struct LiveCheckOptions {
  // Edge spread (Gaussian sigma of the fitted tag edges, px; ~0.3-0.6 for a focused lens). Above
  // this, corners lose precision: refocus.
  double max_edge_spread_px = 1.5;
  // Fraction of pixels at the sensor's maximum: clipped highlights bias the edge fits.
  double max_clipped_fraction = 0.002;
  // The target's white must reach this fraction of the sensor's range (99th percentile of the
  // image): darker images lose precision to noise.
  double min_bright_level = 0.35;
  // Corners found / corners of the board below this: part of the target is hidden or outside.
  double min_corner_fraction = 0.9;
};

struct LiveCheck {
  std::string name;  // "target", "corners", "sharpness", "exposure"
  bool ok = false;
  double value = 0.0;
  double threshold = 0.0;
  std::string summary;  // what was measured, in words
  std::string advice;   // what to do, empty when ok
};

struct LiveCheckReport {
  std::vector<LiveCheck> checks;
  std::vector<double> histogram;  // 256 bins over the sensor's range, fractions summing to 1
  double clipped_fraction = 0.0;
  double bright_level = 0.0;  // 99th percentile / sensor maximum
  int corners = 0;
  int board_corners = 0;
  double edge_spread_px = 0.0;  // NaN when no tag could be refined
  [[nodiscard]] bool ok() const;
};

// Checks one frame (CV_8UC1 or CV_16UC1) of `board`.
LiveCheckReport check_live_frame(const cv::Mat& image, const vision::TargetBoard& board,
                                 vision::AprilTagDetector& detector,
                                 const LiveCheckOptions& options = {});

}  // namespace robocal::robotio
