#pragma once
// Statistics the calibration report shows (issue 20), as pure functions over plain data:
// histograms of position errors, error maps binned over the workspace, and residual diagnostics
// that flag unmodelled error — residual components that vary with where the robot is (an
// effector tilt absorbed into arm lengths leaves residuals that grow with height; a sagging arm
// leaves residuals that grow with reach). A well-specified model leaves residuals that are noise,
// uncorrelated with position.
#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <vector>

namespace robocal::calib {

// Equal-width bins over [lo, hi); values below lo go into the first bin, values at or above hi
// into the last (so every value is counted once).
struct Histogram {
  double lo = 0.0;
  double width = 0.0;
  std::vector<std::size_t> counts;
};
// bins >= 1, hi > lo.
Histogram histogram(const std::vector<double>& values, std::size_t bins, double lo, double hi);

// Pearson correlation of a and b (same size) with its two-sided p-value for "no correlation"
// (Fisher's z: atanh(r) sqrt(n - 3) is standard normal under independence). n < 4 or a constant
// series: r = 0, p = 1.
struct Correlation {
  double r = 0.0;
  double p_value = 1.0;
  std::size_t n = 0;
};
Correlation pearson_correlation(const std::vector<double>& a, const std::vector<double>& b);

// One residual component (x, y or z) against one position coordinate (x, y or z).
struct ResidualTrend {
  int component = 0;   // 0 x, 1 y, 2 z of the residual
  int coordinate = 0;  // 0 x, 1 y, 2 z of the position
  Correlation correlation;
  double slope = 0.0;      // residual change per unit of position (m per m), least squares
  double amplitude = 0.0;  // |slope| x the positions' spread (max - min) along the coordinate: m
  bool significant = false;
};

struct PositionTrends {
  std::size_t n = 0;
  double alpha = 0.01;  // family-wise significance level over the nine pairs (Bonferroni)
  std::array<ResidualTrend, 9> trends{};  // [component * 3 + coordinate]
  // Any significant trend: the residuals are not noise, something the model lacks is left over.
  [[nodiscard]] bool unmodelled_error_suspected() const;
};

// Correlates each residual component with each position coordinate (positions[k] is where
// residual[k] was observed; both in the same frame, metres). A pair is significant when its
// p-value times 9 is below alpha.
PositionTrends residual_position_trends(const std::vector<Eigen::Vector3d>& positions,
                                        const std::vector<Eigen::Vector3d>& residuals,
                                        double alpha = 0.01);

// The RMS of values over a regular grid of a 2-D projection of the workspace (top view: x/y,
// side view: x/z): the error map. Cells without a value have count 0 and rms 0.
struct ErrorGrid {
  Eigen::Vector2d lo = Eigen::Vector2d::Zero();
  Eigen::Vector2d cell = Eigen::Vector2d::Ones();  // cell size along each axis
  int nx = 0, ny = 0;
  std::vector<double> rms;         // [iy * nx + ix]
  std::vector<std::size_t> count;  // [iy * nx + ix]
  [[nodiscard]] double max_rms() const;
};
// The grid spans the points' bounding box (a degenerate axis gets a unit-free width of 1e-3).
ErrorGrid error_grid(const std::vector<Eigen::Vector2d>& points, const std::vector<double>& values,
                     int nx, int ny);

}  // namespace robocal::calib
