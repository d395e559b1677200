#include "robocal/vision/apriltag_detector.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <stdexcept>

#include "robocal/core/parallel.hpp"
#include "robocal/vision/edge_fit.hpp"

extern "C" {
#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>
}

namespace robocal::vision {

double pixel_noise_sigma(const cv::Mat& gray) {
  if (gray.empty() || gray.type() != CV_8UC1)
    throw std::invalid_argument("pixel noise: needs a non-empty 8-bit single-channel image");
  std::array<std::int64_t, 256> count{};
  for (int r = 0; r < gray.rows; ++r) {
    const std::uint8_t* row = gray.ptr<std::uint8_t>(r);
    for (int c = 1; c < gray.cols; ++c)
      ++count[static_cast<std::size_t>(std::abs(row[c] - row[c - 1]))];
  }
  std::int64_t total = 0;
  for (const std::int64_t n : count) total += n;
  if (total == 0) return 0.0;
  // The first integer k with at least half the pairs at |d| <= k. Modelling d as a continuous
  // Gaussian difference rounded to whole DN, P(|d| <= k) = erf((k + 1/2) / (sd sqrt 2)), which
  // gives its sigma sd; the rounding of each pixel added 1/12 DN^2 of variance to it.
  std::int64_t within = 0;
  std::size_t k = 0;
  while (2 * (within + count[k]) < total) within += count[k++];
  const double fraction = static_cast<double>(within + count[k]) / static_cast<double>(total);
  if (fraction >= 1.0) return 0.0;
  // erf(x) = fraction, by bisection (erf is increasing; fraction in [1/2, 1)).
  double lo = 0.0;
  double hi = 6.0;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (std::erf(mid) < fraction ? lo : hi) = mid;
  }
  const double sd = (static_cast<double>(k) + 0.5) / (std::sqrt(2.0) * 0.5 * (lo + hi));
  return std::sqrt(std::max(0.0, 0.5 * (sd * sd - 2.0 / 12.0)));
}

int min_white_black_diff_for(double noise_sigma, double min_decision_margin) {
  constexpr int kLibraryDefault = 5;
  const double wanted = 8.0 * std::max(0.0, noise_sigma);
  const double ceiling = std::max<double>(kLibraryDefault, 2.0 * min_decision_margin);
  return static_cast<int>(std::lround(std::clamp<double>(wanted, kLibraryDefault, ceiling)));
}

struct AprilTagDetector::Impl {
  AprilTagDetectorOptions options;
  apriltag_family_t* family = nullptr;
  void (*destroy_family)(apriltag_family_t*) = nullptr;
  apriltag_detector_t* detector = nullptr;

  ~Impl() {
    if (detector != nullptr) apriltag_detector_destroy(detector);
    if (family != nullptr && destroy_family != nullptr) destroy_family(family);
  }

  // The black border is one cell of width_at_border; the white quiet zone at least one cell.
  [[nodiscard]] QuadRefineOptions quad_refine_options() const {
    QuadRefineOptions refine_options;
    const double cell_fraction = 1.0 / static_cast<double>(family->width_at_border);
    refine_options.inner_band_fraction = cell_fraction;
    refine_options.outer_band_fraction = cell_fraction;
    return refine_options;
  }

  // Drops the tags whose quiet zone leaves the image. The library decodes tags cut by the image
  // border (its quad then follows the border: corners up to 10 px off), and no refinement can
  // measure an edge whose surround is outside the image.
  void drop_tags_cut_by_image_border(const cv::Mat& gray, std::vector<TagDetection>& tags) const {
    const double quiet_zone = quad_refine_options().outer_band_fraction;
    std::erase_if(tags, [&](const TagDetection& tag) {
      return !quad_surround_inside_image(tag.corners, quiet_zone, gray.size());
    });
  }

  // Refines every tag's corners from tag.corners on `gray` (the tags are independent: on the
  // detector's threads). A tag whose refinement fails keeps its corners and `refined` false.
  void refine_tags(const cv::Mat& gray, std::vector<TagDetection>& tags) const {
    const QuadRefineOptions refine_options = quad_refine_options();
    core::parallel_for(static_cast<int>(tags.size()), options.threads, [&](int i) {
      TagDetection& tag = tags[static_cast<size_t>(i)];
      if (const auto r = refine_quad_corners(gray, tag.corners, refine_options)) {
        tag.corners = r->corners;
        tag.refined = true;
        tag.edge_blur_px = r->mean_blur_sigma;
        tag.edge_contrast = r->mean_contrast;
        tag.corner_covariance = r->corner_covariance;
      }
    });
  }

  static void check_image(const cv::Mat& gray) {
    if (gray.empty() || gray.type() != CV_8UC1) {
      throw std::invalid_argument(
          "AprilTag detection needs a non-empty 8-bit single-channel image");
    }
  }

