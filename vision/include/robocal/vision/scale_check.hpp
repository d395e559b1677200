#pragma once
// Scale check of a calibrated rig against an independent certified length.
//
// The rig's metric scale comes from the calibration board's geometry alone: a board printed at
// 99.5 % of its nominal size makes every rig length 1/0.995 too long and nothing in the
// calibration's residuals shows it. A scale bar -- two targets at a certified distance -- checks
// it: the two reference points (each the centroid of a set of corners, e.g. a tag's four outer
// corners, i.e. its centre, which does not depend on how the bar's own tags were printed) are
// TRIANGULATED by two or more cameras, so the measured distance depends only on the rig.
//
// The robot's commanded motion is not an independent length (it assumes the model being
// calibrated) and is not used here.
#include "robocal/vision/observations.hpp"
#include "robocal/vision/rig_calibration.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace robocal::vision {

struct ScaleBar {
  std::string name = "scale bar";
  std::vector<int> corners_a;  // corner ids whose centroid is end A (e.g. tag_id * 4 + 0..3)
  std::vector<int> corners_b;  // ... end B
  double certified_length_m = 0.0;
  double certified_sigma_m = 0.0;  // 1-sigma of the certificate
};

struct ScaleBarFrame {
  bool ok = false;
  std::string message;  // why not ok (e.g. "corner 402 seen by fewer than 2 cameras")
  double length_m = 0.0;
  double sigma_m = 0.0;
};

struct ScaleCheck {
  bool ok = false;  // at least one frame measured
  std::string message;
  std::vector<ScaleBarFrame> frames;
  double measured_length_m = 0.0;  // weighted mean over the usable frames
  double measured_sigma_m = 0.0;
  // Factor to multiply every rig length by so the bar matches its certificate
  // (= certified / measured), with its 1-sigma (measurement and certificate).
  double scale_factor = 1.0;
  double scale_factor_sigma = 0.0;
  double discrepancy = 0.0;  // measured / certified - 1 (0.005 = rig lengths 0.5 % too long)
  // |discrepancy| is beyond `significance` sigma AND beyond `tolerance`: the rig's scale is
  // wrong, most likely because the calibration board was not printed at 100 %.
  bool scale_error = false;
  std::string verdict;  // one line for the user, naming the board and its apparent print scale
};

struct ScaleCheckOptions {
  double default_sigma_px = 0.1;
  double significance = 4.0;  // sigmas
  double tolerance = 1e-4;    // relative (0.01 %)
  std::string calibration_board_name = "calibration board";
};

// frames[f][c]: what camera c saw of the bar in frame f (corner ids of corners_a/corners_b).
// Throws std::invalid_argument when the bar is malformed or a frame's size != rig size.
ScaleCheck check_scale(const std::vector<RigCamera>& rig, const ScaleBar& bar,
                       const std::vector<std::vector<CameraFrame>>& frames,
                       const ScaleCheckOptions& options = {});

// Triangulates one point seen by two or more cameras (pixel sigma per observation): linear
// ray-intersection start, then Gauss-Newton on the reprojection error. Returns false when fewer
// than two cameras see it or the rays are (nearly) parallel.
bool triangulate_point(const std::vector<RigCamera>& rig,
                       const std::vector<std::pair<int, CornerObservation>>& observations,
                       double default_sigma_px, Eigen::Vector3d* point,
                       Eigen::Matrix3d* covariance);

}  // namespace robocal::vision
