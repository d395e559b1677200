// The sensor: noise drawn per pixel, the readout quantised to the bit depth.
#include "robocal/vision/renderer.hpp"

#include "robocal/core/parallel.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <vector>

namespace robocal::vision {

namespace {

// Counter-based random numbers (SplitMix64): pixel k's noise depends only on (seed, k).
std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Standard normal draws by the ziggurat method (Marsaglia & Tsang 2000, 256 layers), with
// Doornik's (2005) fix: the layer index and the uniform come from separate bits of a draw. Exact
// to double precision, tails unbounded, and about 99 % of draws cost one table read and one
// comparison where Box-Muller costs a log, a square root and a sine: the sensor noise of a
// 1600x1200 frame was 40 % of its render.
class Ziggurat {
 public:
  static constexpr int kLayers = 256;
  static constexpr double kTail = 3.6541528853610088;  // where the tail begins
  static constexpr double kArea = 4.92867323399e-3;    // the area of each layer

  Ziggurat() {
    double f = std::exp(-0.5 * kTail * kTail);
    x_[0] = kArea / f;  // the base layer: a rectangle of the same area, the tail included
    x_[1] = kTail;
    for (int i = 2; i < kLayers; ++i) {
      x_[i] = std::sqrt(-2.0 * std::log(kArea / x_[i - 1] + f));
      f = std::exp(-0.5 * x_[i] * x_[i]);
    }
    x_[kLayers] = 0.0;
    for (int i = 0; i < kLayers; ++i) inner_[i] = x_[i + 1] / x_[i];
  }

  // One standard normal from the random words `next()` gives (64 bits each; most draws use one).
  template <typename Words>
  [[nodiscard]] double draw(Words&& next) const {
    for (;;) {
      const std::uint64_t w = next();
      const auto i = static_cast<int>(w & (kLayers - 1));
      const double u = (static_cast<double>(w >> 11) + 0.5) * 0x1.0p-52 - 1.0;  // (-1, 1)
      if (std::abs(u) < inner_[i]) return u * x_[i];  // inside the layer's part under the curve
      if (i == 0) return tail(u < 0.0, next);
      // The wedge between the layer's rectangle and the curve: accept under the density.
      const double x = u * x_[i];
      const double f0 = std::exp(-0.5 * (x_[i] * x_[i] - x * x));
      const double f1 = std::exp(-0.5 * (x_[i + 1] * x_[i + 1] - x * x));
      if (f1 + unit(next()) * (f0 - f1) < 1.0) return x;
    }
  }

 private:
  static double unit(std::uint64_t w) {  // (0, 1)
    return (static_cast<double>(w >> 11) + 0.5) * 0x1.0p-53;
  }
  // Beyond kTail (Marsaglia 1964): exact, by rejection from an exponential.
  template <typename Words>
  static double tail(bool negative, Words&& next) {
    double x = 0.0, y = 0.0;
    do {
      x = std::log(unit(next())) / kTail;
      y = std::log(unit(next()));
    } while (-2.0 * y < x * x);
    return negative ? x - kTail : kTail - x;
  }

  std::array<double, kLayers + 1> x_{};
  std::array<double, kLayers> inner_{};
};

// The sensor's output step for light level y (in steps): rounded half away from zero, as
// std::round, and clamped to [0, top] (NaN reads 0). Inline, and the rounding without a branch:
// on noise it goes either way, and the mispredictions were most of the readout's time.
std::int32_t readout_step(double y, double top) {
  const double clamped = y > 0.0 ? (y < top ? y : top) : 0.0;
  const auto whole = static_cast<std::int32_t>(clamped);
  return whole + static_cast<std::int32_t>(clamped - whole >= 0.5);
}

const Ziggurat kZiggurat;

// Standard normals for pixels first .. first + n - 1 of the frame with noise seed `seed`: each
// pixel k has its own stream of random words, so its noise depends only on (seed, k), whatever
// order the pixels are read in.
void pixel_normals(std::uint64_t seed, std::uint64_t first, std::span<double> out) {
  for (std::size_t i = 0; i < out.size(); ++i) {
    const std::uint64_t start = splitmix64(seed ^ splitmix64(first + i));
    std::uint64_t j = 0;
    out[i] = kZiggurat.draw([&] { return j++ == 0 ? start : splitmix64(start + j); });
  }
}

}  // namespace

cv::Mat apply_sensor(const cv::Mat& ideal, const RenderOptions& o) {
  SceneIrradiance scene;
  scene.pixels = ideal;
  return apply_sensor(scene, o);
}

namespace {

void check_sensor_options(const RenderOptions& o) {
  if (o.bit_depth != 8 && o.bit_depth != 16)
    throw std::invalid_argument("bit_depth must be 8 or 16");
  if (o.threads < 1 || o.threads > 64) throw std::invalid_argument("threads must be in 1..64");
}

}  // namespace

cv::Mat sensor_readout(const cv::Mat& img, const RenderOptions& o) {
  if (img.type() != CV_32F) throw std::invalid_argument("sensor_readout: expects a CV_32F image");
  check_sensor_options(o);
  const double scale = o.bit_depth == 16 ? 257.0 : 1.0;
  const double max_value = o.bit_depth == 16 ? 65535.0 : 255.0;
  cv::Mat out(img.rows, img.cols, o.bit_depth == 16 ? CV_16U : CV_8U);
  const bool noisy = o.read_noise > 0.0 || o.shot_noise_gain > 0.0;
  const double read_var = o.read_noise * o.read_noise;
  const double per_gain = o.shot_noise_gain > 0.0 ? 1.0 / o.shot_noise_gain : 0.0;
  const std::uint64_t seed = splitmix64(o.seed);
  // A row at a time: the normal draws first, then the arithmetic, which vectorises. Bands of
  // rows on o.threads workers (each pixel's value depends on that pixel alone).
  const auto read_rows = [&](int v0, int v1) {
    std::vector<double> z(static_cast<std::size_t>(img.cols), 0.0);
    std::vector<double> level(static_cast<std::size_t>(img.cols));
    for (int v = v0; v < v1; ++v) {
      const float* in = img.ptr<float>(v);
      const auto row_start = static_cast<std::uint64_t>(v) * static_cast<std::uint64_t>(img.cols);
      if (noisy) pixel_normals(seed, row_start, z);
      // Pixel k's noise: variance read_var + signal / gain, its draw depending only on (seed, k).
      for (std::size_t u = 0; u < level.size(); ++u) {
        const double x = in[u];
        level[u] = (x + std::sqrt(read_var + std::max(x, 0.0) * per_gain) * z[u]) * scale;
      }
      if (o.bit_depth == 16) {
        auto* row = out.ptr<std::uint16_t>(v);
        for (std::size_t u = 0; u < level.size(); ++u)
          row[u] = static_cast<std::uint16_t>(readout_step(level[u], max_value));
      } else {
        auto* row = out.ptr<std::uint8_t>(v);
        for (std::size_t u = 0; u < level.size(); ++u)
          row[u] = static_cast<std::uint8_t>(readout_step(level[u], max_value));
      }
    }
  };
  const int bands = std::clamp(o.threads, 1, std::max(img.rows, 1));
  core::parallel_for(bands, bands,
                     [&](int b) { read_rows(img.rows * b / bands, img.rows * (b + 1) / bands); });
  return out;
}

cv::Mat apply_sensor(const SceneIrradiance& scene, const RenderOptions& o) {
  check_sensor_options(o);
  return sensor_readout(blurred_irradiance(scene, o), o);
}

}  // namespace robocal::vision
