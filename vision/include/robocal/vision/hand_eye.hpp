#pragma once
// Hand-eye calibration from the flange poses a controller reports, without a kinematic model:
// a fixed camera watching a board on the tool, or a camera on the tool watching a fixed board.
//
// Every view i ties the board pose the camera sees to the reported flange pose:
//   camera_T_target_i = Y · M_i · X
//   fixed camera:    Y = camera_T_base,    M_i = base_T_flange_i,   X = flange_T_target
//   camera on tool:  Y = camera_T_flange,  M_i = flange_T_base_i,   X = base_T_target
// The relative motions of two views give M_ij · X = X · C_ij (M_ij = M_i⁻¹ M_j, C_ij = C_i⁻¹ C_j),
// the classic AX = XB. A closed form (Park and Martin's rotation from the motions' rotation
// vectors, then the translation by linear least squares; Y averaged over the views) starts a
// joint bundle adjustment over both transforms (and, on request, the intrinsics) on the corner
// pixels of every view: the estimate that explains the images best, with its covariance.
//
// The data are checked before any estimate: a similar pair of motions turns by the same angle
// (angle(M_ij) = angle(C_ij) whatever X is), so reported rotations that disagree with what the
// camera sees (a quaternion order, another mounting, a pose file of another image) are found
// without a solve; positions of kilometres are millimetres read as metres.
#include "robocal/core/pose_covariance.hpp"
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/observations.hpp"
#include "robocal/vision/pose_measurement.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <optional>
#include <string>
#include <vector>

namespace robocal::vision {

enum class HandEyeMount { kFixedCamera, kCameraOnTool };

// "fixed_camera", "camera_on_tool".
const char* hand_eye_mount_name(HandEyeMount mount);

struct HandEyeView {
  std::string name;                                                 // the image, for messages
  Eigen::Isometry3d base_T_flange = Eigen::Isometry3d::Identity();  // as the controller reports
  CameraFrame frame;  // the board's corners in the image (none: the board was not seen)
};

struct HandEyeOptions {
  HandEyeMount mount = HandEyeMount::kFixedCamera;
  bool estimate_intrinsics = false;
  int min_views = 3;
  // Relative rotations smaller than this carry no information on the rotation (pairs skipped);
  // the views must turn about at least two axes this far apart.
  double min_motion_deg = 5.0;
  double min_axis_separation_deg = 10.0;
  // Median disagreement between the reported and the seen rotation angle of the views' motions
  // above which the poses are refused as inconsistent (a calibrated camera and robot agree to a
  // few hundredths of a degree).
  double max_rotation_mismatch_deg = 1.0;
  // Flange positions whose median distance from the base exceeds this are refused as
  // millimetres read as metres.
  double max_plausible_reach_m = 5.0;
  // A view whose reprojection RMS exceeds both this factor times the median view's and
  // min_outlier_view_px is excluded (one per round, worst first) and named.
  double outlier_view_factor = 3.0;
  double min_outlier_view_px = 0.5;
  int max_outlier_rounds = 3;
  PoseMeasurementOptions pose;  // the per-view board pose that starts the closed form
};

struct HandEyeViewReport {
  std::string name;
  bool used = false;
  std::string rejection;  // why the view is not in the estimate (empty when used)
  int corners = 0;
  double rms_px = 0.0;  // reprojection RMS per corner at the final estimate (NaN: not projectable)
};

enum class HandEyeStatus { kOk, kRefused, kFailed };

struct HandEyeResult {
  HandEyeStatus status = HandEyeStatus::kFailed;
  std::string reason;  // why refused or failed
  std::vector<std::string> warnings;
  HandEyeMount mount = HandEyeMount::kFixedCamera;
  // The two answers, in the frames users name them:
  //   fixed camera:   camera_pose = base_T_camera,   target_pose = flange_T_target
  //   camera on tool: camera_pose = flange_T_camera, target_pose = base_T_target
  Eigen::Isometry3d camera_pose = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d target_pose = Eigen::Isometry3d::Identity();
  core::PoseCovariance camera_pose_covariance = core::PoseCovariance::Zero();
  core::PoseCovariance target_pose_covariance = core::PoseCovariance::Zero();
  // The closed form's answer (the bundle adjustment's start).
  Eigen::Isometry3d camera_pose_closed_form = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d target_pose_closed_form = Eigen::Isometry3d::Identity();
  CameraModel camera;                     // as used; refined when the intrinsics are estimated
  std::vector<double> intrinsics_stddev;  // estimated intrinsics only
  double rms_px = 0.0;  // per corner (px, Euclidean) over the used views, as intrinsics reports it
  double residual_sigma_px = 0.0;      // per axis, dof-corrected
  double rotation_mismatch_deg = 0.0;  // median over the motions (the consistency check)
  int corners_used = 0;
  int iterations = 0;
  std::vector<HandEyeViewReport> views;
};

HandEyeResult calibrate_hand_eye(const CameraModel& camera, const BoardPoints& board,
                                 const std::vector<HandEyeView>& views,
                                 const HandEyeOptions& options = {});

// The closed form of A_k · X = X · B_k over the motions k: nullopt when their rotations do not
// determine X (fewer than two rotation axes at least `min_axis_separation_deg` apart among
// rotations of at least `min_motion_deg`).
std::optional<Eigen::Isometry3d> solve_ax_xb(const std::vector<Eigen::Isometry3d>& A,
                                             const std::vector<Eigen::Isometry3d>& B,
                                             double min_motion_deg = 5.0,
                                             double min_axis_separation_deg = 10.0);

// Reprojection RMS (px, per corner) of the views' corners under the given answer, projected as
// calibrate_hand_eye projects them; views with `use[i]` false are skipped (empty: all). For
// judging any solver's answer the same way.
double hand_eye_reprojection_rms(const CameraModel& camera, const BoardPoints& board,
                                 const std::vector<HandEyeView>& views, HandEyeMount mount,
                                 const Eigen::Isometry3d& camera_pose,
                                 const Eigen::Isometry3d& target_pose,
                                 const std::vector<bool>& use = {});

}  // namespace robocal::vision
