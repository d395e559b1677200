#pragma once
// A TargetBoard drawn by the exact planar renderer of synthetic_tags.hpp, with the homography that
// maps board points to their true pixels: the scaffolding of the detector tests and the vision
// accuracy bench.
#include <Eigen/Dense>
#include <opencv2/core.hpp>

#include "robocal/vision/target.hpp"
#include "synthetic_tags.hpp"
#include "target_boards.hpp"

namespace robocal::testing {

struct BoardView {
  cv::Mat image;
  Eigen::Matrix3d h;  ///< board plane -> image (true pixels)
};

/// `board` seen by `cam` as look_at_pose places it (board centre at image point (u, v)), with
/// the given Gaussian blur and noise (sigmas in pixels / grey levels) and noise seed.
inline BoardView render_board_view(const vision::TargetBoard& board, const SyntheticCamera& cam,
                                   double dist, double tilt_deg, double axis_deg, double roll_deg,
                                   double u, double v, double blur_sigma, double noise_sigma,
                                   unsigned seed = SyntheticImageOptions{}.seed) {
  const auto [r, t] =
      look_at_pose(cam, board_centre(board), dist, tilt_deg, axis_deg, roll_deg, u, v);
  SyntheticImageOptions opt;
  opt.blur_sigma = blur_sigma;
  opt.noise_sigma = noise_sigma;
  opt.seed = seed;
  BoardView out;
  out.h = board_homography(cam, r, t);
  out.image = render_planar(cam, out.h, opt, [&](double x, double y) {
    return vision::is_black(board, x, y) ? 0.0 : 1.0;
  });
  return out;
}

}  // namespace robocal::testing
