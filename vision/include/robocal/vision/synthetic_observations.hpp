#pragma once
// Exact synthetic corner observations (projection of known board points + Gaussian pixel noise),
// for tests and benchmarks of the estimators. Rendered images (renderer.hpp) exercise the
// detector as well; these exercise the estimators and their covariances alone.
#include "robocal/vision/observations.hpp"

#include <random>

namespace robocal::vision {

// Corner points of an AprilTag grid with target.hpp's ids and layout: cols x rows tags of side
// `tag_size` (black square), `spacing` between neighbouring squares, first id `first_id`
// row-major; id = tag_id * 4 + k (k = 0 bottom-left, 1 bottom-right, 2 top-right, 3 top-left).
BoardPoints apriltag_grid_points(int cols, int rows, double tag_size, double spacing,
                                 int first_id = 0);

// Every board point that projects into the image (at least `margin_px` from the border) of a
// camera that faces the printed side; pixel noise N(0, sigma_px^2) per axis (sigma_px = 0: exact).
// Each observation carries sigma_px as its noise (or `reported_sigma_px` when > 0).
CameraFrame simulate_frame(const CameraModel& camera, const Eigen::Isometry3d& camera_T_board,
                           const BoardPoints& board, double sigma_px, std::mt19937_64& rng,
                           double margin_px = 2.0, double reported_sigma_px = 0.0);

// Scales every board point by `factor` about the board origin (a print at factor * 100 %).
BoardPoints scaled_board(const BoardPoints& board, double factor);

}  // namespace robocal::vision
