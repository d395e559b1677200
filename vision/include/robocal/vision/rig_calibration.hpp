#pragma once
// Multi-camera rig calibration from a board seen in shared frames.
//
// 1. Per camera and view, planar PnP (IPPE) gives camera_T_board.
// 2. Extrinsics are chained from the reference camera through shared views (a camera that
//    shares views only with a non-reference camera is reached through it); for each link, the
//    view whose relative pose best explains all shared views is taken.
// 3. Bundle adjustment (Ceres; corners whitened by their sigma or, for a CornerGroup, by the
//    group's joint covariance; Huber loss and rejection of corners beyond k sigma) over every
//    camera pose except the reference one (the gauge: the rig frame IS the reference camera's
//    frame), every board pose and, optionally, intrinsics.
// 4. Covariance of the extrinsics from the corner noise (ceres::Covariance), reported in
//    RigCamera's convention, and the baseline (distance to the reference camera) +- sigma.
//
// Scale: metric scale comes from the board geometry only. A mis-printed board scales every
// translation; check it against a certified length with scale_check.hpp.
#include "robocal/vision/observations.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <optional>
#include <string>
#include <vector>

namespace robocal::vision {

struct RigCalibrationOptions {
  int reference_camera = 0;
  bool refine_intrinsics = false;  // all parameters of every camera's model
  double default_sigma_px = 0.1;   // corner noise where an observation carries none
  int min_corners_per_view = 6;    // fewer: the camera is treated as not seeing that view
  int max_iterations = 200;
  // Multiply the covariance by the variance factor chi2 / dof when it exceeds 1 (the corner
  // sigma was too optimistic). Off: the covariance trusts the given sigmas.
  bool inflate_covariance_by_residual = false;
  // Robust fitting: Huber loss on each residual block (whitened, in sigmas; <= 0: none) while
  // corners beyond outlier_sigmas times their own sigma are rejected round by round (the limit
  // grows with the robust spread of all residuals when the sigmas are optimistic); then a plain
  // least-squares solve on the inliers. outlier_sigmas <= 0: no rejection, plain least squares.
  double huber_sigmas = 3.0;
  double outlier_sigmas = 5.0;
  int max_outlier_rounds = 5;
};

// A corner rejected as an outlier and its residual (projected - observed, px) at the solution.
struct RigRejectedCorner {
  int view = 0;
  int camera = 0;
  int id = 0;
  Eigen::Vector2d residual_px = Eigen::Vector2d::Zero();
};

struct CameraCalibration {
  std::string name;
  CameraModel model;  // refined if refine_intrinsics
  Eigen::Isometry3d camera_T_rig = Eigen::Isometry3d::Identity();
  // 6x6 in RigCamera's convention ([d_theta; d_t] on the left of camera_T_rig); zero for the
  // reference camera.
  Eigen::Matrix<double, 6, 6> extrinsic_covariance = Eigen::Matrix<double, 6, 6>::Zero();
  // Camera centre in the rig frame and its covariance.
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Matrix3d position_covariance = Eigen::Matrix3d::Zero();
  double baseline_m = 0.0;  // distance of the centre from the reference camera's centre
  double baseline_sigma_m = 0.0;
  std::vector<double> intrinsic_sigma;  // per model parameter (empty if not refined)
  int views = 0;                        // views this camera contributed
  int corners = 0;                      // inlier corners
  int outliers = 0;                     // corners rejected
  double rms_px = 0.0;
};

struct RigCalibrationResult {
  bool ok = false;
  std::string message;  // the error when !ok; notes otherwise
  std::vector<CameraCalibration> cameras;
  // Per view: the board pose in the rig frame, or nullopt when no located camera saw it.
  std::vector<std::optional<Eigen::Isometry3d>> rig_T_board;
  // view_rms_px[v][c]: reprojection RMS of camera c in view v; NaN when it did not see it.
  std::vector<std::vector<double>> view_rms_px;
  // view_outliers[v][c]: corners of camera c in view v rejected as outliers; all in `rejected`.
  std::vector<std::vector<int>> view_outliers;
  std::vector<RigRejectedCorner> rejected;
  double rms_px = 0.0;
  double chi2 = 0.0;
  int dof = 0;
  int iterations = 0;
  double variance_factor = 1.0;  // chi2 / dof

  // The calibrated rig (world frame = rig frame), with extrinsic covariances.
  [[nodiscard]] std::vector<RigCamera> rig() const;
};

// cameras: name and intrinsic model of each camera (their camera_T_world is ignored).
// views[v][c]: what camera c saw in view v (empty: not seen). Never throws on bad data: returns
// ok = false with a message naming the cameras / views at fault. Throws std::invalid_argument
// if a view does not have one frame per camera.
RigCalibrationResult calibrate_rig(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                                   const std::vector<std::vector<CameraFrame>>& views,
                                   const RigCalibrationOptions& options = {});

// cv::stereoCalibrate on the same detections (CALIB_FIX_INTRINSIC, the corners both cameras saw
// in each view), for comparison. Only pinhole models (OpenCV's distortion layout).
struct OpenCvStereoResult {
  bool ok = false;
  std::string message;
  Eigen::Isometry3d b_T_a = Eigen::Isometry3d::Identity();  // camera b from camera a
  double baseline_m = 0.0;
  double rms_px = 0.0;
  int views = 0;
};
OpenCvStereoResult opencv_stereo_calibrate(const std::vector<RigCamera>& cameras,
                                           const BoardPoints& board,
                                           const std::vector<std::vector<CameraFrame>>& views,
                                           int camera_a, int camera_b, int min_common_corners = 6);

}  // namespace robocal::vision
