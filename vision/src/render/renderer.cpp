#include "robocal/vision/renderer.hpp"

#include "render/pattern_index.hpp"
#include "render/scene_light.hpp"
#include "render/scene_rays.hpp"

#include "robocal/core/parallel.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <stdexcept>

namespace robocal::vision {

namespace {

using detail::CornerHit;
using detail::PatternIndex;
using detail::TargetGeometry;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

}  // namespace

CameraRays precompute_rays(const CameraModel& camera) {
  const std::string problem = validate_camera(camera);
  if (!problem.empty()) throw std::invalid_argument("camera: " + problem);
  CameraRays r;
  r.camera = camera;
  r.cols = camera.width + 1;
  r.rows = camera.height + 1;
  r.rays.resize(static_cast<size_t>(r.cols) * static_cast<size_t>(r.rows));
  for (int j = 0; j < r.rows; ++j) {
    // Warm start from the left neighbour (or the pixel above at the row start).
    std::optional<Eigen::Vector3d> prev;
    if (j > 0) {
      const Eigen::Vector3d& above =
          r.rays[static_cast<size_t>(j - 1) * static_cast<size_t>(r.cols)];
      if (above.allFinite()) prev = above;
    }
    for (int i = 0; i < r.cols; ++i) {
      const Eigen::Vector2d px(i - 0.5, j - 0.5);
      std::optional<Eigen::Vector3d> ray =
          prev ? unproject(camera, px, *prev) : unproject(camera, px);
      if (!ray && prev) ray = unproject(camera, px);
      r.rays[static_cast<size_t>(j) * static_cast<size_t>(r.cols) + static_cast<size_t>(i)] =
          ray ? *ray : Eigen::Vector3d(kNaN, kNaN, kNaN);
      prev = ray;
    }
  }
  return r;
}

namespace {

struct CornerWindow {
  int i0 = 0, i1 = -1, j0 = 0, j1 = -1;
  [[nodiscard]] bool contains(int i, int j) const {
    return i >= i0 && i <= i1 && j >= j0 && j <= j1;
  }
};

// The window from the papers' outlines projected by the camera model (32 points a side, grown by
// two pixels), then checked: no ray on the ring of corners just outside it meets a target. The
// corners a target's rays meet form one connected region (the camera model maps the paper's
// visible part continuously), so a region that left the window would cross that ring. Anything
// doubtful (a paper point behind the camera or off the model, a ray on the ring that meets a
// target) gives the whole grid: the window only ever saves work.
CornerWindow corner_window(const CameraRays& rays, const std::vector<TargetGeometry>& geo,
                           const std::vector<RenderTarget>& targets) {
  const CornerWindow whole{0, rays.cols - 1, 0, rays.rows - 1};
  constexpr int kPerSide = 32;
  double u0 = std::numeric_limits<double>::infinity(), v0 = u0, u1 = -u0, v1 = -u0;
  for (std::size_t k = 0; k < targets.size(); ++k) {
    if (!geo[k].faces_camera) continue;  // intersect() never meets it
    const TargetBoard& b = targets[k].board;
    const std::array<Eigen::Vector2d, 4> paper = {
        b.extent_min, Eigen::Vector2d(b.extent_max.x(), b.extent_min.y()), b.extent_max,
        Eigen::Vector2d(b.extent_min.x(), b.extent_max.y())};
    for (std::size_t side = 0; side < 4; ++side)
      for (int n = 0; n < kPerSide; ++n) {
        const Eigen::Vector2d xy =
            paper[side] + (paper[(side + 1) % 4] - paper[side]) * (double(n) / kPerSide);
        const Eigen::Vector3d p = targets[k].camera_T_board * Eigen::Vector3d(xy.x(), xy.y(), 0.0);
        if (!(p.z() > 0.0)) return whole;
        const std::optional<Eigen::Vector2d> px = project(rays.camera, p);
        if (!px || !px->allFinite()) return whole;
        u0 = std::min(u0, px->x());
        u1 = std::max(u1, px->x());
        v0 = std::min(v0, px->y());
        v1 = std::max(v1, px->y());
      }
  }
  if (!(u0 <= u1)) return {};  // no target faces the camera
  // Corner (i, j) lies at pixel coordinates (i - 1/2, j - 1/2).
  const auto index = [](double x, double lo, double hi) {
    return static_cast<int>(std::clamp(x + 0.5, lo, hi));
  };
  CornerWindow w;
  w.i0 = index(std::floor(u0) - 2.0, -1.0, rays.cols);
  w.i1 = index(std::ceil(u1) + 2.0, -1.0, rays.cols);
  w.j0 = index(std::floor(v0) - 2.0, -1.0, rays.rows);
  w.j1 = index(std::ceil(v1) + 2.0, -1.0, rays.rows);
  const auto meets = [&](int i, int j) {
    if (i < 0 || j < 0 || i >= rays.cols || j >= rays.rows) return false;
    const Eigen::Vector3d& ray =
        rays.rays[static_cast<size_t>(j) * static_cast<size_t>(rays.cols) + static_cast<size_t>(i)];
    return detail::nearest_hit(geo, targets, ray).target >= 0;
  };
  // The ring: rows j0 - 1 and j1 + 1, columns i0 - 1 and i1 + 1 (outside the grid: nothing).
  for (int i = w.i0 - 1; i <= w.i1 + 1; ++i)
    if (meets(i, w.j0 - 1) || meets(i, w.j1 + 1)) return whole;
  for (int j = w.j0; j <= w.j1; ++j)
    if (meets(w.i0 - 1, j) || meets(w.i1 + 1, j)) return whole;
  w.i0 = std::max(w.i0, 0);
  w.j0 = std::max(w.j0, 0);
  w.i1 = std::min(w.i1, rays.cols - 1);
  w.j1 = std::min(w.j1, rays.rows - 1);
  return w;
}

// The square of r_corner, from the image centre to the centre of a corner pixel (vignetting's
// The square of r_corner, from the image centre to the centre of a corner pixel (vignetting's
// unit radius).
double pixel_gain_scale(int W, int H) {
  return std::max(0.25 * (double(W - 1) * (W - 1) + double(H - 1) * (H - 1)), 1e-9);
}
// The lighting and vignetting factor of pixel (i, j) of a W x H image; half_diag2 is
// pixel_gain_scale(W, H). render_scene and background_light share it, so the background they
// give is the same to the bit.
double pixel_gain(int i, int j, int W, int H, double half_diag2, const RenderOptions& o) {
  double gain = 1.0 + o.lighting_gradient.x() * ((i + 0.5) / W - 0.5) +
                o.lighting_gradient.y() * ((j + 0.5) / H - 0.5);
  if (o.vignetting != 0.0) {
    const double du = i - 0.5 * (W - 1), dv = j - 0.5 * (H - 1);
    gain *= 1.0 - o.vignetting * (du * du + dv * dv) / half_diag2;
  }
  return gain;
}

// A band of rows' pixels with sub-cells (edge pixels) and their sub-cell values, in row order.
struct Band {
  std::vector<int> edge_pixels;
  std::vector<float> subcell_values;
};

// What tracing one pixel needs beside the scene: its sub-cells' corners, modules and values.
struct PixelScratch {
  std::vector<Eigen::Vector2d> subcorner;
  std::vector<std::int64_t> submodule;
  std::vector<float> subcell;

