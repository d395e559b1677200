#pragma once
// End-effector (target) pose measurement with one or more calibrated cameras.
//
// Per camera: IPPE on the undistorted corners gives both planar-PnP solutions. All of them (from
// every camera) are refined jointly over every camera that sees the target (Ceres, camera poses
// and intrinsics held fixed); distinct local minima are kept, the best wins, and the measurement
// is flagged ambiguous when the runner-up explains the corners nearly as well (typical of a
// single camera at an oblique or distant view; a second camera usually resolves it).
//
// NOISE: corners carry a sigma (or the default), or a joint covariance per CornerGroup of a
// camera frame (e.g. the four corners of a refined AprilTag, whose errors are correlated); each
// group is one residual block whitened by its covariance.
// ROBUSTNESS: Huber loss and rejection of corners beyond k sigma (options), reported per pose
// and per camera.
//
// COVARIANCE: 6x6 over [d_theta (rad); d_t (m)] with the perturbation applied in the world
// frame: world_T_target = [exp(d_theta) R, t + d_t]. So the lower-right 3x3 block is the
// covariance of the target origin's position in world coordinates. It comes from the corner
// noise (sigma per corner, or the default) and, when a camera carries an extrinsic covariance,
// from the rig's uncertainty too (first-order propagation).
#include "robocal/core/chi_square.hpp"
#include "robocal/vision/observations.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <limits>
#include <string>
#include <vector>

namespace robocal::vision {

struct PoseMeasurementOptions {
  double default_sigma_px = 0.1;  // corner noise where an observation carries none
  int min_corners = 12;           // fewer corners in all cameras together: flag few_corners
  // Ambiguity: the runner-up local minimum's chi2 is below EITHER ratio * best (guards against
  // an underestimated sigma) OR best + min_delta (guards against tiny costs at low noise).
  double ambiguity_cost_ratio = 4.0;
  double ambiguity_min_delta_chi2 = 50.0;
  // ... among poses whose Mahalanobis distance (squared, 6 dof) from the best exceeds this: a
  // broad single minimum is expressed by the covariance, not by the flag.
  double ambiguity_min_separation_chi2 = 36.0;
  // A camera frame whose blur_px exceeds this is flagged blurred (NaN blur: not judged).
  double max_blur_px = 2.0;
  bool include_extrinsic_covariance = true;
  // Settled-frame test: false-alarm probability of the chi-square test on the pose difference.
  double motion_false_alarm = 1e-4;
  // Robust fitting: Huber loss on each residual block (whitened, in sigmas; <= 0: plain least
  // squares), then rounds rejecting corners whose residual exceeds outlier_sigmas times their
  // own sigma (Mahalanobis under their 2x2 covariance; the limit grows with the robust spread of
  // all residuals when the sigmas are too optimistic). outlier_sigmas <= 0: no rejection. The
  // final pose and covariance are a plain least-squares fit on the inliers.
  double huber_sigmas = 3.0;
  double outlier_sigmas = 5.0;
  int max_outlier_rounds = 5;
};

// A corner rejected as an outlier: where it was seen and its residual at the final pose.
struct RejectedCorner {
  int frame = 0;   // index of the frame (measure_settled_pose: all frames)
  int camera = 0;  // index in the rig
  int id = 0;      // board corner id
  Eigen::Vector2d residual_px = Eigen::Vector2d::Zero();  // projected - observed
};

enum class PoseStatus {
  kOk,             // a pose was measured (look at the quality flags too)
  kNotSeen,        // no camera saw the target
  kTooFewCorners,  // fewer than 4 corners in every camera: no initial pose
  kMoving,         // several frames disagree beyond the noise: the target moved
  kFailed,         // the solver did not converge (message says why)
};
const char* pose_status_name(PoseStatus status);

struct CameraPoseDiagnostics {
  int camera = 0;       // index in the rig
  int corners = 0;      // corners of this camera used in the fit
  double rms_px = 0.0;  // reprojection RMS (per axis) at the final pose
  // IPPE alone in this camera: RMS of the second solution / RMS of the first (>= 1; inf if
  // only one solution). Values near 1 mean this camera alone cannot tell the two apart.
  double ippe_rms_ratio = std::numeric_limits<double>::infinity();
  bool blurred = false;
  int outliers = 0;  // corners of this camera rejected as outliers
};

struct PoseMeasurement {
  PoseStatus status = PoseStatus::kFailed;
  std::string message;  // why, for anything but a clean kOk
  Eigen::Isometry3d world_T_target = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 6> covariance_corner_noise = Eigen::Matrix<double, 6, 6>::Zero();
  double chi2 = 0.0;  // sum of squared whitened residuals at the solution
  int dof = 0;        // 2 * corners - 6
  double rms_px = 0.0;
  int corners = 0;   // inlier corners used
  int outliers = 0;  // corners rejected (listed in `rejected`)
  std::vector<RejectedCorner> rejected;
  int frames_used = 0;
  // Runner-up (another planar-PnP branch: a local minimum well outside the best pose's noise
  // ellipsoid) and its chi2; inf when none exists.
  double alternative_chi2 = std::numeric_limits<double>::infinity();
  Eigen::Isometry3d world_T_target_alternative = Eigen::Isometry3d::Identity();
  // Quality flags.
  bool ambiguous = false;
  bool few_corners = false;
  bool blurred = false;
  bool moving = false;
  double motion_chi2 = 0.0;  // largest chi-square of the settled-frame test (6 dof)
  std::vector<CameraPoseDiagnostics> cameras;

