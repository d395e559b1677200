#pragma once
// Synthetic camera images of calibration targets with exact ground truth.
//
// Every output pixel is the exact box-filtered (area-averaged) image of the targets: the four
// corners of the pixel are mapped back through the full camera model (unprojection, precomputed
// once per camera in CameraRays) onto the target plane, and the black area of the pattern inside
// that footprint is computed analytically by clipping against the pattern's modules, each
// clipped piece weighted by the local pixel/board area ratio (perspective), so edges and corners
// sit where the model puts them to < 0.001 px (tests: Renderer.CornersLieWhere...). Pixels on
// a target's silhouette or seeing several targets are supersampled (8x8 interpolated rays); a
// target or target corner smaller than one pixel that falls between pixel corners is missed.
// Then, in this order:
// lighting gradient and vignetting (multiplicative), occluders, Gaussian defocus blur, shot +
// read noise (seeded), quantisation to 8 or 16 bit.
//
// Intensities are in DN of an 8-bit sensor (0..255); 16-bit output is DN * 257.
// Pixel convention: OpenCV ((0,0) = centre of the top-left pixel), as everywhere in robocal.
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/target.hpp"

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>

namespace robocal::vision {

// Unit bearing vectors of all pixel corners: corner (i, j) is pixel position (i - 0.5, j - 0.5),
// i in [0, width], j in [0, height]; row-major. NaN where the model cannot be inverted.
struct CameraRays {
  CameraModel camera;
  int cols = 0;  // width + 1
  int rows = 0;  // height + 1
  std::vector<Eigen::Vector3d> rays;
};
CameraRays precompute_rays(const CameraModel& camera);

struct RenderTarget {
  TargetBoard board;
  Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();  // see pose.hpp
};

// Something in front of the targets, in image coordinates: a disc (radius) or an axis-aligned
// rectangle (half_size), filled with `level` DN.
struct Occluder {
  enum class Shape { kDisc, kRectangle } shape = Shape::kDisc;
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  double radius = 0.0;
  Eigen::Vector2d half_size = Eigen::Vector2d::Zero();
  double level = 0.0;
  bool operator==(const Occluder&) const = default;
};

struct RenderOptions {
  double black_level = 20.0;       // DN of the printed black
  double white_level = 220.0;      // DN of the white paper
  double background_level = 60.0;  // DN where no target is seen
  // Relative brightness change across the image: factor 1 + gx (u/W - 1/2) + gy (v/H - 1/2).
  Eigen::Vector2d lighting_gradient = Eigen::Vector2d::Zero();
  // Relative brightness loss at the image corners: factor 1 - vignetting (r / r_corner)^2,
  // r measured from the image centre, r_corner = distance to the centre of a corner pixel.
  double vignetting = 0.0;
  std::vector<Occluder> occluders;
  double blur_sigma = 0.0;       // Gaussian defocus blur (lens PSF sigma), pixels (0 = none)
  int blur_subcells = 4;         // sub-cells per side of a pixel an edge crosses (1..8; 1: none)
  double read_noise = 0.0;       // Gaussian read noise sigma, DN
  double shot_noise_gain = 0.0;  // electrons per DN; shot-noise variance = signal / gain (0: off)
  int bit_depth = 8;             // 8 or 16
  std::uint64_t seed = 1;        // noise seed: same seed, same image
  // Workers for one image (bands of rows); the image is the same for any number. More than one
  // where a single camera's frame is awaited (a live camera), one where frames are rendered in
  // parallel already.
  int threads = 1;
  bool operator==(const RenderOptions&) const = default;
};

struct CornerTruth {
  int target = 0;                                   // index into the targets
  int id = 0;                                       // corner id on that target (target.hpp)
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();  // OpenCV convention; NaN if not projectable
  // Projects inside the image, the target faces the camera, and neither another target nor an
  // occluder (grown by 1.5 px + 3 blur sigma) covers it.
  bool visible = false;
  bool occluded = false;  // by another target or an occluder
};

struct RenderResult {
  cv::Mat image;  // CV_8U or CV_16U
  std::vector<CornerTruth> corners;
};

// The light reaching the sensor before the lens blur: each pixel's mean (exact area sampling,
// lighting, vignetting and occluders applied) and, for the pixels an edge crosses, the means of
// their sub-cells.
struct SceneIrradiance {
  cv::Mat pixels;                     // CV_32F, DN
  int subcells = 1;                   // sub-cells per pixel side
  std::vector<int> edge_pixels;       // v * width + u of the pixels with sub-cells
  std::vector<float> subcell_values;  // subcells^2 per edge pixel, row-major, DN
};
// With sub-cells when options.blur_sigma > 0 (without blur the pixel means are all it takes).
SceneIrradiance render_irradiance(const CameraRays& rays, const std::vector<RenderTarget>& targets,
                                  const RenderOptions& options);
// The ideal image: the pixel means alone; no blur, noise or quantisation.
cv::Mat render_ideal(const CameraRays& rays, const std::vector<RenderTarget>& targets,
                     const RenderOptions& options);
// Blur, noise and quantisation (deterministic for a given seed):
// sensor_readout(blurred_irradiance(scene, options), options).
cv::Mat apply_sensor(const SceneIrradiance& scene, const RenderOptions& options);
// The light on the pixels after the lens blur (CV_32F, DN); the scene's pixels without blur.
cv::Mat blurred_irradiance(const SceneIrradiance& scene, const RenderOptions& options);
// Noise and quantisation of the light on the pixels (deterministic for a given seed).
cv::Mat sensor_readout(const cv::Mat& irradiance, const RenderOptions& options);
// The same for an image of pixel means alone: every pixel taken as uniform.
cv::Mat apply_sensor(const cv::Mat& ideal, const RenderOptions& options);
// Ground-truth pixel positions and visibility of every corner of every target.
std::vector<CornerTruth> corner_truth(const CameraModel& camera,
                                      const std::vector<RenderTarget>& targets,
                                      const RenderOptions& options);
// All of the above.
RenderResult render(const CameraRays& rays, const std::vector<RenderTarget>& targets,
                    const RenderOptions& options);

// The frames of one simulated camera. A robot standing still is shot several times (the
// settled-frame test): a frame of the same scene as the last one (the same target poses, bit for
// bit, and the same options but for the noise seed and bit depth) keeps the last frame's blurred
// irradiance and draws only new sensor noise. A target no ray of the camera can meet (it faces
// away, or its paper lies outside the cone or the four side planes that hold every ray) is left
// out of the scene first,
// so every frame of a camera in an array that does not see the board is the same empty scene.
// Either way the image equals render()'s exactly, at the cost of the readout alone. Any other
// frame keeps the light where no target can be seen from the camera's last frame with the same
// background (level, lighting, vignetting, blur): only the pixels around the targets are rendered
// and blurred again, and the image is still render()'s to the bit. Thread-safe; one object per
// camera.
class StillSceneRenderer {
 public:
  explicit StillSceneRenderer(CameraRays rays);
  // Rays shared with other renderers of the same camera model (a 1600x1200 camera's take tens of
  // MB and a good part of a second to compute).
  explicit StillSceneRenderer(std::shared_ptr<const CameraRays> rays);
  [[nodiscard]] const CameraRays& rays() const { return *rays_; }
  // The image render(rays(), targets, options) gives.
  cv::Mat render(const std::vector<RenderTarget>& targets, const RenderOptions& options);
  // Frames that reused the last scene (tests, statistics).
  [[nodiscard]] long reused() const;

 private:
  [[nodiscard]] bool may_be_seen(const RenderTarget& target) const;
  // The blurred light of the scene (blurred_irradiance(render_irradiance(...))).
  cv::Mat light_of(const std::vector<RenderTarget>& targets, const RenderOptions& options);

  std::shared_ptr<const CameraRays> rays_;
  double widest_ray_ = 0.0;  // largest angle of a ray from the optical axis, rad
  // Outward normals of planes through the camera centre with every ray behind them (left, right,
  // top, bottom; none for a lens that sees behind itself).
  std::vector<Eigen::Vector3d> sides_;
  mutable std::mutex mutex_;
  std::vector<Eigen::Matrix4d> last_poses_;
  std::optional<RenderOptions> last_options_;
  cv::Mat last_irradiance_;
  long reused_ = 0;
  // The scene without targets: its light and that light blurred, for `options`.
  struct Background {
    RenderOptions options;
    cv::Mat light;
    cv::Mat blurred;
  };
  std::shared_ptr<const Background> background_;
};

}  // namespace robocal::vision