  explicit PixelScratch(int s)
      : subcorner(static_cast<size_t>((s + 1) * (s + 1))),
        submodule(static_cast<size_t>((s + 1) * (s + 1))),
        subcell(static_cast<size_t>(s * s)) {}
};

// One scene's tracing: the targets' geometry and patterns, the window of pixel corners that may
// meet them, and the light of each pixel (its mean and, for an edge pixel, its sub-cells').
class SceneTracer {
 public:
  SceneTracer(const CameraRays& rays, const std::vector<RenderTarget>& targets,
              const RenderOptions& o, int subcells, bool with_subcells)
      : rays_(rays),
        targets_(targets),
        o_(o),
        W_(rays.cols - 1),
        H_(rays.rows - 1),
        s_(subcells),
        with_subcells_(with_subcells),
        contrast_(o.white_level - o.black_level),
        half_diag2_(pixel_gain_scale(W_, H_)) {
    geo_.reserve(targets.size());
    index_.reserve(targets.size());
    for (const RenderTarget& t : targets) {
      geo_.push_back(detail::geometry_of(t));
      index_.emplace_back(t.board);
    }
    window_ = corner_window(rays, geo_, targets);
  }

  [[nodiscard]] const CornerWindow& window() const { return window_; }

  // Rows j0 .. j1 - 1, pixel columns i0 .. i1, into img, with their own edge pixels: bands of
  // rows are independent (a band traces its first row of corners again), and joined in order
  // they are the whole image's.
  void render_band(int j0, int j1, int i0, int i1, cv::Mat& img, Band& band) const;

