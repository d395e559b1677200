// The lens blur: the light of each pixel and of each edge pixel's sub-cells spread over its
// neighbours before the pixels integrate it.
#include "render/scene_light.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <vector>

namespace robocal::vision {

namespace {

// Share of the light of a uniform strip [x0, x1] (1-D, pixel units) that the Gaussian blur
// puts into the pixel [n - 1/2, n + 1/2]: the double integral of g_sigma(y - x), in closed form
// with Psi(t) = t Phi(t) + phi(t), the antiderivative of the normal CDF Phi.
double strip_to_pixel(double n, double x0, double x1, double sigma) {
  const auto psi = [](double t) {
    return t * 0.5 * std::erfc(-t / std::numbers::sqrt2) +
           std::exp(-0.5 * t * t) / std::sqrt(2.0 * std::numbers::pi);
  };
  const double lo = n - 0.5, hi = n + 0.5;
  return sigma * (psi((hi - x0) / sigma) - psi((lo - x0) / sigma) - psi((hi - x1) / sigma) +
                  psi((lo - x1) / sigma));
}

// Weights of the s sub-strips of pixel 0 on pixels -r..r: row a is sub-strip a.
std::vector<float> substrip_weights(int s, int r, double sigma) {
  std::vector<float> w(static_cast<size_t>(s * (2 * r + 1)));
  for (int a = 0; a < s; ++a)
    for (int d = -r; d <= r; ++d)
      w[static_cast<size_t>(a * (2 * r + 1) + d + r)] = static_cast<float>(
          strip_to_pixel(d, -0.5 + double(a) / s, -0.5 + double(a + 1) / s, sigma));
  return w;
}

}  // namespace

namespace detail {

cv::Mat blur_before_sampling(const SceneIrradiance& scene, double sigma,
                             const cv::Mat* blurred_background, const cv::Rect& changed) {
  const cv::Mat& pixels = scene.pixels;
  const int W = pixels.cols, H = pixels.rows;
  const int r = static_cast<int>(std::ceil(5.0 * sigma)) + 1;  // the kernel below 1e-6
  const int taps = 2 * r + 1;
  const cv::Rect whole(0, 0, W, H);
  const auto grow = [r](const cv::Rect& a) {
    return cv::Rect(a.x - r, a.y - r, a.width + 2 * r, a.height + 2 * r);
  };
  const std::vector<float> pixel_kernel = substrip_weights(1, r, sigma);
  // The pixels' own light without the edge pixels' (their sub-cells are spread below), over
  // `part` of the image.
  const auto uniform_light = [&](const cv::Rect& part) {
    cv::Mat uniform = pixels(part).clone();
    for (const int k : scene.edge_pixels) {
      const cv::Point p(k % W, k / W);
      if (part.contains(p)) uniform.at<float>(p - part.tl()) = 0.0f;
    }
    return uniform;
  };
  cv::Mat out;
  const cv::Mat kernel(taps, 1, CV_32F, const_cast<float*>(pixel_kernel.data()));
  if (blurred_background != nullptr) {
    out = blurred_background->clone();
    // Pixels farther than r from every changed one see only the background.
    const cv::Rect near = grow(changed) & whole;
    if (!changed.empty() && !near.empty()) {
      // The filter reads r pixels around `near` (the image's own where it has them, the mirror
      // beyond its border): only that much of the light is copied, and the part filtered is the
      // same part of it, so the sums are the whole image's.
      const cv::Rect read = grow(near) & whole;
      const cv::Mat uniform = uniform_light(read);
      cv::Mat part;
      cv::sepFilter2D(uniform(near - read.tl()), part, CV_32F, kernel, kernel, cv::Point(-1, -1),
                      0.0, cv::BORDER_REFLECT);
      part.copyTo(out(near));
    }
  } else {
    cv::sepFilter2D(uniform_light(whole), out, CV_32F, kernel, kernel, cv::Point(-1, -1), 0.0,
                    cv::BORDER_REFLECT);
  }
  if (scene.edge_pixels.empty()) return out;

  const int s = scene.subcells;
  const std::vector<float> w = substrip_weights(s, r, sigma);
  // Light of edge pixels, on the image grown by r on each side, then folded back (a mirrored
  // source lands on the pixel mirrored from where the direct source lands). Only the part of
  // the grown image the edge pixels reach is held: grown column x0 + x is image column
  // x0 + x - r (edge pixel u reaches grown columns u .. u + 2r), and the same for rows.
  int u_lo = W, u_hi = -1, v_lo = H, v_hi = -1;
  for (const int k : scene.edge_pixels) {
    u_lo = std::min(u_lo, k % W);
    u_hi = std::max(u_hi, k % W);
    v_lo = std::min(v_lo, k / W);
    v_hi = std::max(v_hi, k / W);
  }
  const int x0 = u_lo, y0 = v_lo;
  cv::Mat grown = cv::Mat::zeros(v_hi - v_lo + taps, u_hi - u_lo + taps, CV_32F);
  std::vector<float> across(static_cast<size_t>(s * taps));  // sub-row b spread across columns
  for (std::size_t e = 0; e < scene.edge_pixels.size(); ++e) {
    const int u = scene.edge_pixels[e] % W, v = scene.edge_pixels[e] / W;
    const float* f = &scene.subcell_values[e * static_cast<size_t>(s * s)];
    for (int b = 0; b < s; ++b)
      for (int d = 0; d < taps; ++d) {
        float acc = 0.0f;
        for (int a = 0; a < s; ++a) acc += f[b * s + a] * w[static_cast<size_t>(a * taps + d)];
        across[static_cast<size_t>(b * taps + d)] = acc;
      }
    for (int dy = 0; dy < taps; ++dy) {
      // grown row v + dy = image row v + dy - r
      float* row = grown.ptr<float>(v - y0 + dy) + (u - x0);
      for (int b = 0; b < s; ++b) {
        const float wy = w[static_cast<size_t>(b * taps + dy)];
        const float* a_row = &across[static_cast<size_t>(b * taps)];
        for (int dx = 0; dx < taps; ++dx) row[dx] += wy * a_row[dx];
      }
    }
  }
  // Columns in the same order as one loop over x (the sums are the same to the last bit), the
  // mirror looked up only where it is one. The grown image is zero outside the part held, and
  // adding zero leaves a pixel as it is: the folded image is the whole grown image's.
  const int x1 = x0 + grown.cols;  // one past the last grown column held
  const int inner_end = std::max(r, W + r);
  for (int y = y0; y < y0 + grown.rows; ++y) {
    const int iy = cv::borderInterpolate(y - r, H, cv::BORDER_REFLECT);
    const float* src = grown.ptr<float>(y - y0);
    float* dst = out.ptr<float>(iy);
    for (int x = x0; x < std::min(r, x1); ++x)
      dst[cv::borderInterpolate(x - r, W, cv::BORDER_REFLECT)] += src[x - x0];
    for (int x = std::max(x0, r); x < std::min(inner_end, x1); ++x) dst[x - r] += src[x - x0];
    for (int x = std::max(x0, inner_end); x < x1; ++x)
      dst[cv::borderInterpolate(x - r, W, cv::BORDER_REFLECT)] += src[x - x0];
  }
  return out;
}

}  // namespace detail

cv::Mat blurred_irradiance(const SceneIrradiance& scene, const RenderOptions& o) {
  if (scene.pixels.type() != CV_32F)
    throw std::invalid_argument("apply_sensor: expects a CV_32F image");
  if (scene.subcell_values.size() !=
      scene.edge_pixels.size() * static_cast<size_t>(scene.subcells * scene.subcells))
    throw std::invalid_argument("apply_sensor: sub-cell values do not match the edge pixels");
  return o.blur_sigma > 0.0 ? detail::blur_before_sampling(scene, o.blur_sigma) : scene.pixels;
}

}  // namespace robocal::vision
