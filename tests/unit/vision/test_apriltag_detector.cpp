#include <gtest/gtest.h>

#include <cmath>

#include "robocal/vision/apriltag_detector.hpp"
#include "synthetic_tags.hpp"

namespace rv = robocal::vision;
namespace rt = robocal::testing;

namespace {

struct ErrorStats {
  double rms = 0.0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  double radial = 0.0;
  int count = 0;
  int tags = 0;
};

// Corner error statistics of detections against truth (matched by id).
ErrorStats compare(const std::vector<rv::TagDetection>& found,
                   const std::vector<rt::SyntheticTag>& truth, bool library_corners) {
  ErrorStats s;
  for (const auto& t : truth) {
    for (const auto& d : found) {
      if (d.id != t.id) continue;
      ++s.tags;
      const Eigen::Vector2d centre =
          (t.corners[0] + t.corners[1] + t.corners[2] + t.corners[3]) / 4;
      for (size_t k = 0; k < 4; ++k) {
        const Eigen::Vector2d e =
            (library_corners ? d.library_corners[k] : d.corners[k]) - t.corners[k];
        s.rms += e.squaredNorm();
        s.mean += e;
        s.radial += e.dot((t.corners[k] - centre).normalized());
        ++s.count;
      }
    }
  }
  if (s.count > 0) {
    s.rms = std::sqrt(s.rms / s.count);
    s.mean /= s.count;
    s.radial /= s.count;
  }
  return s;
}

}  // namespace

TEST(AprilTagDetector, ExperimentSweep) {
  rt::SyntheticCamera cam;
  rt::TagGrid grid;
  grid.cols = 6;
  grid.rows = 5;
  grid.tag_mm = 40;
  grid.gap_mm = 10;
  rt::TagGridRenderer renderer(grid);
  rv::AprilTagDetector det;
  for (double tilt : {0.0, 30.0, 45.0}) {
    for (double blur : {0.0, 0.8, 1.5}) {
      auto [r, t] = rt::look_at_pose(cam, renderer.board_size() / 2, 600, tilt, 30, 10, 640, 512);
      rt::SyntheticImageOptions opt;
      opt.blur_sigma = blur;
      opt.noise_sigma = 2.0;
      std::vector<rt::SyntheticTag> truth;
      cv::Mat img = renderer.render(cam, rt::board_homography(cam, r, t), opt, &truth);
      auto found = det.detect(img);
      auto ours = compare(found, truth, false);
      auto lib = compare(found, truth, true);
      int refined = 0;
      double blur_est = 0;
      for (auto& d : found) {
        refined += d.refined;
        blur_est += d.edge_blur_px / found.size();
      }
      printf(
          "tilt %4.0f blur %.1f: truth %zu found %zu refined %d blurest %.3f | ours rms %.4f bias "
          "(%.4f %.4f) rad %.4f | lib rms %.4f bias (%.4f %.4f) rad %.4f\n",
          tilt, blur, truth.size(), found.size(), refined, blur_est, ours.rms, ours.mean.x(),
          ours.mean.y(), ours.radial, lib.rms, lib.mean.x(), lib.mean.y(), lib.radial);
    }
  }
}
