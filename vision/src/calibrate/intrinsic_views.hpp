#pragma once
// Intrinsic calibration's views before the fit (internal): which views can be used, the start of
// the focal length and of every board pose, and how well the views cover the image.
#include "robocal/vision/intrinsic_calibration.hpp"

#include <Eigen/Geometry>

#include <array>
#include <vector>

namespace robocal::vision::detail {

using Pose6 = std::array<double, 6>;  // [rotation vector; translation]

Eigen::Isometry3d to_isometry(const Pose6& p);
Pose6 from_isometry(const Eigen::Isometry3d& t);

// The views the fit uses, each with its index in IntrinsicCalibrationResult::views and (once
// posed) its board pose.
struct UsedViews {
  std::vector<const CalibrationView*> views;
  std::vector<size_t> report;
  std::vector<Pose6> poses;
};

// The views whose observations are consistent and plenty; every view gets its report (with the
// reason when it is not used).
UsedViews screen_views(const std::vector<CalibrationView>& views,
                       const IntrinsicCalibrationOptions& options,
                       IntrinsicCalibrationResult& result);

// (fx, fy) to start from: Zhang's constraints over the views' homographies with the principal
// point at the image centre, or a plausible guess where they are degenerate.
Eigen::Vector2d focal_start(const UsedViews& used, const IntrinsicCalibrationOptions& options);

struct ViewTilts {
  int tilted = 0;  // views tilted by at least good_tilt_deg
  double max_tilt_deg = 0.0;
};

// Poses every view by IPPE through the starting pinhole camera; a view without a pose, or with
// the board seen from behind, is dropped with its reason.
ViewTilts pose_views(UsedViews& used, const Eigen::Vector4d& pinhole,
                     const IntrinsicCalibrationOptions& options,
                     IntrinsicCalibrationResult& result);

// The 3x3 image regions no corner falls in, and the advice to fill them.
void find_uncovered_regions(const UsedViews& used, const IntrinsicCalibrationOptions& options,
                            IntrinsicCalibrationResult& result);

// Angle between the board normal and the line of sight to the board's observed centre.
double view_tilt_deg(const CalibrationView& v, const Eigen::Isometry3d& camera_T_board);

}  // namespace robocal::vision::detail
