#pragma once
// From what the camera pipeline saw to the camera-in-the-loop identification's input: per robot
// pose, the corners each calibrated camera detected become calib pixel observations of the target
// corners (given in the measured/tool frame), and the calibrated rig becomes the identification's
// cameras (start poses; camera 0 = the gauge, so the world is the rig's frame).
#include "session/results_files.hpp"

#include "robocal/calib/identification.hpp"
#include "robocal/calib/pixel_observations.hpp"
#include "robocal/vision/observations.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <map>
#include <string>
#include <vector>

namespace robocal::app {

// One robot pose is a PixelPose (session/results_files.hpp): its actuator readings and, per rig
// camera, the corners detected in its image (cameras[c] empty: camera c saw none).

struct PixelBridgeOptions {
  double default_sigma_px = 0.1;   // corners whose detection carries no sigma
  int min_corners_per_camera = 4;  // a camera seeing fewer corners of a pose contributes none
};

struct PixelMeasurements {
  std::vector<calib::ObservingCamera> cameras;  // rig cameras: model, world_T_camera
  calib::Measurements measurements;             // poses with at least one camera's corners
  std::vector<std::string> skipped;             // "id: reason" for poses left out
  std::size_t unknown_corners = 0;              // detected ids that are not target corners
};

// `rig` = the calibrated cameras (vision convention: camera_T_world, world = rig frame);
// `target` = corner id -> point in the measured frame (metres). Throws std::invalid_argument when
// a pose does not have one frame per rig camera or the rig is empty/invalid.
PixelMeasurements build_pixel_measurements(const std::vector<vision::RigCamera>& rig,
                                           const vision::BoardPoints& target,
                                           const std::vector<PixelPose>& poses,
                                           const PixelBridgeOptions& options = {});

// How many pixels a metre at the board spans, as the cameras saw it: the median, over the poses
// and the cameras with corners of them, of the mean focal length over the board's depth
// (`rig_T_target` per pose id; poses without one are skipped). 0 when there is none. It turns
// the robot's unmodelled error into pixels for the fit gate.
double median_pixels_per_metre(const std::vector<vision::RigCamera>& rig,
                               const std::vector<PixelPose>& poses,
                               const std::map<std::string, Eigen::Isometry3d>& rig_T_target);

// The camera-in-the-loop route end to end: builds the pixel measurements, adds the rig's cameras
// to `robot` (camera 0 = gauge; the other cameras' poses estimated, intrinsics held) and
// identifies from `robot_start` (the robot's base frame must already be roughly placed in the
// rig's world, e.g. by aligning the nominal model with per-pose PnP measurements).
struct PixelRouteResult {
  PixelMeasurements input;
  calib::IdentificationResult result;             // over robot + camera parameters
  Eigen::VectorXd robot_estimate;                 // the robot's part of result.estimate
  std::vector<Eigen::Isometry3d> world_T_camera;  // estimated camera poses
  calib::PixelErrorStatistics fit_pixels;         // reprojection at the estimate
};
PixelRouteResult identify_from_pixels(const calib::FramePredictor& robot,
                                      const Eigen::VectorXd& robot_start,
                                      const calib::SolveOptions& robot_options,
                                      const std::vector<vision::RigCamera>& rig,
                                      const vision::BoardPoints& target,
                                      const std::vector<PixelPose>& poses,
                                      const PixelBridgeOptions& options = {});

}  // namespace robocal::app
