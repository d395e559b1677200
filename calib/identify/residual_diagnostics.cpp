#include "robocal/calib/residual_diagnostics.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

namespace robocal::calib {

Histogram histogram(const std::vector<double>& values, std::size_t bins, double lo, double hi) {
  if (bins == 0 || !(hi > lo)) throw std::invalid_argument("histogram: need bins >= 1, hi > lo");
  Histogram h;
  h.lo = lo;
  h.width = (hi - lo) / static_cast<double>(bins);
  h.counts.assign(bins, 0);
  for (const double v : values) {
    const double f = std::floor((v - lo) / h.width);
    const double last = static_cast<double>(bins - 1);
    h.counts[static_cast<std::size_t>(std::clamp(std::isfinite(f) ? f : last, 0.0, last))] += 1;
  }
  return h;
}

Correlation pearson_correlation(const std::vector<double>& a, const std::vector<double>& b) {
  Correlation c;
  c.n = std::min(a.size(), b.size());
  if (c.n < 4) return c;
  const double n = static_cast<double>(c.n);
  double mean_a = 0.0, mean_b = 0.0;
  for (std::size_t k = 0; k < c.n; ++k) {
    mean_a += a[k];
    mean_b += b[k];
  }
  mean_a /= n;
  mean_b /= n;
  double saa = 0.0, sbb = 0.0, sab = 0.0;
  for (std::size_t k = 0; k < c.n; ++k) {
    const double da = a[k] - mean_a, db = b[k] - mean_b;
    saa += da * da;
    sbb += db * db;
    sab += da * db;
  }
  if (saa <= 0.0 || sbb <= 0.0) return c;
  c.r = std::clamp(sab / std::sqrt(saa * sbb), -1.0, 1.0);
  // |r| = 1 makes atanh infinite: p = erfc(inf) = 0, which is the right limit.
  const double z = std::atanh(c.r) * std::sqrt(n - 3.0);
  c.p_value = std::erfc(std::abs(z) / std::sqrt(2.0));
  return c;
}

bool ResidualTrends::unmodelled_error_suspected() const {
  return std::any_of(trends.begin(), trends.end(),
                     [](const ResidualTrend& t) { return t.significant; });
}

namespace {

double spread(const std::vector<double>& v) {
  if (v.empty()) return 0.0;
  const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
  return *hi - *lo;
}

double stddev(const std::vector<double>& v) {
  if (v.size() < 2) return 0.0;
  double mean = 0.0;
  for (double x : v) mean += x;
  mean /= static_cast<double>(v.size());
  double ss = 0.0;
  for (double x : v) ss += (x - mean) * (x - mean);
  return std::sqrt(ss / static_cast<double>(v.size() - 1));
}

}  // namespace

ResidualTrends residual_trends(const std::vector<Eigen::VectorXd>& variables,
                               const std::vector<std::string>& names,
                               const std::vector<Eigen::Vector3d>& residuals, double alpha) {
  ResidualTrends d;
  d.n = std::min(variables.size(), residuals.size());
  d.alpha = alpha;
  d.variables = names;
  const std::size_t nv = names.size();
  for (std::size_t k = 0; k < d.n; ++k)
    if (variables[k].size() != static_cast<Eigen::Index>(nv))
      throw std::invalid_argument("residual_trends: pose " + std::to_string(k) + " has " +
                                  std::to_string(variables[k].size()) + " variables, expected " +
                                  std::to_string(nv));
  std::vector<std::vector<double>> variable(nv, std::vector<double>(d.n));
  std::array<std::vector<double>, 3> component;
  for (std::size_t k = 0; k < d.n; ++k) {
    for (std::size_t v = 0; v < nv; ++v)
      variable[v][k] = variables[k][static_cast<Eigen::Index>(v)];
    for (std::size_t c = 0; c < 3; ++c) {
      component[c].resize(d.n);
      component[c][k] = residuals[k][static_cast<Eigen::Index>(c)];
    }
  }
  const double tests = static_cast<double>(3 * nv);
  d.trends.resize(3 * nv);
  for (std::size_t c = 0; c < 3; ++c)
    for (std::size_t v = 0; v < nv; ++v) {
      ResidualTrend& t = d.trends[c * nv + v];
      t.component = static_cast<int>(c);
      t.variable = static_cast<int>(v);
      t.correlation = pearson_correlation(variable[v], component[c]);
      const double sd = stddev(variable[v]);
      t.slope = sd > 0.0 ? t.correlation.r * stddev(component[c]) / sd : 0.0;
      t.amplitude = std::abs(t.slope) * spread(variable[v]);
      t.significant = t.correlation.n >= 4 && t.correlation.p_value * tests < alpha;
    }
  return d;
}

ResidualTrends residual_position_trends(const std::vector<Eigen::Vector3d>& positions,
                                        const std::vector<Eigen::Vector3d>& residuals,
                                        double alpha) {
  const std::vector<Eigen::VectorXd> variables(positions.begin(), positions.end());
  return residual_trends(variables, {"x", "y", "z"}, residuals, alpha);
}

ResidualTrends residual_load_trends(const std::vector<Eigen::VectorXd>& loads,
                                    const std::vector<Eigen::Vector3d>& residuals, double alpha) {
  const std::size_t actuators = loads.empty() ? 0 : static_cast<std::size_t>(loads[0].size());
  std::vector<std::string> names;
  for (std::size_t i = 0; i < actuators; ++i)
    names.push_back("load on actuator " + std::to_string(i + 1));
  return residual_trends(loads, names, residuals, alpha);
}

double ErrorGrid::max_rms() const {
  return rms.empty() ? 0.0 : *std::max_element(rms.begin(), rms.end());
}

ErrorGrid error_grid(const std::vector<Eigen::Vector2d>& points, const std::vector<double>& values,
                     int nx, int ny) {
  if (nx < 1 || ny < 1) throw std::invalid_argument("error_grid: need nx, ny >= 1");
  ErrorGrid g;
  g.nx = nx;
  g.ny = ny;
  const std::size_t cells = static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny);
  g.rms.assign(cells, 0.0);
  g.count.assign(cells, 0);
  const std::size_t n = std::min(points.size(), values.size());
  if (n == 0) return g;
  Eigen::Vector2d lo = points[0], hi = points[0];
  for (std::size_t k = 0; k < n; ++k) {
    lo = lo.cwiseMin(points[k]);
    hi = hi.cwiseMax(points[k]);
  }
  const Eigen::Vector2d extent = (hi - lo).cwiseMax(Eigen::Vector2d::Constant(1e-3));
  g.lo = lo;
  g.cell = extent.cwiseQuotient(Eigen::Vector2d(nx, ny));
  std::vector<double> sum_sq(cells, 0.0);
  for (std::size_t k = 0; k < n; ++k) {
    const Eigen::Vector2d f = (points[k] - lo).cwiseQuotient(g.cell);
    const int ix = std::clamp(static_cast<int>(std::floor(f.x())), 0, nx - 1);
    const int iy = std::clamp(static_cast<int>(std::floor(f.y())), 0, ny - 1);
    const std::size_t i =
        static_cast<std::size_t>(iy) * static_cast<std::size_t>(nx) + static_cast<std::size_t>(ix);
    sum_sq[i] += values[k] * values[k];
    g.count[i] += 1;
  }
  for (std::size_t i = 0; i < cells; ++i)
    if (g.count[i] > 0) g.rms[i] = std::sqrt(sum_sq[i] / static_cast<double>(g.count[i]));
  return g;
}

}  // namespace robocal::calib
