#include "robocal/calib/noise_estimate.hpp"

#include "robocal/calib/uncertainty.hpp"
#include "robocal/core/median.hpp"

#include <fmt/core.h>
#include <Eigen/QR>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace robocal::calib {
namespace {

// Leverages h_ii and (JᵀJ)⁻¹ of a full-rank J through the SVD of its column-scaled form (unit-free
// rank test, as parameter_uncertainty does). The SVD is taken of the triangle R of a thin QR of
// the tall scaled J (its singular values and right vectors are J's): on a camera array's pixel
// route (tens of thousands of rows, 54 columns) an SVD of J itself took 1.5 s, this a tenth.
bool leverage(const Eigen::MatrixXd& J, Eigen::VectorXd& h, Eigen::MatrixXd& normal_inverse,
              std::string& why) {
  const Eigen::Index n = J.cols();
  Eigen::VectorXd norms = J.colwise().norm().transpose();
  for (Eigen::Index j = 0; j < n; ++j)
    if (!(norms(j) > 0.0)) {
      why = fmt::format("column {} of the Jacobian is zero", j);
      return false;
    }
  if (J.rows() < n) {
    why = "the Jacobian is rank deficient";
    return false;
  }
  const Eigen::MatrixXd scaled = J * norms.cwiseInverse().asDiagonal();
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(scaled);
  const Eigen::MatrixXd r = qr.matrixQR().topRows(n).triangularView<Eigen::Upper>();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(r, Eigen::ComputeFullV);
  const Eigen::VectorXd& s = svd.singularValues();
  if (n > 0 && !(s(n - 1) > 1e-12 * s(0))) {
    why = "the Jacobian is rank deficient";
    return false;
  }
  // The left singular vectors U = scaled V S⁻¹; the leverages are the squared norms of its rows.
  h = (scaled * (svd.matrixV() * s.cwiseInverse().asDiagonal())).rowwise().squaredNorm();
  normal_inverse = norms.cwiseInverse().asDiagonal() * svd.matrixV() *
                   s.cwiseAbs2().cwiseInverse().asDiagonal() * svd.matrixV().transpose() *
                   norms.cwiseInverse().asDiagonal();
  return true;
}

}  // namespace

NoiseEstimate estimate_noise(const Eigen::MatrixXd& whitened_jacobian,
                             const Eigen::VectorXd& whitened_residuals,
                             const std::vector<int>& row_group, std::vector<NoiseGroup> groups,
                             int max_iterations) {
  const Eigen::Index m = whitened_jacobian.rows();
  if (whitened_residuals.size() != m || static_cast<Eigen::Index>(row_group.size()) != m)
    throw std::invalid_argument("estimate_noise: one residual and one group per row needed");
  NoiseEstimate out;
  const auto G = static_cast<int>(groups.size());
  for (auto& g : groups) g.rows = 0;
  for (int g : row_group) {
    if (g >= G) throw std::invalid_argument("estimate_noise: row group out of range");
    if (g >= 0) ++groups[static_cast<std::size_t>(g)].rows;
  }
  out.row_scale = Eigen::VectorXd::Ones(m);
  std::vector<double> scale(groups.size(), 1.0);
  Eigen::VectorXd h;
  for (out.iterations = 0; out.iterations < std::max(1, max_iterations); ++out.iterations) {
    const Eigen::MatrixXd J = out.row_scale.cwiseInverse().asDiagonal() * whitened_jacobian;
    if (!leverage(J, h, out.normal_inverse, out.message)) return out;
    const Eigen::VectorXd r = whitened_residuals.cwiseQuotient(out.row_scale);
    std::vector<double> sum_r2(groups.size(), 0.0);
    std::vector<double> red(groups.size(), 0.0);
    for (Eigen::Index i = 0; i < m; ++i) {
      const int g = row_group[static_cast<std::size_t>(i)];
      if (g < 0) continue;
      sum_r2[static_cast<std::size_t>(g)] += r(i) * r(i);
      red[static_cast<std::size_t>(g)] += std::max(0.0, 1.0 - h(i));
    }
    double change = 0.0;
    for (std::size_t g = 0; g < groups.size(); ++g) {
      groups[g].redundancy = red[g];
      groups[g].estimable = red[g] >= 1.0 && sum_r2[g] > 0.0;
      if (!groups[g].estimable) continue;
      const double factor = sum_r2[g] / red[g];  // variance factor relative to current weights
      scale[g] *= std::sqrt(factor);
      change = std::max(change, std::abs(std::sqrt(factor) - 1.0));
    }
    for (Eigen::Index i = 0; i < m; ++i) {
      const int g = row_group[static_cast<std::size_t>(i)];
      out.row_scale(i) = g < 0 ? 1.0 : scale[static_cast<std::size_t>(g)];
    }
    if (change < 1e-10) break;
  }
  // Final weights: leverages, normal inverse, intervals and the robust scale.
  const Eigen::MatrixXd J = out.row_scale.cwiseInverse().asDiagonal() * whitened_jacobian;
  if (!leverage(J, h, out.normal_inverse, out.message)) return out;
  out.redundancy = (Eigen::VectorXd::Ones(m) - h).cwiseMax(0.0);
  const Eigen::VectorXd r = whitened_residuals.cwiseQuotient(out.row_scale);
  for (std::size_t g = 0; g < groups.size(); ++g) {
    NoiseGroup& grp = groups[g];
    grp.scale = grp.estimable ? scale[g] : 1.0;
    std::vector<double> normalised;
    for (Eigen::Index i = 0; i < m; ++i)
      if (row_group[static_cast<std::size_t>(i)] == static_cast<int>(g) && out.redundancy(i) > 1e-6)
        normalised.push_back(std::abs(r(i)) / std::sqrt(out.redundancy(i)));
    grp.robust_scale = grp.scale;
    if (normalised.size() >= 5) {
      const double mad = 1.4826 * core::median(normalised, 0.0);
      if (mad > 0.0) grp.robust_scale = grp.scale * mad;
    }
    if (grp.estimable) {
      const int dof = std::max(1, static_cast<int>(std::lround(grp.redundancy)));
      // Σ r̃² (at the estimated scale) / 1 ≈ χ²_dof · (true/estimated)²: invert for the interval.
      grp.scale_low = grp.scale * std::sqrt(dof / chi_square_quantile(0.975, dof));
      grp.scale_high = grp.scale * std::sqrt(dof / chi_square_quantile(0.025, dof));
    } else {
      grp.scale_low = grp.scale_high = 1.0;
    }
  }
  out.groups = std::move(groups);
  out.ok = true;
  out.message = fmt::format("noise estimated for {} observation type(s) in {} iteration(s)",
                            std::count_if(out.groups.begin(), out.groups.end(),
                                          [](const NoiseGroup& g) { return g.estimable; }),
                            out.iterations + 1);
  return out;
}

Eigen::MatrixXd pose_residual_covariance(const Eigen::MatrixXd& block_jacobian,
                                         const Eigen::MatrixXd& normal_inverse, bool in_fit) {
  const Eigen::MatrixXd H = block_jacobian * normal_inverse * block_jacobian.transpose();
  const Eigen::MatrixXd I = Eigen::MatrixXd::Identity(H.rows(), H.cols());
  return in_fit ? Eigen::MatrixXd(I - H) : Eigen::MatrixXd(I + H);
}

}  // namespace robocal::calib
