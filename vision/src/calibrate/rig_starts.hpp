#pragma once
// Rig calibration's starting point (internal): each camera's board poses by planar PnP, the
// extrinsics chained from the reference camera through the views cameras share, and a board
// pose per view.
#include "robocal/vision/rig_calibration.hpp"

#include "fit/board_pose.hpp"

#include <Eigen/Geometry>

#include <array>
#include <optional>
#include <string>
#include <vector>

namespace robocal::vision::detail {

using Pose6 = std::array<double, 6>;  // [rotation vector; translation]
using Views = std::vector<std::vector<CameraFrame>>;
// starts[v][c]: both IPPE solutions (best first) of camera c in view v; empty where it saw
// too few corners.
using PlanarStarts = std::vector<std::vector<std::vector<PlanarPnpSolution>>>;
using Extrinsics = std::vector<std::optional<Eigen::Isometry3d>>;

std::string camera_label(const std::vector<RigCamera>& cameras, size_t c);

// Step 1: per camera and view, the IPPE solutions where enough corners are seen.
PlanarStarts planar_starts(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                           const Views& views, const RigCalibrationOptions& options);

// The first camera with no start in any view, as the message saying so; "" when all have one.
std::string unseen_camera(const std::vector<RigCamera>& cameras, const PlanarStarts& starts,
                          const RigCalibrationOptions& options);

// Step 2: the extrinsics chained from the reference camera through shared views (a camera that
// shares views only with another non-reference camera is reached through it).
Extrinsics chain_extrinsics(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                            const Views& views, const PlanarStarts& starts,
                            const RigCalibrationOptions& options);

// The cameras no chain reached, as the message saying so; "" when all were.
std::string unlinked_cameras(const std::vector<RigCamera>& cameras, const Extrinsics& located,
                             size_t ref);

struct BoardStarts {
  std::vector<Pose6> rig_T_board;
  std::vector<bool> view_used;  // some located camera saw the view
};

// Step 3: the board pose per view: the (camera, IPPE branch) that best explains every camera's
// corners.
BoardStarts initial_board_poses(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                                const Views& views, const PlanarStarts& starts,
                                const Extrinsics& located, const RigCalibrationOptions& options);

}  // namespace robocal::vision::detail
