// A renderer for many frames of one camera: the targets no ray can meet are left out, the
// light of a scene seen again is reused, and the background is traced once.
#include "robocal/vision/renderer.hpp"

#include "render/scene_light.hpp"
#include "render/scene_rays.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <mutex>
#include <numbers>
#include <stdexcept>

namespace robocal::vision {

namespace {

// Options that give the same blurred irradiance: equal but for the sensor's (noise, seed, bit
// depth), which the readout alone uses.
bool same_scene_options(const RenderOptions& a, RenderOptions b) {
  b.read_noise = a.read_noise;
  b.shot_noise_gain = a.shot_noise_gain;
  b.bit_depth = a.bit_depth;
  b.seed = a.seed;
  b.threads = a.threads;
  return a == b;
}

// Options that give the same light where no target is seen, blurred.
bool same_background(const RenderOptions& a, const RenderOptions& b) {
  return a.background_level == b.background_level && a.lighting_gradient == b.lighting_gradient &&
         a.vignetting == b.vignetting && a.blur_sigma == b.blur_sigma;
}

}  // namespace

StillSceneRenderer::StillSceneRenderer(CameraRays rays)
    : StillSceneRenderer(std::make_shared<const CameraRays>(std::move(rays))) {}

StillSceneRenderer::StillSceneRenderer(std::shared_ptr<const CameraRays> rays)
    : rays_(std::move(rays)) {
  if (!rays_) throw std::invalid_argument("StillSceneRenderer: no camera rays");
  double lowest_z = 1.0;
  for (const Eigen::Vector3d& ray : rays_->rays)
    if (ray.allFinite()) lowest_z = std::min(lowest_z, ray.z() / ray.norm());
  widest_ray_ = std::acos(std::clamp(lowest_z, -1.0, 1.0));
  if (!(lowest_z > 0.0)) return;
  // The rays' extreme angles left-right (atan2(x, z)) and up-down (atan2(y, z)): a ray at angle a
  // lies behind the plane with normal (cos b, 0, -sin b) for every b >= a.
  constexpr double kPi = std::numbers::pi;
  double x_lo = kPi, x_hi = -kPi, y_lo = kPi, y_hi = -kPi;
  for (const Eigen::Vector3d& ray : rays_->rays) {
    if (!ray.allFinite()) continue;
    const double ax = std::atan2(ray.x(), ray.z()), ay = std::atan2(ray.y(), ray.z());
    x_lo = std::min(x_lo, ax);
    x_hi = std::max(x_hi, ax);
    y_lo = std::min(y_lo, ay);
    y_hi = std::max(y_hi, ay);
  }
  sides_ = {{-std::cos(x_lo), 0.0, std::sin(x_lo)},
            {std::cos(x_hi), 0.0, -std::sin(x_hi)},
            {0.0, -std::cos(y_lo), std::sin(y_lo)},
            {0.0, std::cos(y_hi), -std::sin(y_hi)}};
}

// False only when no ray can meet the target's paper, as render_scene's intersect() decides: the
// camera sees its back (the same test, from the same numbers), or a sphere around the paper lies
// wholly outside the cone of the rays (with a margin far above rounding).
bool StillSceneRenderer::may_be_seen(const RenderTarget& target) const {
  if (!detail::geometry_of(target).faces_camera) return false;
  const Eigen::Vector2d lo = target.board.extent_min, hi = target.board.extent_max;
  const std::array<Eigen::Vector3d, 4> paper = {
      target.camera_T_board * Eigen::Vector3d(lo.x(), lo.y(), 0.0),
      target.camera_T_board * Eigen::Vector3d(hi.x(), lo.y(), 0.0),
      target.camera_T_board * Eigen::Vector3d(hi.x(), hi.y(), 0.0),
      target.camera_T_board * Eigen::Vector3d(lo.x(), hi.y(), 0.0)};
  const Eigen::Vector3d centre = 0.25 * (paper[0] + paper[1] + paper[2] + paper[3]);
  double radius = 0.0;
  for (const Eigen::Vector3d& p : paper) radius = std::max(radius, (p - centre).norm());
  const double distance = centre.norm();
  if (!(distance > radius)) return true;  // the camera is inside the sphere
  const double off_axis = std::atan2(centre.head<2>().norm(), centre.z());
  const double half_width = std::asin(radius / distance);
  if (off_axis - half_width > widest_ray_ + 1e-6) return false;
  // Wholly in front of a side plane: every ray is behind it.
  return std::none_of(sides_.begin(), sides_.end(), [&](const Eigen::Vector3d& n) {
    return n.dot(centre) > radius + 1e-6 * distance;
  });
}

cv::Mat StillSceneRenderer::render(const std::vector<RenderTarget>& all_targets,
                                   const RenderOptions& options) {
  std::vector<RenderTarget> targets;
  for (const RenderTarget& t : all_targets)
    if (may_be_seen(t)) targets.push_back(t);
  std::vector<Eigen::Matrix4d> poses;
  poses.reserve(targets.size());
  for (const RenderTarget& t : targets) poses.push_back(t.camera_T_board.matrix());
  cv::Mat irradiance;
  {
    const std::lock_guard lock(mutex_);
    if (last_options_ && same_scene_options(*last_options_, options) && poses == last_poses_) {
      irradiance = last_irradiance_;  // shared, never written: readout makes a new image
      ++reused_;
    }
  }
  if (irradiance.empty()) {
    irradiance = light_of(targets, options);
    const std::lock_guard lock(mutex_);
    last_poses_ = std::move(poses);
    last_options_ = options;
    last_irradiance_ = irradiance;
  }
  return sensor_readout(irradiance, options);
}

// Occluders are painted anywhere in the image: a scene with them is rendered whole.
cv::Mat StillSceneRenderer::light_of(const std::vector<RenderTarget>& targets,
                                     const RenderOptions& options) {
  if (!options.occluders.empty())
    return blurred_irradiance(render_irradiance(*rays_, targets, options), options);
  std::shared_ptr<const Background> background;
  {
    const std::lock_guard lock(mutex_);
    if (background_ && same_background(background_->options, options)) background = background_;
  }
  if (!background) {
    auto fresh = std::make_shared<Background>();
    fresh->options = options;
    fresh->light = detail::background_light(rays_->cols - 1, rays_->rows - 1, options);
    if (options.blur_sigma > 0.0) {
      SceneIrradiance empty;
      empty.pixels = fresh->light;
      fresh->blurred = detail::blur_before_sampling(empty, options.blur_sigma);
    }
    background = fresh;
    const std::lock_guard lock(mutex_);
    background_ = std::move(fresh);
  }
  cv::Rect changed;
  const SceneIrradiance scene = detail::render_scene(
      *rays_, targets, options, options.blur_sigma > 0.0, &background->light, &changed);
  if (!(options.blur_sigma > 0.0)) return scene.pixels;
  return detail::blur_before_sampling(scene, options.blur_sigma, &background->blurred, changed);
}

long StillSceneRenderer::reused() const {
  const std::lock_guard lock(mutex_);
  return reused_;
}

}  // namespace robocal::vision