  // A clean measurement a robot identification can use.
  [[nodiscard]] bool usable() const {
    return status == PoseStatus::kOk && !ambiguous && !few_corners && !blurred && !moving;
  }
};

// One frame: frame[c] is what camera c (rig[c]) saw; empty corner lists are ignored. Corner ids
// missing from `board` are ignored. Never throws on bad observations; the status says what
// happened. Throws std::invalid_argument when frame.size() != rig.size().
PoseMeasurement measure_target_pose(const std::vector<RigCamera>& rig, const BoardPoints& board,
                                    const std::vector<CameraFrame>& frame,
                                    const PoseMeasurementOptions& options = {});

// Same, started from a given pose instead of IPPE (refines the nearest local minimum).
PoseMeasurement refine_target_pose(const std::vector<RigCamera>& rig, const BoardPoints& board,
                                   const std::vector<CameraFrame>& frame,
                                   const Eigen::Isometry3d& world_T_target_guess,
                                   const PoseMeasurementOptions& options = {});

// Settled-frame test between two measurements of the same robot pose: chi-square of the pose
// difference under the sum of both corner-noise covariances (6 dof).
struct MotionCheck {
  double chi2 = 0.0;
  double p_value = 1.0;  // probability of a chi2 at least this large for a still target
  bool moving = false;
  double translation_m = 0.0;
  double rotation_rad = 0.0;
};
MotionCheck check_target_still(const PoseMeasurement& a, const PoseMeasurement& b,
                               double false_alarm = 1e-4);

// Several frames per robot pose: frames[f][c]. Measures frame 0, refines every other frame from
// it, and tests each against frame 0. When all agree, the pose is re-estimated from all frames
// together (frames_used = number of frames); otherwise status kMoving with moving = true and the
// largest chi-square in the message.
PoseMeasurement measure_settled_pose(const std::vector<RigCamera>& rig, const BoardPoints& board,
                                     const std::vector<std::vector<CameraFrame>>& frames,
                                     const PoseMeasurementOptions& options = {});

// Upper-tail probability of the chi-square distribution with `dof` degrees of freedom, and the x
// with chi2_survival(x, dof) = p: core's chi-square functions (core/chi_square.hpp).
inline double chi2_survival(double x, int dof) {
  return core::chi_square_survival(x, dof);
}
inline double chi2_quantile_upper(double p, int dof) {
  return core::chi_square_quantile_upper(p, dof);
}

}  // namespace robocal::vision
