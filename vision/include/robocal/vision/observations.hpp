#pragma once
// Plain observations shared by rig calibration, pose measurement and the scale check. They do not
// depend on any detector: per camera and per frame, a list of (corner id, pixel) with an optional
// per-corner noise sigma. Pixels follow the project's convention (OpenCV's: (0,0) is the centre of
// the top-left pixel; see camera_models.hpp).
#include "robocal/vision/camera_model.hpp"

#include <Eigen/Geometry>

#include <limits>
#include <map>
#include <string>
#include <vector>

namespace robocal::vision {

struct CornerObservation {
  int id = 0;                                       // the board's corner id (see target.hpp)
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();  // OpenCV convention
  double sigma_px = 0.0;  // 1-sigma noise per axis; <= 0: unknown (the caller's default applies)
};

// Joint noise covariance of corners measured together, px^2, ordered (u0, v0, u1, v1, ...)
// like `corner_ids`. The four corners of a refined AprilTag are intersections of its four fitted
// edges: adjacent corners share an edge, so their errors are correlated, and an estimator that
// treats them as independent misjudges how well the tag's position and size are known (its
// covariance comes out too small). Estimators whiten each group by its covariance.
struct CornerGroup {
  std::vector<int> corner_ids;
  Eigen::MatrixXd covariance;
};

// What one camera saw of one board in one frame. An empty `corners` list means "not seen".
struct CameraFrame {
  std::vector<CornerObservation> corners;
  // Edge spread of the detected corners in px (e.g. TagDetection::edge_blur_px; ~0.3 sharp);
  // NaN when unknown. Used for the "blurred" quality flag only.
  double blur_px = std::numeric_limits<double>::quiet_NaN();
  // Optional joint covariances of groups of `corners` (by id); a corner in a group uses the
  // group's covariance instead of its sigma_px. Corners in no group are independent.
  std::vector<CornerGroup> corner_groups;
};

// Board geometry for the estimators: corner id -> point in the board frame (metres, z = 0 for
// planar boards). Build it from a TargetBoard's corners or from any other source.
using BoardPoints = std::map<int, Eigen::Vector3d>;

// A calibrated camera placed in a rig (world) frame.
struct RigCamera {
  std::string name;
  CameraModel model;
  // Maps world (rig) points into this camera: p_camera = camera_T_world * p_world.
  Eigen::Isometry3d camera_T_world = Eigen::Isometry3d::Identity();
  // Optional 6x6 covariance of camera_T_world (perturbation [d_theta; d_t] applied on the left:
  // camera_T_world = [exp(d_theta) R, t + d_t]); all zeros = unknown / exact.
  Eigen::Matrix<double, 6, 6> extrinsic_covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

}  // namespace robocal::vision
