#include "robocal/vision/synthetic_observations.hpp"

namespace robocal::vision {

BoardPoints apriltag_grid_points(int cols, int rows, double tag_size, double spacing,
                                 int first_id) {
  BoardPoints out;
  const double pitch = tag_size + spacing;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const int tag = first_id + r * cols + c;
      const double x = c * pitch;
      const double y = r * pitch;
      out[tag * 4 + 0] = Eigen::Vector3d(x, y + tag_size, 0.0);
      out[tag * 4 + 1] = Eigen::Vector3d(x + tag_size, y + tag_size, 0.0);
      out[tag * 4 + 2] = Eigen::Vector3d(x + tag_size, y, 0.0);
      out[tag * 4 + 3] = Eigen::Vector3d(x, y, 0.0);
    }
  }
  return out;
}

CameraFrame simulate_frame(const CameraModel& camera, const Eigen::Isometry3d& camera_T_board,
                           const BoardPoints& board, double sigma_px, std::mt19937_64& rng,
                           double margin_px, double reported_sigma_px) {
  CameraFrame frame;
  // The printed face is z = 0 with z pointing into the board: the camera must be on the -z side.
  const Eigen::Vector3d normal = camera_T_board.linear().col(2);
  if (!(normal.dot(camera_T_board.translation()) > 0.0)) return frame;
  std::normal_distribution<double> noise(0.0, 1.0);
  for (const auto& [id, point] : board) {
    const auto px = project(camera, camera_T_board * point);
    if (!px || !in_image(camera, *px, margin_px)) continue;
    CornerObservation obs;
    obs.id = id;
    obs.pixel = *px;
    if (sigma_px > 0.0) {
      const double nx = noise(rng);
      const double ny = noise(rng);
      obs.pixel += sigma_px * Eigen::Vector2d(nx, ny);
    }
    obs.sigma_px = reported_sigma_px > 0.0 ? reported_sigma_px : sigma_px;
    frame.corners.push_back(obs);
  }
  return frame;
}

BoardPoints scaled_board(const BoardPoints& board, double factor) {
  BoardPoints out;
  for (const auto& [id, p] : board) out[id] = factor * p;
  return out;
}

}  // namespace robocal::vision
