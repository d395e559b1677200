#pragma once
// The reprojection residual every camera fit minimises (internal): a board corner carried into
// the camera frame, projected through the lens model and compared with the pixel where it was
// seen, in units of its noise.
//
// The fits differ only in how the corner reaches the camera, i.e. in their parameter blocks:
// intrinsic calibration solves [intrinsics, camera_T_board], rig calibration [camera_T_rig,
// rig_T_board, intrinsics], pose measurement a perturbation of the board's world pose seen by a
// camera held fixed. Each says that as a `Chain` beside its solver; projection, residual and
// whitening are this one ReprojectionCost.
#include "robocal/vision/camera_models.hpp"

#include <ceres/rotation.h>
#include <Eigen/Core>

namespace robocal::vision::detail {

// A pose [rotation vector; translation] applied to a point: R p + t.
template <class T>
void transform_point(const T* pose, const T* point, T* out) {
  ceres::AngleAxisRotatePoint(pose, point, out);
  for (int i = 0; i < 3; ++i) out[i] += pose[3 + i];
}

// Chain(blocks..., project) computes the corner in the camera frame from the parameter blocks
// and returns project(intrinsics, camera_point).
template <class Model, class Chain>
struct ReprojectionCost {
  Chain chain;
  Eigen::Vector2d pixel;   // where the corner was seen (OpenCV convention)
  double inv_sigma = 1.0;  // 1: pixel residuals (whitened later as a CornerGroup)

  template <class T>
  bool operator()(const T* a, T* residual) const {
    return chain(a, projector(residual));
  }
  template <class T>
  bool operator()(const T* a, const T* b, T* residual) const {
    return chain(a, b, projector(residual));
  }
  template <class T>
  bool operator()(const T* a, const T* b, const T* c, T* residual) const {
    return chain(a, b, c, projector(residual));
  }

 private:
  template <class T>
  auto projector(T* residual) const {
    return [this, residual](const T* intrinsics, const T* camera_point) {
      T px[2];
      if (!Model::project(intrinsics, camera_point, px)) return false;
      residual[0] = (px[0] - T(pixel[0])) * T(inv_sigma);
      residual[1] = (px[1] - T(pixel[1])) * T(inv_sigma);
      return true;
    };
  }
};

}  // namespace robocal::vision::detail
