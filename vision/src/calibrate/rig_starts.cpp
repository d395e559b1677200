#include "calibrate/rig_starts.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <limits>

namespace robocal::vision::detail {

namespace {

int usable_corners(const BoardPoints& board, const CameraFrame& frame) {
  int n = 0;
  for (const CornerObservation& o : frame.corners)
    if (board.count(o.id) && o.pixel.allFinite()) ++n;
  return n;
}

// camera_T_rig of camera c from the views it shares with a located camera: of the candidates
// (one per shared view), the one that best explains c's corners in all of them; nullopt when it
// shares none yet.
std::optional<Eigen::Isometry3d> link_camera(size_t c, const Extrinsics& located,
                                             const std::vector<RigCamera>& cameras,
                                             const BoardPoints& board, const Views& views,
                                             const PlanarStarts& starts,
                                             const RigCalibrationOptions& options) {
  std::vector<std::pair<size_t, size_t>> shared;  // (view, located camera)
  for (size_t v = 0; v < views.size(); ++v) {
    if (starts[v][c].empty()) continue;
    for (size_t k = 0; k < cameras.size(); ++k)
      if (k != c && located[k] && !starts[v][k].empty()) shared.emplace_back(v, k);
  }
  if (shared.empty()) return std::nullopt;
  double best_cost = std::numeric_limits<double>::infinity();
  Eigen::Isometry3d best;
  for (const auto& [v, k] : shared) {
    const Eigen::Isometry3d rig_T_board =
        located[k]->inverse() * starts[v][k].front().camera_T_board;
    const Eigen::Isometry3d candidate = starts[v][c].front().camera_T_board * rig_T_board.inverse();
    double cost = 0.0;
    for (const auto& [w, j] : shared) {
      const Eigen::Isometry3d board_in_rig =
          located[j]->inverse() * starts[w][j].front().camera_T_board;
      cost += reprojection_chi2(cameras[c].model, board, views[w][c], candidate * board_in_rig,
                                options.default_sigma_px);
    }
    if (cost < best_cost) {
      best_cost = cost;
      best = candidate;
    }
  }
  return best;
}

}  // namespace

std::string camera_label(const std::vector<RigCamera>& cameras, size_t c) {
  return cameras[c].name.empty() ? fmt::format("camera {}", c)
                                 : fmt::format("camera {} '{}'", c, cameras[c].name);
}

PlanarStarts planar_starts(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                           const Views& views, const RigCalibrationOptions& options) {
  PlanarStarts starts(views.size(), std::vector<std::vector<PlanarPnpSolution>>(cameras.size()));
  for (size_t v = 0; v < views.size(); ++v)
    for (size_t c = 0; c < cameras.size(); ++c)
      if (usable_corners(board, views[v][c]) >= options.min_corners_per_view)
        starts[v][c] = planar_pnp_ippe(cameras[c].model, board, views[v][c]);
  return starts;
}

std::string unseen_camera(const std::vector<RigCamera>& cameras, const PlanarStarts& starts,
                          const RigCalibrationOptions& options) {
  for (size_t c = 0; c < cameras.size(); ++c) {
    const bool seen = std::any_of(starts.begin(), starts.end(),
                                  [&](const auto& view) { return !view[c].empty(); });
    if (!seen)
      return fmt::format(
          "rig calibration: {} sees the board (>= {} corners) in none of the {} views",
          camera_label(cameras, c), options.min_corners_per_view, starts.size());
  }
  return "";
}

Extrinsics chain_extrinsics(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                            const Views& views, const PlanarStarts& starts,
                            const RigCalibrationOptions& options) {
  Extrinsics located(cameras.size());
  located[static_cast<size_t>(options.reference_camera)] = Eigen::Isometry3d::Identity();
  bool progress = true;
  while (progress) {
    progress = false;
    for (size_t c = 0; c < cameras.size(); ++c) {
      if (located[c]) continue;
      located[c] = link_camera(c, located, cameras, board, views, starts, options);
      progress = progress || located[c].has_value();
    }
  }
  return located;
}

std::string unlinked_cameras(const std::vector<RigCamera>& cameras, const Extrinsics& located,
                             size_t ref) {
  std::vector<std::string> lost;
  for (size_t c = 0; c < cameras.size(); ++c)
    if (!located[c]) lost.push_back(camera_label(cameras, c));
  if (lost.empty()) return "";
  return fmt::format(
      "rig calibration: {} share{} no views with the reference {} (directly or through other "
      "cameras): show the board to both at once",
      fmt::join(lost, ", "), lost.size() == 1 ? "s" : "", camera_label(cameras, ref));
}

BoardStarts initial_board_poses(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                                const Views& views, const PlanarStarts& starts,
                                const Extrinsics& located, const RigCalibrationOptions& options) {
  const size_t nc = cameras.size();
  BoardStarts out;
  out.rig_T_board.assign(views.size(), Pose6{});
  out.view_used.assign(views.size(), false);
  for (size_t v = 0; v < views.size(); ++v) {
    double best_cost = std::numeric_limits<double>::infinity();
    Eigen::Isometry3d best;
    for (size_t k = 0; k < nc; ++k) {
      for (const auto& sol : starts[v][k]) {
        const Eigen::Isometry3d candidate = located[k]->inverse() * sol.camera_T_board;
        double cost = 0.0;
        for (size_t c = 0; c < nc; ++c)
          if (!starts[v][c].empty())
            cost += reprojection_chi2(cameras[c].model, board, views[v][c], *located[c] * candidate,
                                      options.default_sigma_px);
        if (cost < best_cost) {
          best_cost = cost;
          best = candidate;
        }
      }
    }
    if (std::isfinite(best_cost)) {
      pose_to_vec6(best, out.rig_T_board[v].data());
      out.view_used[v] = true;
    }
  }
  return out;
}

}  // namespace robocal::vision::detail
