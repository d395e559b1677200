#include "stages/pixel_bridge.hpp"

#include <fmt/core.h>

#include <map>
#include <stdexcept>

namespace robocal::app {

namespace {

// Each grouped corner's own 2x2 block of its tag's joint covariance (the per-tag edge-fit
// covariance the pose route uses). A pixel observation carries one corner, so the correlation
// between corners of one tag is not carried; a corner in several groups keeps the first.
std::map<int, Eigen::Matrix2d> corner_covariances(const vision::CameraFrame& frame) {
  std::map<int, Eigen::Matrix2d> out;
  for (const auto& group : frame.corner_groups) {
    if (group.covariance.rows() != 2 * static_cast<Eigen::Index>(group.corner_ids.size()) ||
        group.covariance.cols() != group.covariance.rows())
      continue;
    for (std::size_t k = 0; k < group.corner_ids.size(); ++k) {
      const auto i = 2 * static_cast<Eigen::Index>(k);
      const Eigen::Matrix2d block = group.covariance.block<2, 2>(i, i);
      if (block.allFinite() && block.determinant() > 0.0 && block(0, 0) > 0.0)
        out.emplace(group.corner_ids[k], block);
    }
  }
  return out;
}

}  // namespace

PixelMeasurements build_pixel_measurements(const std::vector<vision::RigCamera>& rig,
                                           const vision::BoardPoints& target,
                                           const std::vector<PosePixels>& poses,
                                           const PixelBridgeOptions& options) {
  if (rig.empty()) throw std::invalid_argument("pixel measurements need at least one camera");
  if (!(options.default_sigma_px > 0.0))
    throw std::invalid_argument("the default corner sigma must be positive");
  PixelMeasurements out;
  for (std::size_t c = 0; c < rig.size(); ++c) {
    const std::string problem = vision::validate_camera(rig[c].model);
    if (!problem.empty()) throw std::invalid_argument(fmt::format("rig camera {}: {}", c, problem));
    calib::ObservingCamera cam;
    cam.name = rig[c].name.empty() ? fmt::format("camera{}", c) : rig[c].name;
    cam.model = rig[c].model;
    cam.world_T_camera = rig[c].camera_T_world.inverse();
    out.cameras.push_back(std::move(cam));
  }
  for (const auto& pose : poses) {
    if (pose.cameras.size() != rig.size())
      throw std::invalid_argument(fmt::format("pose {}: {} camera frames for a rig of {} cameras",
                                              pose.id, pose.cameras.size(), rig.size()));
    calib::PoseMeasurement m;
    m.id = pose.id;
    m.actuators = pose.actuators;
    for (std::size_t c = 0; c < rig.size(); ++c) {
      const auto group_covariance = corner_covariances(pose.cameras[c]);
      std::vector<calib::PixelObservation> seen;
      for (const auto& corner : pose.cameras[c].corners) {
        const auto it = target.find(corner.id);
        if (it == target.end()) {
          ++out.unknown_corners;
          continue;
        }
        const auto in_group = group_covariance.find(corner.id);
        if (in_group != group_covariance.end()) {
          seen.push_back(calib::PixelObservation::with_covariance(
              static_cast<int>(c), corner.id, it->second, corner.pixel, in_group->second));
          continue;
        }
        const double sigma = corner.sigma_px > 0.0 ? corner.sigma_px : options.default_sigma_px;
        seen.push_back(calib::PixelObservation::with_sigma(static_cast<int>(c), corner.id,
                                                           it->second, corner.pixel, sigma));
      }
      if (static_cast<int>(seen.size()) >= options.min_corners_per_camera)
        m.observations.insert(m.observations.end(), seen.begin(), seen.end());
    }
    if (m.observations.empty()) {
      out.skipped.push_back(fmt::format("{}: no camera saw at least {} target corners", pose.id,
                                        options.min_corners_per_camera));
      continue;
    }
    out.measurements.poses.push_back(std::move(m));
  }
  return out;
}

PixelRouteResult identify_from_pixels(const calib::FramePredictor& robot,
                                      const Eigen::VectorXd& robot_start,
                                      const calib::SolveOptions& robot_options,
                                      const std::vector<vision::RigCamera>& rig,
                                      const vision::BoardPoints& target,
                                      const std::vector<PosePixels>& poses,
                                      const PixelBridgeOptions& options) {
  PixelRouteResult out;
  out.input = build_pixel_measurements(rig, target, poses, options);
  const calib::CameraRigPredictor model(robot, out.input.cameras);
  const Eigen::VectorXd start = model.initial_parameters(robot_start);
  out.result =
      calib::identify(model, start, out.input.measurements, model.solve_options(robot_options));
  out.robot_estimate = model.robot_parameters(out.result.estimate);
  for (int c = 0; c < model.camera_count(); ++c)
    out.world_T_camera.push_back(model.world_T_camera(out.result.estimate, c));
  out.fit_pixels = calib::pixel_errors(model, out.result.estimate, out.input.measurements.poses);
  return out;
}

}  // namespace robocal::app
