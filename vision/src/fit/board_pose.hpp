#pragma once
// Internals shared by pose measurement, rig calibration and the scale check.
#include "robocal/vision/observations.hpp"

#include <ceres/rotation.h>
#include <Eigen/Geometry>

#include <array>
#include <optional>
#include <vector>

namespace robocal::vision::detail {

// A board pose hypothesis from planar PnP in one camera, with its RMS reprojection error (px).
struct PlanarPnpSolution {
  Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
  double rms_px = 0.0;
};

// Both IPPE solutions (best first) for the corners of `frame` that the board knows. Corners are
// undistorted through the camera model first, so any lens model works. Empty when fewer than 4
// usable corners or IPPE fails.
std::vector<PlanarPnpSolution> planar_pnp_ippe(const CameraModel& camera, const BoardPoints& board,
                                               const CameraFrame& frame);

// Sum of squared whitened reprojection residuals of `frame` for a board pose; +inf where a
// point cannot be projected.
double reprojection_chi2(const CameraModel& camera, const BoardPoints& board,
                         const CameraFrame& frame, const Eigen::Isometry3d& camera_T_board,
                         double default_sigma_px, int* used = nullptr);

// exp(w) * v for a rotation vector w (templated for Jets).
template <class T>
void rotate(const T* w, const T* v, T* out) {
  ceres::AngleAxisRotatePoint(w, v, out);
}

// Rotation matrix of a rotation vector and back (double).
Eigen::Matrix3d exp_so3(const Eigen::Vector3d& w);
Eigen::Vector3d log_so3(const Eigen::Matrix3d& R);

// Pose from / to [rotation vector; translation].
Eigen::Isometry3d pose_from_vec6(const double* v);
void pose_to_vec6(const Eigen::Isometry3d& pose, double* v);

inline double sigma_or(double sigma, double fallback) {
  return sigma > 0.0 ? sigma : fallback;
}

}  // namespace robocal::vision::detail
