#include "stages/pixel_bridge.hpp"

#include <fmt/core.h>

#include <Eigen/Cholesky>

#include <algorithm>
#include <map>
#include <set>
#include <stdexcept>

namespace robocal::app {

namespace {

// One camera's corners as pixel observations, each tag's corners together with their joint
// covariance (the per-tag edge-fit covariance the pose route uses) as one calib::PixelGroup;
// corners in no usable group keep their own σ. Group `first` indices count from 0 (the caller
// offsets them). A corner in several groups joins the first.
struct CameraPixels {
  std::vector<calib::PixelObservation> observations;
  std::vector<calib::PixelGroup> groups;
  int unknown_corners = 0;
};

CameraPixels camera_pixels(int camera, const vision::CameraFrame& frame,
                           const vision::BoardPoints& target, double default_sigma_px) {
  CameraPixels out;
  std::map<int, const vision::CornerObservation*> by_id;
  for (const auto& corner : frame.corners) {
    if (target.count(corner.id) == 0) {
      ++out.unknown_corners;
      continue;
    }
    by_id.emplace(corner.id, &corner);
  }
  std::set<int> used;
  for (const auto& group : frame.corner_groups) {
    const auto n = static_cast<Eigen::Index>(group.corner_ids.size());
    if (group.covariance.rows() != 2 * n || group.covariance.cols() != 2 * n ||
        !group.covariance.allFinite())
      continue;
    std::vector<Eigen::Index> present;  // member positions within the group
    for (Eigen::Index k = 0; k < n; ++k) {
      const int id = group.corner_ids[static_cast<std::size_t>(k)];
      if (by_id.count(id) != 0 && used.count(id) == 0) present.push_back(k);
    }
    if (present.empty()) continue;
    Eigen::MatrixXd covariance(2 * present.size(), 2 * present.size());
    for (std::size_t i = 0; i < present.size(); ++i)
      for (std::size_t j = 0; j < present.size(); ++j)
        covariance.block<2, 2>(2 * static_cast<Eigen::Index>(i), 2 * static_cast<Eigen::Index>(j)) =
            group.covariance.block<2, 2>(2 * present[i], 2 * present[j]);
    if (covariance.llt().info() != Eigen::Success) continue;  // degenerate fit: own σ below
    std::vector<calib::PixelObservation> members;
    for (std::size_t i = 0; i < present.size(); ++i) {
      const int id = group.corner_ids[static_cast<std::size_t>(present[i])];
      const auto k = 2 * static_cast<Eigen::Index>(i);
      members.push_back(calib::PixelObservation::with_covariance(
          camera, id, target.at(id), by_id.at(id)->pixel, covariance.block<2, 2>(k, k)));
      used.insert(id);
    }
    if (members.size() > 1)
      out.groups.push_back(calib::PixelGroup::from_covariance(
          static_cast<int>(out.observations.size()), members, covariance));
    out.observations.insert(out.observations.end(), members.begin(), members.end());
  }
  for (const auto& [id, corner] : by_id) {
    if (used.count(id) != 0) continue;
    const double sigma = corner->sigma_px > 0.0 ? corner->sigma_px : default_sigma_px;
    out.observations.push_back(
        calib::PixelObservation::with_sigma(camera, id, target.at(id), corner->pixel, sigma));
  }
  return out;
}

}  // namespace

PixelMeasurements build_pixel_measurements(const std::vector<vision::RigCamera>& rig,
                                           const vision::BoardPoints& target,
                                           const std::vector<PixelPose>& poses,
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
                                              pose.pose, pose.cameras.size(), rig.size()));
    calib::PoseMeasurement m;
    m.id = pose.pose;
    m.actuators = pose.actuators;
    for (std::size_t c = 0; c < rig.size(); ++c) {
      CameraPixels seen =
          camera_pixels(static_cast<int>(c), pose.cameras[c], target, options.default_sigma_px);
      out.unknown_corners += seen.unknown_corners;
      if (static_cast<int>(seen.observations.size()) < options.min_corners_per_camera) continue;
      const auto offset = static_cast<int>(m.observations.size());
      for (auto& g : seen.groups) {
        g.first += offset;
        m.pixel_groups.push_back(std::move(g));
      }
      m.observations.insert(m.observations.end(), seen.observations.begin(),
                            seen.observations.end());
    }
    if (m.observations.empty()) {
      out.skipped.push_back(fmt::format("{}: no camera saw at least {} target corners", pose.pose,
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
                                      const std::vector<PixelPose>& poses,
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

double median_pixels_per_metre(const std::vector<vision::RigCamera>& rig,
                               const std::vector<PixelPose>& poses,
                               const std::map<std::string, Eigen::Isometry3d>& rig_T_target) {
  std::vector<double> scales;
  for (const PixelPose& pose : poses) {
    const auto target = rig_T_target.find(pose.pose);
    if (target == rig_T_target.end()) continue;
    for (std::size_t c = 0; c < pose.cameras.size() && c < rig.size(); ++c) {
      if (pose.cameras[c].corners.empty() || rig[c].model.params.size() < 2) continue;
      const double depth = (rig[c].camera_T_world * target->second).translation().z();
      if (!(depth > 0.0)) continue;
      const double focal = 0.5 * (rig[c].model.params[0] + rig[c].model.params[1]);
      scales.push_back(focal / depth);
    }
  }
  if (scales.empty()) return 0.0;
  const auto mid = scales.begin() + static_cast<std::ptrdiff_t>(scales.size() / 2);
  std::nth_element(scales.begin(), mid, scales.end());
  return *mid;
}

}  // namespace robocal::app
