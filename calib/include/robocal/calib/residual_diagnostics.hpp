#pragma once
// Statistics the calibration report shows, as pure functions over plain data:
// histograms of position errors, error maps binned over the workspace, and residual diagnostics
// that flag unmodelled error — residual components that vary with where the robot is (an
// effector tilt absorbed into arm lengths leaves residuals that grow with height; a sagging arm
// leaves residuals that grow with reach) or with the load its actuators carry (joint compliance).
// A well-specified model leaves residuals that are noise, uncorrelated with position and load.
#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <string>
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

// One residual component (x, y or z) against one explanatory variable (a position coordinate,
// or the load an actuator carries).
struct ResidualTrend {
  int component = 0;  // 0 x, 1 y, 2 z of the residual
  int variable = 0;   // index into ResidualTrends::variables
  Correlation correlation;
  double slope = 0.0;      // residual change per unit of the variable (m per unit), least squares
  double amplitude = 0.0;  // |slope| x the variable's spread (max - min) over the poses: m
  bool significant = false;
};

struct ResidualTrends {
  std::size_t n = 0;
  double alpha = 0.01;                 // family-wise significance level over all pairs (Bonferroni)
  std::vector<std::string> variables;  // names, e.g. "x" or "load on actuator 2"
  std::vector<ResidualTrend> trends;   // [component * variables.size() + variable]
  // Any significant trend: the residuals are not noise, something the model lacks is left over.
  [[nodiscard]] bool unmodelled_error_suspected() const;
};

// Correlates each residual component with each variable (variables[k] holds the values at the
// pose of residuals[k]; every vector the size of `names`). A pair is significant when its
// p-value times the number of pairs is below alpha.
ResidualTrends residual_trends(const std::vector<Eigen::VectorXd>& variables,
                               const std::vector<std::string>& names,
                               const std::vector<Eigen::Vector3d>& residuals, double alpha = 0.01);

// Against the position (positions[k] is where residual[k] was observed; same frame, metres):
// variables "x", "y", "z".
ResidualTrends residual_position_trends(const std::vector<Eigen::Vector3d>& positions,
                                        const std::vector<Eigen::Vector3d>& residuals,
                                        double alpha = 0.01);

// Against the load: loads[k][i] is the static load actuator i carries at pose k (for example
// calib::tool_weight_loads: a unit weight at the tool). Joint or gear compliance, a sagging arm or
// a payload the model lacks leave residuals that follow the load rather than the position.
// Variables "load on actuator 1", ...
ResidualTrends residual_load_trends(const std::vector<Eigen::VectorXd>& loads,
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
