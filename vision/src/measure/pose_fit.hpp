#pragma once
// The least-squares fit of one board pose over every camera of a rig (internal to measure/):
// the corners observed, the fit from a start, its linearisation for the covariance, and each
// corner's distance from it for the outlier rounds.
#include "robocal/vision/observations.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <limits>
#include <vector>

namespace robocal::vision::detail {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

// One observed corner with everything the residual needs.
struct Corner {
  int camera = 0;
  int frame = 0;
  int id = 0;
  Eigen::Vector3d board_point;
  Eigen::Vector2d pixel;
  double sigma = 0.1;                // used when the corner is in no group
  Eigen::Matrix2d marginal_inverse;  // inverse of its own 2x2 covariance (outlier test)
  bool outlier = false;
};

struct Observations {
  std::vector<Corner> corners;
  // Per (frame, camera): the corner groups given with it and the indices of its corners.
  struct Source {
    const std::vector<CornerGroup>* groups = nullptr;
    std::vector<size_t> indices;
  };
  std::vector<Source> sources;
};

struct FitResult {
  bool converged = false;
  Eigen::Isometry3d world_T_target = Eigen::Isometry3d::Identity();
  double chi2 = std::numeric_limits<double>::infinity();
};

struct Linearisation {
  Matrix6d information = Matrix6d::Zero();  // J^T J over the target perturbation
  std::vector<Matrix6d> cross;              // per camera: J_target^T J_camera
  std::vector<double> sq_px;                // per camera: sum of squared pixel residuals
  std::vector<int> count;
  double chi2 = 0.0;
  bool ok = true;
};

// The corners of `frames` (per frame, one CameraFrame per camera) that the board knows.
Observations gather(const std::vector<RigCamera>& rig, const BoardPoints& board,
                    const std::vector<const std::vector<CameraFrame>*>& frames,
                    double default_sigma);

// Levenberg-Marquardt over the 6 pose perturbation parameters (the covariance is evaluated
// afterwards by linearise(), re-centred at the solution).
// huber_scale > 0: robust (Huber) loss on each block's whitened residual norm.
FitResult refine(const std::vector<RigCamera>& rig, const Observations& obs,
                 const Eigen::Isometry3d& start, double huber_scale = 0.0);

Linearisation linearise(const std::vector<RigCamera>& rig, const Observations& obs,
                        const Eigen::Isometry3d& pose);

// Squared Mahalanobis distance of each corner's pixel residual under its own 2x2 covariance.
std::vector<double> corner_d2(const std::vector<RigCamera>& rig, const Observations& obs,
                              const Eigen::Isometry3d& world_T_target);

}  // namespace robocal::vision::detail
