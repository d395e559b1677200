#pragma once
// Camera-in-the-loop identification: the robot model plus the cameras that watch its target, as
// one FramePredictor whose parameter vector is the robot's followed by named camera parameters.
// Pixel observations (observations.hpp) are then ordinary residual blocks of identify(), and
// identifiability, priors, covariance and reporting cover the cameras unchanged.
//
// Parameter layout (after the robot's P parameters), per camera c named N:
//   N.x N.y N.z       camera centre in the world (m)
//   N.rx N.ry N.rz    world-frame rotation vector from the camera's start orientation (rad):
//                     world_R_camera = exp([r]×) · world_R_camera_start (0 at the start)
//   N.fx N.fy N.cx N.cy N.k1 ...   the camera model's parameters (vision/camera_models.hpp
//                     layout), present only when CameraRigOptions::estimate_intrinsics
//
// GAUGE: the world is the gauge camera's frame (camera 0 by default): its pose parameters are
// never candidates (solve_options() leaves them out), so the robot's base frame is estimated in
// that camera's frame. With the usual start world_T_camera0 = identity, the world IS camera 0's
// frame. (With intrinsics estimated, every camera's intrinsics are candidates, the gauge
// camera's too.)
//
// The calib library uses vision's camera models and nothing else of vision (CMake target
// robocal_vision_camera: Eigen only, no OpenCV).
#include "robocal/calib/identification.hpp"
#include "robocal/vision/camera_model.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <random>
#include <string>
#include <vector>

namespace robocal::calib {

// A camera that observes the measured frame's target.
struct ObservingCamera {
  std::string name;           // parameter-name prefix, e.g. "camera0"; unique
  vision::CameraModel model;  // intrinsics (start values when estimated)
  Eigen::Isometry3d world_T_camera = Eigen::Isometry3d::Identity();  // start pose in the world
};

struct CameraRigOptions {
  bool estimate_intrinsics = false;  // every camera's model parameters become unknowns
  int gauge_camera = 0;  // this camera's pose is held: it defines the world (-1: none held)
};

class CameraRigPredictor final : public FramePredictor {
 public:
  // `robot` must outlive this. Throws std::invalid_argument on an unusable camera (its model
  // fails vision::validate_camera, duplicate or empty name) or a gauge index out of range.
  CameraRigPredictor(const FramePredictor& robot, std::vector<ObservingCamera> cameras,
                     CameraRigOptions options = {});

  std::size_t parameter_count() const override;
  std::vector<std::string> parameter_names() const override;
  // The robot's labels, then the cameras' names ("camera1.x": a camera's pose, not the robot).
  std::vector<std::string> parameter_labels() const override;
  // The robot's prediction; the jacobian has zero columns for the camera parameters.
  bool predict(const Eigen::VectorXd& params, const Eigen::VectorXd& actuators, int slot,
               bool with_jacobian, FramePrediction& out, std::string& why) const override;
  // Exact: the projection is differentiated with Jets with respect to the corner's world position,
  // the camera pose and intrinsics; the frame part is chained through frame.jacobian with the
  // twist convention of observations.hpp (δx_w = δp − [R X]× δφ).
  bool pixel_residual(const PixelObservation& obs, const Eigen::VectorXd& params,
                      const FramePrediction& frame, Eigen::Vector2d& residual,
                      Eigen::Matrix<double, 2, Eigen::Dynamic>* jacobian,
                      std::string& why) const override;

  // ---- layout ----
  int camera_count() const { return static_cast<int>(cameras_.size()); }
  const std::vector<ObservingCamera>& cameras() const { return cameras_; }
  const CameraRigOptions& options() const { return options_; }
  std::size_t pose_offset(int camera) const;        // index of N.x
  std::size_t intrinsics_offset(int camera) const;  // index of N.fx; only with estimate_intrinsics

  // robot parameters followed by every camera's start values.
  Eigen::VectorXd initial_parameters(const Eigen::VectorXd& robot_params) const;
  Eigen::VectorXd robot_parameters(const Eigen::VectorXd& params) const;
  Eigen::Isometry3d world_T_camera(const Eigen::VectorXd& params, int camera) const;
  vision::CameraModel camera_model(const Eigen::VectorXd& params, int camera) const;
  // Parameters that set a camera to `world_T_camera` (and `model` when intrinsics are estimated).
  void set_camera(Eigen::VectorXd& params, int camera, const Eigen::Isometry3d& world_T_camera,
                  const vision::CameraModel* model = nullptr) const;

  // The robot's solve options extended to the full vector: candidates = the robot's candidates
  // (all robot parameters when empty) + every camera pose except the gauge camera's (+ all
  // intrinsics when estimated). Camera parameters come first in confounded groups (preference
  // below the robot's), have no prior, no bounds and no multi-start spread unless
  // `camera_start_sigma` > 0 (m and rad, for the pose parameters).
  SolveOptions solve_options(const SolveOptions& robot, double camera_start_sigma = 0.0) const;

  // Its own parts are pure; the robot's predictor decides.
  bool thread_safe() const override { return robot_.thread_safe(); }

 private:
  const FramePredictor& robot_;
  std::vector<ObservingCamera> cameras_;
  CameraRigOptions options_;
  std::size_t robot_count_ = 0;
  std::vector<std::size_t> offsets_;  // pose offset per camera
};

// world_T_camera of a camera at `eye` looking at `target` (OpenCV axes: z forward, x right,
// y down; `up` = the world direction that appears up in the image).
Eigen::Isometry3d camera_looking_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                                    const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

// Simulation rig: `count` pinhole cameras (width × height, mild barrel distortion) below the
// points (world −z side) at 2.5 times their spread, 0.4 spreads apart along x, looking at their
// centre with a focal length that frames them. Named camera0, camera1, ...
std::vector<ObservingCamera> cameras_below(const std::vector<Eigen::Vector3d>& points,
                                           int count = 2, int width = 1280, int height = 960);

struct PixelSimulationOptions {
  double pixel_sigma = 0.1;  // px, per axis
  bool add_noise = true;
  Eigen::VectorXd actuator_sigma;  // per actuator reading noise (empty = none)
  double image_margin = 2.0;       // px: corners closer to the border are not seen
  int min_corners = 4;             // a camera seeing fewer corners of a pose reports none
  // When nonzero: the target's outward normal in the measured frame; a corner is seen only by
  // cameras on that side of the target (a board is not seen from behind).
  Eigen::Vector3d target_normal = Eigen::Vector3d::Zero();
};

// Pixel observations of `target_points` (in the measured frame) at every actuator vector, for
// the TRUE parameters `truth` (robot and cameras, full vector of `rig`). Readings optionally
// noisy; poses the true model cannot solve or no camera sees are skipped. Ids "p0000"...
Measurements simulate_pixel_measurements(const CameraRigPredictor& rig,
                                         const Eigen::VectorXd& truth,
                                         const std::vector<Eigen::VectorXd>& actuators,
                                         const std::vector<Eigen::Vector3d>& target_points,
                                         const PixelSimulationOptions& options, std::mt19937& rng);

// Reprojection error (pixels, unwhitened) of every pixel observation at `params`.
struct PixelErrorStatistics {
  std::size_t observations = 0;
  double rms_px = 0.0;  // sqrt(mean of squared 2-D distances)
  double max_px = 0.0;
};
PixelErrorStatistics pixel_errors(const CameraRigPredictor& rig, const Eigen::VectorXd& params,
                                  const std::vector<PoseMeasurement>& poses);

}  // namespace robocal::calib
