#include "robocal/robotio/camera_checks.hpp"

#include "robocal/vision/target_detection.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace robocal::robotio {

bool LiveCheckReport::ok() const {
  return std::all_of(checks.begin(), checks.end(), [](const LiveCheck& c) { return c.ok; });
}

LiveCheckReport check_live_frame(const cv::Mat& image, const vision::TargetBoard& board,
                                 vision::AprilTagDetector& detector,
                                 const LiveCheckOptions& options) {
  if (image.empty() || image.channels() != 1 ||
      (image.depth() != CV_8U && image.depth() != CV_16U)) {
    throw std::invalid_argument("live check: needs a grey 8- or 16-bit image");
  }
  LiveCheckReport report;
  const bool wide = image.depth() == CV_16U;
  const double maximum = wide ? 65535.0 : 255.0;

  // Exposure: histogram, clipped fraction, bright level.
  report.histogram.assign(256, 0.0);
  long clipped = 0;
  for (int row = 0; row < image.rows; ++row) {
    for (int col = 0; col < image.cols; ++col) {
      const int value =
          wide ? image.at<unsigned short>(row, col) : image.at<unsigned char>(row, col);
      report.histogram[static_cast<std::size_t>(wide ? value / 256 : value)] += 1.0;
      clipped += value >= static_cast<int>(maximum) ? 1 : 0;
    }
  }
  const double pixels = static_cast<double>(image.total());
  double cumulative = 0.0;
  int percentile_bin = 255;
  for (std::size_t bin = 0; bin < report.histogram.size(); ++bin) {
    report.histogram[bin] /= pixels;
    cumulative += report.histogram[bin];
    if (cumulative >= 0.99 && percentile_bin == 255 && bin < 255) {
      percentile_bin = static_cast<int>(bin);
    }
  }
  report.clipped_fraction = static_cast<double>(clipped) / pixels;
  report.bright_level = (percentile_bin + 0.5) / 256.0;

  // Target and corners.
  cv::Mat gray = image;
  if (wide) {
    image.convertTo(gray, CV_8U, 1.0 / 257.0);
  }
  const vision::TargetDetection detection = vision::detect_target(gray, board, detector);
  const bool found = detection.status != vision::DetectionStatus::kRejected;
  report.corners = found ? static_cast<int>(detection.corner_ids.size()) : 0;
  report.board_corners = static_cast<int>(board.corners.size());
  report.edge_spread_px = found ? detection.edge_blur_px : std::nan("");

  LiveCheck target{"target", found, found ? 1.0 : 0.0, 1.0, "", ""};
  target.summary = found ? "target found" : "target not found (" + detection.reason + ")";
  if (!found) {
    target.advice =
        "Bring the whole target into the camera's view, facing the camera; check that the "
        "target file matches the printed board.";
  }
  report.checks.push_back(target);

  const double fraction =
      report.board_corners > 0 ? static_cast<double>(report.corners) / report.board_corners : 0.0;
  LiveCheck corners{"corners", found && fraction >= options.min_corner_fraction,
                    fraction,  options.min_corner_fraction,
                    "",        ""};
  corners.summary = fmt::format("{} of {} corners detected", report.corners, report.board_corners);
  if (!corners.ok) {
    corners.advice =
        "Part of the target is hidden, outside the image or glaring: move the camera or the "
        "target so the whole board is visible, and remove reflections.";
  }
  report.checks.push_back(corners);

  const bool spread_known = found && std::isfinite(report.edge_spread_px);
  LiveCheck sharpness{"sharpness",
                      spread_known && report.edge_spread_px <= options.max_edge_spread_px,
                      spread_known ? report.edge_spread_px : std::nan(""),
                      options.max_edge_spread_px,
                      "",
                      ""};
  sharpness.summary = spread_known ? fmt::format("edge spread {:.2f} px (limit {:.2f} px)",
                                                 report.edge_spread_px, options.max_edge_spread_px)
                                   : "edge spread unknown (no tag refined)";
  if (!sharpness.ok) {
    sharpness.advice =
        "The target's edges are blurred: focus the lens on the target at its working distance, "
        "close the aperture a little for more depth of field, or shorten the exposure if the "
        "target moves.";
  }
  report.checks.push_back(sharpness);

  const bool clipped_ok = report.clipped_fraction <= options.max_clipped_fraction;
  const bool bright_ok = report.bright_level >= options.min_bright_level;
  LiveCheck exposure{"exposure",
                     clipped_ok && bright_ok,
                     report.clipped_fraction,
                     options.max_clipped_fraction,
                     "",
                     ""};
  exposure.summary = fmt::format(
      "{:.2f}% of pixels clipped (limit {:.2f}%), brightest 1% at "
      "{:.0f}% of the range (at least {:.0f}%)",
      100.0 * report.clipped_fraction, 100.0 * options.max_clipped_fraction,
      100.0 * report.bright_level, 100.0 * options.min_bright_level);
  if (!clipped_ok) {
    exposure.advice =
        "Overexposed: shorten the exposure or lower the gain until no part of the "
        "target is saturated.";
  } else if (!bright_ok) {
    exposure.advice =
        "Underexposed: lengthen the exposure (keep it short enough for a still "
        "image), add light, or raise the gain a little.";
  }
  report.checks.push_back(exposure);
  return report;
}

}  // namespace robocal::robotio