 private:
  [[nodiscard]] const Eigen::Vector3d& ray_at(int i, int j) const {
    return rays_
        .rays[static_cast<size_t>(j) * static_cast<size_t>(rays_.cols) + static_cast<size_t>(i)];
  }
  // A pixel corner's hit and the module it lies in (shared by the four pixels around it).
  // Outside the window no ray meets a target: only whether the ray is valid is left to tell.
  [[nodiscard]] CornerHit corner_hit(int i, int j) const {
    if (!window_.contains(i, j)) {
      CornerHit miss;
      if (!ray_at(i, j).allFinite()) miss.target = -2;
      return miss;
    }
    CornerHit h = detail::nearest_hit(geo_, targets_, ray_at(i, j));
    if (h.target >= 0)
      h.module = index_[static_cast<size_t>(h.target)].module_at(h.xy.x(), h.xy.y());
    return h;
  }
  // black_fraction, or its answer without the search where the four corners share a module.
  static double black_of(const PatternIndex& pattern, const std::array<Eigen::Vector2d, 4>& q,
                         std::int64_t m0, std::int64_t m1, std::int64_t m2, std::int64_t m3) {
    if (m0 >= 0 && m0 == m1 && m0 == m2 && m0 == m3)
      if (const std::optional<double> uniform = pattern.inside_module(q, m0)) return *uniform;
    return pattern.black_fraction(q);
  }
  double pixel_light(int i, int j, const CornerHit* const c[4], PixelScratch& scratch,
                     bool& edge) const;
  double target_pixel(int i, int j, const CornerHit* const c[4], PixelScratch& scratch,
                      bool& edge) const;
  void edge_subcells(int i, int j, int target, PixelScratch& scratch) const;
  double silhouette_pixel(int i, int j, PixelScratch& scratch, bool& edge) const;

