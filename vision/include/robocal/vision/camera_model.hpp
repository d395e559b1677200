#pragma once
// Runtime camera model: which projection model, the image size and the parameter vector, with
// project/unproject dispatching to the templated models of camera_models.hpp.
// Pixel convention: OpenCV's, (0,0) = centre of the top-left pixel (see camera_models.hpp).
#include "robocal/vision/camera_models.hpp"

#include <Eigen/Core>

#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace robocal::vision {

enum class CameraKind { kPinholeRadtan, kPinholeRational, kFisheyeKB4 };

struct CameraModel {
  CameraKind kind = CameraKind::kPinholeRadtan;
  int width = 0;   // pixels
  int height = 0;  // pixels
  // Layout of camera_models.hpp for `kind`: fx fy cx cy, then the distortion coefficients.
  std::vector<double> params;
  bool operator==(const CameraModel&) const = default;
};

// Number of parameters of a kind (9, 12 or 8).
int num_params(CameraKind kind);
// File names of the kinds: "pinhole_radtan", "pinhole_rational", "fisheye_kb4".
std::string_view kind_name(CameraKind kind);
std::optional<CameraKind> kind_from_name(std::string_view name);

// Calls f(ModelStruct{}) for the model struct of `kind`, e.g. to instantiate a Ceres functor:
//   visit_camera_kind(cam.kind, [&](auto model) { using M = decltype(model); ... M::kNumParams });
template <class F>
decltype(auto) visit_camera_kind(CameraKind kind, F&& f) {
  switch (kind) {
    case CameraKind::kPinholeRational:
      return std::forward<F>(f)(PinholeRational{});
    case CameraKind::kFisheyeKB4:
      return std::forward<F>(f)(FisheyeKB4{});
    case CameraKind::kPinholeRadtan:
    default:
      return std::forward<F>(f)(PinholeRadtan{});
  }
}

// Builders with zero distortion unless given (missing trailing coefficients are zero).
CameraModel make_camera(CameraKind kind, int width, int height, double fx, double fy, double cx,
                        double cy, const std::vector<double>& distortion = {});

// Empty string when the model is usable, else what is wrong (parameter count, size, focal).
std::string validate_camera(const CameraModel& camera);

// Projects a point given in the camera frame (metres) to a pixel; nullopt if it cannot be
// projected (behind the camera, beyond the rational model's pole). Does NOT check the image
// bounds: see in_image().
std::optional<Eigen::Vector2d> project(const CameraModel& camera, const Eigen::Vector3d& p_cam);

// Unit bearing vector (camera frame) of a pixel, found by Newton iteration on the distortion
// (converges to ~1e-12 px re-projection). nullopt where the distortion cannot be inverted.
std::optional<Eigen::Vector3d> unproject(const CameraModel& camera, const Eigen::Vector2d& pixel);
// The same, starting from a nearby pixel's bearing (faster when sweeping a grid).
std::optional<Eigen::Vector3d> unproject(const CameraModel& camera, const Eigen::Vector2d& pixel,
                                         const Eigen::Vector3d& initial_bearing);

// How far apart two models of one camera put the same rays: RMS pixel distance over an 11 × 11
// grid of rays through `reference`'s image (each ray unprojected with `reference`, projected with
// `other`). Infinity when no ray can be compared. E.g. an estimated camera against the truth.
double projection_difference_px(const CameraModel& other, const CameraModel& reference);

// True when a pixel lies inside the image area shrunk by `margin` pixels on each side
// ([-0.5, width-0.5] x [-0.5, height-0.5] at margin 0).
bool in_image(const CameraModel& camera, const Eigen::Vector2d& pixel, double margin = 0.0);

// 2x(N) Jacobian of the projection w.r.t. the point (2x3) and the parameters (2xN), by
// automatic differentiation; false where project() fails.
bool project_jacobians(const CameraModel& camera, const Eigen::Vector3d& p_cam,
                       Eigen::Vector2d* pixel, Eigen::Matrix<double, 2, 3>* d_point,
                       Eigen::MatrixXd* d_params);

}  // namespace robocal::vision
