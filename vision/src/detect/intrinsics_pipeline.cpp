#include "robocal/vision/intrinsics_pipeline.hpp"

#include "robocal/vision/image_detection.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <fmt/format.h>

namespace robocal::vision {

bool is_image_file(const std::filesystem::path& file) {
  static const std::vector<std::string> exts = {".png", ".jpg",  ".jpeg", ".bmp",
                                                ".tif", ".tiff", ".pgm",  ".ppm"};
  std::string ext = file.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return std::find(exts.begin(), exts.end(), ext) != exts.end();
}

std::vector<std::filesystem::path> list_image_files(const std::filesystem::path& dir) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    throw std::invalid_argument(dir.string() + ": not a folder");
  }
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec))
    if (e.is_regular_file() && is_image_file(e.path())) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

IntrinsicsRun calibrate_from_folder(const std::filesystem::path& dir, const TargetBoard& board,
                                    const IntrinsicsPipelineOptions& options) {
  const auto files = list_image_files(dir);
  if (files.empty()) {
    throw std::invalid_argument(dir.string() +
                                ": no image files (png, jpg, bmp, tif, pgm) in the folder");
  }
  IntrinsicsRun run;
  std::vector<DetectionRequest> requests;
  requests.reserve(files.size());
  for (const auto& f : files) requests.push_back({f, 0, 0, {}});
  const auto detected = detect_in_images(requests, board, 1, {}, options.apriltag);
  std::vector<CalibrationView> views;
  for (std::size_t i = 0; i < files.size(); ++i) {
    const auto& f = files[i];
    const ImageDetection& d = detected[i];
    ImageRecord rec;
    rec.file = f.filename().string();
    if (d.width == 0) {  // unreadable
      rec.error = d.problem;
      run.images.push_back(rec);
      continue;
    }
    if (run.width == 0) {
      run.width = d.width;
      run.height = d.height;
    } else if (d.width != run.width || d.height != run.height) {
      rec.error = fmt::format("{}: size {}x{} differs from the first image's {}x{}", f.string(),
                              d.width, d.height, run.width, run.height);
      run.images.push_back(rec);
      continue;
    }
    const TargetDetection& det = d.detection;
    rec.status = det.status;
    rec.detail = det.reason;
    rec.corners = static_cast<int>(det.pixels.size());
    rec.edge_blur_px = det.edge_blur_px;
    run.images.push_back(rec);
    if (det.status != DetectionStatus::kRejected)
      views.push_back(to_calibration_view(det, rec.file));
  }
  IntrinsicCalibrationOptions copt = options.calibration;
  if (run.width == 0) {
    run.calibration.status = CalibrationStatus::kRefused;
    run.calibration.reason = "no readable image in the folder";
    return run;
  }
  copt.width = run.width;
  copt.height = run.height;
  run.calibration = calibrate_intrinsics(views, copt);
  return run;
}

std::string coverage_svg(const IntrinsicCalibrationResult& result, int width, int height) {
  std::string s = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" "
      "viewBox=\"-0.5 -0.5 {0} {1}\">\n"
      "<rect x=\"-0.5\" y=\"-0.5\" width=\"{0}\" height=\"{1}\" fill=\"white\" "
      "stroke=\"black\"/>\n",
      width, height);
  const CoverageMap& m = result.coverage;
  double max_sigma = 0.0;
  for (double v : m.projection_sigma_px)
    if (std::isfinite(v)) max_sigma = std::max(max_sigma, v);
  if (max_sigma > 0.0) {
    s += "<g id=\"projection-uncertainty\">\n";
    const double cw = static_cast<double>(width) / m.cols;
    const double ch = static_cast<double>(height) / m.rows;
    for (int r = 0; r < m.rows; ++r) {
      for (int c = 0; c < m.cols; ++c) {
        const double v = m.projection_sigma_px[static_cast<size_t>(r * m.cols + c)];
        if (!std::isfinite(v)) continue;
        const double t = std::clamp(v / max_sigma, 0.0, 1.0);
        s += fmt::format(
            "<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" "
            "fill=\"rgb({},{},{})\" fill-opacity=\"0.6\"><title>{:.3f} px (1 sigma), {} "
            "corners</title></rect>\n",
            c * cw - 0.5, r * ch - 0.5, cw, ch, static_cast<int>(255 * t),
            static_cast<int>(255 * (1 - t)), 80, v,
            m.corner_count[static_cast<size_t>(r * m.cols + c)]);
      }
    }
    s += "</g>\n";
  }
  s += "<g id=\"corners\">\n";
  for (const auto& cr : result.residuals) {
    s += fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"{}\" fill=\"{}\"/>\n", cr.pixel.x(),
                     cr.pixel.y(), cr.outlier ? 6 : 3, cr.outlier ? "red" : "#333");
  }
  s += "</g>\n<g id=\"uncovered\" fill=\"none\" stroke=\"red\" stroke-width=\"4\" "
       "stroke-dasharray=\"20,10\">\n";
  const auto& names = image_region_names();
  for (const auto& u : result.uncovered_regions) {
    const auto it = std::find(names.begin(), names.end(), u);
    if (it == names.end()) continue;
    const int idx = static_cast<int>(it - names.begin());
    const int column = idx % 3, row = idx / 3;
    s += fmt::format(
        "<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\"><title>no corners "
        "({})</title></rect>\n",
        column * width / 3.0 - 0.5, row * height / 3.0 - 0.5, width / 3.0, height / 3.0, u);
  }
  s += "</g>\n</svg>\n";
  return s;
}

}  // namespace robocal::vision