  const CameraRays& rays_;
  const std::vector<RenderTarget>& targets_;
  const RenderOptions& o_;
  int W_, H_, s_;
  bool with_subcells_;
  double contrast_;
  double half_diag2_;
  std::vector<TargetGeometry> geo_;
  std::vector<PatternIndex> index_;
  CornerWindow window_;
};

double SceneTracer::target_pixel(int i, int j, const CornerHit* const c[4], PixelScratch& scratch,
                                 bool& edge) const {
  const int t0 = c[0]->target;
  const PatternIndex& pattern = index_[static_cast<size_t>(t0)];
  const std::array<Eigen::Vector2d, 4> q = {c[0]->xy, c[1]->xy, c[2]->xy, c[3]->xy};
  const double black = black_of(pattern, q, c[0]->module, c[1]->module, c[2]->module, c[3]->module);
  const double value = o_.white_level - contrast_ * black;
  if (with_subcells_ && black > 0.0 && black < 1.0) {
    edge_subcells(i, j, t0, scratch);
    edge = true;
  }
  return value;
}

// An edge crosses the pixel: the black fraction of each sub-cell, whose corners are the board
// points of bilinearly interpolated corner rays (their footprints tile the pixel's exactly: a
// plane cuts the span of two rays in a straight line).
void SceneTracer::edge_subcells(int i, int j, int target, PixelScratch& scratch) const {
  const int s = s_;
  const PatternIndex& pattern = index_[static_cast<size_t>(target)];
  const TargetGeometry& g = geo_[static_cast<size_t>(target)];
  for (int b = 0; b <= s; ++b)
    for (int a = 0; a <= s; ++a) {
      const double fx = double(a) / s, fy = double(b) / s;
      const Eigen::Vector2d& xy = scratch.subcorner[static_cast<size_t>(b * (s + 1) + a)] =
          detail::plane_point(g,
                              (1 - fy) * ((1 - fx) * ray_at(i, j) + fx * ray_at(i + 1, j)) +
                                  fy * ((1 - fx) * ray_at(i, j + 1) + fx * ray_at(i + 1, j + 1)));
      scratch.submodule[static_cast<size_t>(b * (s + 1) + a)] = pattern.module_at(xy.x(), xy.y());
    }
  for (int b = 0; b < s; ++b)
    for (int a = 0; a < s; ++a) {
      const auto corner = [&](int da, int db) {
        return scratch.subcorner[static_cast<size_t>((b + db) * (s + 1) + a + da)];
      };
      const auto module = [&](int da, int db) {
        return scratch.submodule[static_cast<size_t>((b + db) * (s + 1) + a + da)];
      };
      const std::array<Eigen::Vector2d, 4> qs = {corner(0, 0), corner(1, 0), corner(1, 1),
                                                 corner(0, 1)};
      scratch.subcell[static_cast<size_t>(b * s + a)] = static_cast<float>(
          o_.white_level - contrast_ * black_of(pattern, qs, module(0, 0), module(1, 0),
                                                module(1, 1), module(0, 1)));
    }
}

// Silhouette of a target or several targets: supersampled interpolated rays.
double SceneTracer::silhouette_pixel(int i, int j, PixelScratch& scratch, bool& edge) const {
  constexpr int kSuper = 8;
  const int s = s_;
  std::vector<float>& subcell = scratch.subcell;
  const Eigen::Vector3d& r00 = ray_at(i, j);
  const Eigen::Vector3d& r10 = ray_at(i + 1, j);
  const Eigen::Vector3d& r01 = ray_at(i, j + 1);
  const Eigen::Vector3d& r11 = ray_at(i + 1, j + 1);
  double sum = 0;
  std::fill(subcell.begin(), subcell.end(), 0.0f);
  for (int sy = 0; sy < kSuper; ++sy) {
    const double fy = (sy + 0.5) / kSuper;
    for (int sx = 0; sx < kSuper; ++sx) {
      const double fx = (sx + 0.5) / kSuper;
      const Eigen::Vector3d ray =
          ((1 - fy) * ((1 - fx) * r00 + fx * r10) + fy * ((1 - fx) * r01 + fx * r11)).normalized();
      const CornerHit h = detail::nearest_hit(geo_, targets_, ray);
      double sample = o_.background_level;
      if (h.target >= 0)
        sample = index_[static_cast<size_t>(h.target)].black_at(h.xy.x(), h.xy.y())
                     ? o_.black_level
                     : o_.white_level;
      sum += sample;
      // Sample (sx, sy) falls in sub-cell (sx s / kSuper, sy s / kSuper); with s <= kSuper
      // every sub-cell gets (kSuper / s)^2 samples or, for s not dividing kSuper, 1-4.
      subcell[static_cast<size_t>((sy * s / kSuper) * s + sx * s / kSuper)] +=
          static_cast<float>(sample);
    }
  }
  const double value = sum / (kSuper * kSuper);
  if (with_subcells_) {
    for (int b = 0; b < s; ++b)
      for (int a = 0; a < s; ++a) {
        const int na = (a + 1) * kSuper / s - a * kSuper / s;  // samples per column
        const int nb = (b + 1) * kSuper / s - b * kSuper / s;
        subcell[static_cast<size_t>(b * s + a)] /= static_cast<float>(na * nb);
      }
    edge = true;
  }
  return value;
}

// The light of pixel (i, j) from its four corners' hits (before lighting and vignetting); edge:
// the scratch's sub-cells hold its sub-cell means.
double SceneTracer::pixel_light(int i, int j, const CornerHit* const c[4], PixelScratch& scratch,
                                bool& edge) const {
  const int t0 = c[0]->target;
  if (t0 == c[1]->target && t0 == c[2]->target && t0 == c[3]->target)
    return t0 >= 0 ? target_pixel(i, j, c, scratch, edge) : o_.background_level;
  if (t0 == -2 || c[1]->target == -2 || c[2]->target == -2 || c[3]->target == -2)
    return o_.background_level;  // outside the model's invertible field
  return silhouette_pixel(i, j, scratch, edge);
}

void SceneTracer::render_band(int j0, int j1, int i0, int i1, cv::Mat& img, Band& band) const {
  PixelScratch scratch(s_);
  std::vector<CornerHit> upper(static_cast<size_t>(W_ + 1)), lower(static_cast<size_t>(W_ + 1));
  for (int i = i0; i <= i1 + 1; ++i) upper[static_cast<size_t>(i)] = corner_hit(i, j0);
  for (int j = j0; j < j1; ++j) {
    for (int i = i0; i <= i1 + 1; ++i) lower[static_cast<size_t>(i)] = corner_hit(i, j + 1);
    float* row = img.ptr<float>(j);
    for (int i = i0; i <= i1; ++i) {
      const CornerHit* const c[4] = {
          &upper[static_cast<size_t>(i)], &upper[static_cast<size_t>(i + 1)],
          &lower[static_cast<size_t>(i + 1)], &lower[static_cast<size_t>(i)]};
      bool edge = false;
      const double value = pixel_light(i, j, c, scratch, edge);
      const double gain = pixel_gain(i, j, W_, H_, half_diag2_, o_);
      row[i] = static_cast<float>(value * gain);
      if (edge) {
        band.edge_pixels.push_back(j * W_ + i);
        for (const float v : scratch.subcell)
          band.subcell_values.push_back(static_cast<float>(v * gain));
      }
    }
    std::swap(upper, lower);
  }
}

// Occluders: 4x4 supersampled coverage of the shape, painted over the scene (and over the
// sub-cells of edge pixels with the pixel's coverage: occluder borders are not resolved below a
// pixel).
void paint_occluders(const RenderOptions& o, SceneIrradiance& scene) {
  cv::Mat& img = scene.pixels;
  const int W = img.cols, H = img.rows, s = scene.subcells;
  std::vector<int> slot_of_pixel;
  if (!o.occluders.empty() && !scene.edge_pixels.empty()) {
    slot_of_pixel.assign(static_cast<size_t>(W) * static_cast<size_t>(H), -1);
    for (std::size_t k = 0; k < scene.edge_pixels.size(); ++k)
      slot_of_pixel[static_cast<size_t>(scene.edge_pixels[k])] = static_cast<int>(k);
  }
  for (const Occluder& occ : o.occluders) {
    const Eigen::Vector2d ext = occ.shape == Occluder::Shape::kDisc
                                    ? Eigen::Vector2d(occ.radius, occ.radius)
                                    : occ.half_size;
    const int u0 = std::max(0, static_cast<int>(std::floor(occ.center.x() - ext.x())));
    const int u1 = std::min(W - 1, static_cast<int>(std::ceil(occ.center.x() + ext.x())));
    const int v0 = std::max(0, static_cast<int>(std::floor(occ.center.y() - ext.y())));
    const int v1 = std::min(H - 1, static_cast<int>(std::ceil(occ.center.y() + ext.y())));
    for (int v = v0; v <= v1; ++v)
      for (int u = u0; u <= u1; ++u) {
        int n_in = 0;
        for (int sy = 0; sy < 4; ++sy)
          for (int sx = 0; sx < 4; ++sx)
            n_in += detail::inside_occluder(
                occ, Eigen::Vector2d(u - 0.5 + (sx + 0.5) / 4, v - 0.5 + (sy + 0.5) / 4), 0.0);
        if (n_in == 0) continue;
        const double a = n_in / 16.0;
        float& px = img.at<float>(v, u);
        px = static_cast<float>((1 - a) * px + a * occ.level);
        if (slot_of_pixel.empty()) continue;
        const int slot = slot_of_pixel[static_cast<size_t>(v * W + u)];
        if (slot < 0) continue;
        for (int k = 0; k < s * s; ++k) {
          float& sub = scene.subcell_values[static_cast<size_t>(slot * s * s + k)];
          sub = static_cast<float>((1 - a) * sub + a * occ.level);
        }
      }
  }
}

}  // namespace

namespace detail {

// The light of a scene without targets: every pixel as render_scene gives one no target meets.
cv::Mat background_light(int W, int H, const RenderOptions& o) {
  cv::Mat img(H, W, CV_32F);
  const double half_diag2 = pixel_gain_scale(W, H);
  for (int j = 0; j < H; ++j) {
    float* row = img.ptr<float>(j);
    for (int i = 0; i < W; ++i)
      row[i] = static_cast<float>(o.background_level * pixel_gain(i, j, W, H, half_diag2, o));
  }
  return img;
}

SceneIrradiance render_scene(const CameraRays& rays, const std::vector<RenderTarget>& targets,
                             const RenderOptions& o, bool with_subcells, const cv::Mat* background,
                             cv::Rect* changed) {
  const int W = rays.cols - 1, H = rays.rows - 1;
  if (W <= 0 || H <= 0) throw std::invalid_argument("render: empty camera rays");
  SceneIrradiance scene;
  scene.subcells = with_subcells ? o.blur_subcells : 1;
  const int s = scene.subcells;
  if (s < 1 || s > 8) throw std::invalid_argument("blur_subcells must be in 1..8");
  if (o.threads < 1 || o.threads > 64) throw std::invalid_argument("threads must be in 1..64");
  with_subcells = with_subcells && s > 1;
  if (background != nullptr &&
      (background->rows != H || background->cols != W || background->type() != CV_32F))
    throw std::invalid_argument("render: the background light does not match the camera");
  scene.pixels = background != nullptr ? background->clone() : background_light(W, H, o);
  const SceneTracer tracer(rays, targets, o, s, with_subcells);
  const CornerWindow& window = tracer.window();
  // The pixels with a corner in the window (pixel (i, j) has corners i, i + 1 and j, j + 1);
  // every other pixel's four corners miss: it keeps the background's light.
  const int pi0 = std::max(0, window.i0 - 1), pi1 = std::min(W - 1, window.i1);
  const int pj0 = std::max(0, window.j0 - 1), pj1 = std::min(H - 1, window.j1);
  const bool any = pi0 <= pi1 && pj0 <= pj1;
  const int rows = any ? pj1 - pj0 + 1 : 0;
  const int bands = std::clamp(o.threads, 1, std::max(rows, 1));
  std::vector<Band> band(static_cast<size_t>(bands));
  if (any)
    core::parallel_for(bands, bands, [&](int b) {
      tracer.render_band(pj0 + rows * b / bands, pj0 + rows * (b + 1) / bands, pi0, pi1,
                         scene.pixels, band[static_cast<size_t>(b)]);
    });
  if (changed != nullptr) *changed = any ? cv::Rect(pi0, pj0, pi1 - pi0 + 1, rows) : cv::Rect();
  for (const Band& b : band) {
    scene.edge_pixels.insert(scene.edge_pixels.end(), b.edge_pixels.begin(), b.edge_pixels.end());
    scene.subcell_values.insert(scene.subcell_values.end(), b.subcell_values.begin(),
                                b.subcell_values.end());
  }
  paint_occluders(o, scene);
  return scene;
}

}  // namespace detail

SceneIrradiance render_irradiance(const CameraRays& rays, const std::vector<RenderTarget>& targets,
                                  const RenderOptions& options) {
  return detail::render_scene(rays, targets, options, options.blur_sigma > 0.0);
}

cv::Mat render_ideal(const CameraRays& rays, const std::vector<RenderTarget>& targets,
                     const RenderOptions& options) {
  return detail::render_scene(rays, targets, options, false).pixels;
}

std::vector<CornerTruth> corner_truth(const CameraModel& camera,
                                      const std::vector<RenderTarget>& targets,
                                      const RenderOptions& o) {
  std::vector<TargetGeometry> geo;
  geo.reserve(targets.size());
  for (const RenderTarget& t : targets) geo.push_back(detail::geometry_of(t));
  std::vector<CornerTruth> out;
  for (int k = 0; k < static_cast<int>(targets.size()); ++k) {
    const RenderTarget& t = targets[static_cast<size_t>(k)];
    for (const TargetCorner& c : t.board.corners) {
      CornerTruth truth;
      truth.target = k;
      truth.id = c.id;
      const Eigen::Vector3d p_cam = t.camera_T_board * c.point;
      const auto px = project(camera, p_cam);
      truth.pixel = px ? *px : Eigen::Vector2d(kNaN, kNaN);
      if (px) {
        // Another target in front of the corner?
        const Eigen::Vector3d ray = p_cam.normalized();
        const double dist = p_cam.norm();
        for (int m = 0; m < static_cast<int>(targets.size()) && !truth.occluded; ++m) {
          if (m == k) continue;
          double s;
          Eigen::Vector2d xy;
          if (detail::intersect(geo[static_cast<size_t>(m)], targets[static_cast<size_t>(m)].board,
                                ray, &s, &xy) &&
              s < dist)
            truth.occluded = true;
        }
        for (const Occluder& occ : o.occluders)
          if (detail::inside_occluder(occ, *px, 1.5 + 3.0 * o.blur_sigma)) truth.occluded = true;
        truth.visible =
            geo[static_cast<size_t>(k)].faces_camera && in_image(camera, *px) && !truth.occluded;
      }
      out.push_back(truth);
    }
  }
  return out;
}

RenderResult render(const CameraRays& rays, const std::vector<RenderTarget>& targets,
                    const RenderOptions& options) {
  RenderResult r;
  r.image = apply_sensor(render_irradiance(rays, targets, options), options);
  r.corners = corner_truth(rays.camera, targets, options);
  return r;
}

}  // namespace robocal::vision
