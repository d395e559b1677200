#pragma once
// Intrinsic camera calibration from views of a planar target.
//
// Pipeline: per-view sanity checks -> Zhang-style initialisation from homographies (principal
// point at the image centre, focal lengths from the orthogonality constraints, poses by IPPE) ->
// Ceres bundle adjustment over intrinsics and board poses with a Huber loss -> iterative outlier
// rejection (residuals beyond k robust sigma) -> a final plain least-squares solve on the inliers,
// whose Jacobian gives the parameter covariance (scaled by the residual variance).
// All pixels follow the project convention (OpenCV's: (0,0) = centre of the top-left pixel);
// board points are in metres on the board plane z = 0.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/observations.hpp"

namespace robocal::vision {

/// The observations of one image: board points and where they were seen.
struct CalibrationView {
  std::string name;  ///< image file name (for reports)
  std::vector<int> corner_ids;
  std::vector<Eigen::Vector3d> board_points;  ///< metres, z = 0
  std::vector<Eigen::Vector2d> pixels;        ///< OpenCV convention
  /// Optional joint covariances of groups of corners (by id, see observations.hpp): with them the
  /// bundle adjustment weights each group by its inverse covariance (generalised least squares)
  /// instead of treating all corners as independent and equally noisy.
  std::vector<CornerGroup> corner_groups;
};

struct IntrinsicCalibrationOptions {
  CameraKind kind = CameraKind::kPinholeRadtan;
  int width = 0;  ///< image size (px), required
  int height = 0;
  double huber_px = 1.0;         ///< robust loss scale during outlier rounds
  double outlier_sigmas = 4.0;   ///< corners beyond this many robust sigma are rejected
  double min_outlier_px = 0.05;  ///< never reject residuals below this (noise-free data)
  int max_outlier_rounds = 4;
  int min_corners_per_view = 8;
  int min_views = 4;                 ///< fewer usable views: refused
  int recommended_views = 10;        ///< fewer: warning
  double min_max_tilt_deg = 10.0;    ///< all views flatter than this: refused (f unobservable)
  double good_tilt_deg = 20.0;       ///< fewer than 3 views this tilted: warning
  int max_uncovered_regions = 5;     ///< of the 3x3 image regions; more uncovered: refused
  double high_rms_warning_px = 0.3;  ///< RMS above this: warning (focus, flatness, detection)
  int coverage_cols = 16;            ///< resolution of the coverage / uncertainty map
  int coverage_rows = 12;
  int max_iterations = 200;
  /// Start from these parameters (same layout as CameraModel::params) instead of the
  /// homography initialisation; empty: initialise from the views.
  std::vector<double> initial_params;
};

enum class CalibrationStatus { kOk, kRefused, kFailed };

struct ViewReport {
  std::string name;
  bool used = false;
  std::string rejection;  ///< why the view was not used (empty if used)
  Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
  double tilt_deg = 0.0;  ///< angle between the board normal and the line of sight to it
  double rms_px = 0.0;    ///< over the view's inlier corners
  int corners = 0;
  int outliers = 0;
};

struct CornerResidual {
  int view = 0;
  int corner_id = 0;
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
  Eigen::Vector2d residual = Eigen::Vector2d::Zero();  ///< projected - observed (px)
  bool outlier = false;
};

/// Per-cell observation count and projection uncertainty over the image.
struct CoverageMap {
  int cols = 0;
  int rows = 0;
  std::vector<int> corner_count;  ///< row-major, cols x rows
  /// 1-sigma projection uncertainty (px, RMS over both axes) of a point seen through the cell
  /// at 1 m depth, from the intrinsics covariance alone (the camera frame held fixed).
  std::vector<double> projection_sigma_px;
};

struct IntrinsicCalibrationResult {
  CalibrationStatus status = CalibrationStatus::kFailed;
  std::string reason;                 ///< why refused / failed (empty when ok)
  std::vector<std::string> warnings;  ///< ok, but the user should know
  std::vector<std::string> advice;    ///< which views to add
  CameraModel camera;
  std::vector<std::string> param_names;
  std::vector<double> param_stddev;  ///< 1-sigma, same order as camera.params
  Eigen::MatrixXd param_covariance;
  double rms_px = 0.0;             ///< over all inlier corners
  double residual_sigma_px = 0.0;  ///< per-axis residual std (px, dof-corrected)
  /// chi2 / dof of the weighted fit; the parameter covariance is (J^T W J)^-1 times this. With
  /// no corner covariances (unit weights) it is residual_sigma_px^2.
  double variance_factor = 1.0;
  int corners_used = 0;
  int corners_rejected = 0;
  int iterations = 0;
  bool converged = false;
  std::vector<ViewReport> views;
  std::vector<CornerResidual> residuals;
  CoverageMap coverage;
  std::vector<std::string> uncovered_regions;  ///< of the 3x3 image regions, by name
};

/// Calibrates. Never throws for bad data: bad views are reported per view, and the whole
/// calibration is refused (with reason and advice) when the remaining views cannot determine
/// the intrinsics. Throws std::invalid_argument only for invalid options (no image size,
/// initial_params of the wrong size).
IntrinsicCalibrationResult calibrate_intrinsics(const std::vector<CalibrationView>& views,
                                                const IntrinsicCalibrationOptions& options);

/// Names of the 3x3 image regions, row-major ("top-left" ... "bottom-right").
const std::vector<std::string>& image_region_names();

}  // namespace robocal::vision