  std::vector<TagDetection> run(const cv::Mat& gray, bool refine) {
    check_image(gray);
    image_u8_t image{gray.cols, gray.rows, static_cast<int32_t>(gray.step[0]),
                     const_cast<uint8_t*>(gray.ptr<uint8_t>(0))};
    detector->qtp.min_white_black_diff =
        options.min_white_black_diff > 0
            ? options.min_white_black_diff
            : min_white_black_diff_for(pixel_noise_sigma(gray), options.min_decision_margin);
    zarray_t* found = apriltag_detector_detect(detector, &image);
    std::vector<TagDetection> out;
    out.reserve(static_cast<size_t>(zarray_size(found)));
    for (int i = 0; i < zarray_size(found); ++i) {
      apriltag_detection_t* det = nullptr;
      zarray_get(found, i, &det);
      if (det->decision_margin < options.min_decision_margin) continue;
      TagDetection tag;
      tag.id = det->id;
      tag.hamming = det->hamming;
      tag.decision_margin = det->decision_margin;
      for (size_t k = 0; k < 4; ++k) {
        tag.library_corners[k] = Eigen::Vector2d(det->p[k][0] + kAprilTagToOpenCvOffset,
                                                 det->p[k][1] + kAprilTagToOpenCvOffset);
      }
      tag.corners = tag.library_corners;
      tag.edge_blur_px = std::numeric_limits<double>::quiet_NaN();
      tag.edge_contrast = std::numeric_limits<double>::quiet_NaN();
      out.push_back(tag);
    }
    drop_tags_cut_by_image_border(gray, out);
    if (refine) {
      refine_tags(gray, out);
      drop_tags_cut_by_image_border(gray, out);
    }
    apriltag_detections_destroy(found);
    std::sort(out.begin(), out.end(),
              [](const TagDetection& a, const TagDetection& b) { return a.id < b.id; });
    return out;
  }
};

AprilTagDetector::AprilTagDetector(AprilTagDetectorOptions options)
    : impl_(std::make_unique<Impl>()) {
  if (!(options.quad_decimate >= 1.0f) || options.quad_decimate > 8.0f) {
    throw std::invalid_argument("AprilTag quad_decimate must be in [1, 8]");
  }
  if (options.threads < 1 || options.threads > 64) {
    throw std::invalid_argument("AprilTag threads must be in [1, 64]");
  }
  if (options.min_white_black_diff < 0 || options.min_white_black_diff > 255) {
    throw std::invalid_argument("AprilTag min_white_black_diff must be in [0, 255] (0: automatic)");
  }
  if (options.max_hamming < 0 || options.max_hamming > 2) {
    throw std::invalid_argument("AprilTag max_hamming must be 0, 1 or 2");
  }
  const std::string& name = options.family;
  if (name == "tag36h11") {
    impl_->family = tag36h11_create();
    impl_->destroy_family = tag36h11_destroy;
  } else if (name == "tag25h9") {
    impl_->family = tag25h9_create();
    impl_->destroy_family = tag25h9_destroy;
  } else if (name == "tag16h5") {
    impl_->family = tag16h5_create();
    impl_->destroy_family = tag16h5_destroy;
  } else if (name == "tagCircle21h7") {
    impl_->family = tagCircle21h7_create();
    impl_->destroy_family = tagCircle21h7_destroy;
  } else if (name == "tagStandard41h12") {
    impl_->family = tagStandard41h12_create();
    impl_->destroy_family = tagStandard41h12_destroy;
  } else if (name == "tagStandard52h13") {
    impl_->family = tagStandard52h13_create();
    impl_->destroy_family = tagStandard52h13_destroy;
  } else {
    throw std::invalid_argument("unknown AprilTag family '" + name +
                                "' (tag36h11, tag25h9, tag16h5, tagCircle21h7, tagStandard41h12, "
                                "tagStandard52h13)");
  }
  impl_->detector = apriltag_detector_create();
  apriltag_detector_add_family_bits(impl_->detector, impl_->family, options.max_hamming);
  impl_->detector->quad_decimate = options.quad_decimate;
  impl_->detector->quad_sigma = options.quad_sigma;
  impl_->detector->nthreads = options.threads;
  impl_->detector->refine_edges = options.refine_edges;
  impl_->detector->decode_sharpening = options.decode_sharpening;
  impl_->options = std::move(options);
}

AprilTagDetector::~AprilTagDetector() = default;
AprilTagDetector::AprilTagDetector(AprilTagDetector&&) noexcept = default;
AprilTagDetector& AprilTagDetector::operator=(AprilTagDetector&&) noexcept = default;

std::vector<TagDetection> AprilTagDetector::detect(const cv::Mat& gray) {
  return impl_->run(gray, impl_->options.subpixel_refine);
}

std::vector<TagDetection> AprilTagDetector::refine_at(const cv::Mat& gray,
                                                      const std::vector<TagDetection>& previous) {
  Impl::check_image(gray);
  std::vector<TagDetection> tags;
  tags.reserve(previous.size());
  for (const TagDetection& before : previous) {
    TagDetection tag;
    tag.id = before.id;
    tag.hamming = before.hamming;
    tag.decision_margin = before.decision_margin;
    tag.library_corners = before.corners;  // where the refinement starts
    tag.corners = before.corners;
    tag.edge_blur_px = std::numeric_limits<double>::quiet_NaN();
    tag.edge_contrast = std::numeric_limits<double>::quiet_NaN();
    tags.push_back(tag);
  }
  impl_->refine_tags(gray, tags);
  std::erase_if(tags, [](const TagDetection& tag) { return !tag.refined; });
  return tags;
}

std::vector<TagDetection> AprilTagDetector::detect_library_only(const cv::Mat& gray) {
  return impl_->run(gray, false);
}

const AprilTagDetectorOptions& AprilTagDetector::options() const {
  return impl_->options;
}

}  // namespace robocal::vision
