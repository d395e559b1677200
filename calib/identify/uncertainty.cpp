#include "robocal/calib/uncertainty.hpp"

#include <fmt/core.h>
#include <Eigen/Dense>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace robocal::calib {

ParameterUncertainty parameter_uncertainty(const Eigen::MatrixXd& whitened_jacobian,
                                           const std::vector<std::string>& names,
                                           const CovarianceOptions& options,
                                           const Eigen::VectorXd& whitened_residuals) {
  const Eigen::Index n = whitened_jacobian.cols();
  const Eigen::Index m = whitened_jacobian.rows();
  if (static_cast<Eigen::Index>(names.size()) != n)
    throw std::invalid_argument("parameter_uncertainty: one name per Jacobian column needed");
  ParameterUncertainty out;
  out.names = names;
  out.confidence = options.confidence;
  if (!whitened_jacobian.allFinite()) {
    out.message = "the Jacobian contains NaN or infinite values";
    return out;
  }
  if (m < n) {
    out.message = fmt::format("{} equations for {} parameters: no covariance exists", m, n);
    return out;
  }
  // Column scaling makes the singularity test unit-free; the SVD gives a stable inverse.
  Eigen::VectorXd norms = whitened_jacobian.colwise().norm().transpose();
  for (Eigen::Index j = 0; j < n; ++j) {
    if (!(norms(j) > 0.0)) {
      out.message = fmt::format("{} has no effect on the measurements: no covariance exists",
                                names[static_cast<std::size_t>(j)]);
      return out;
    }
  }
  const Eigen::MatrixXd scaled = whitened_jacobian * norms.cwiseInverse().asDiagonal();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(scaled, Eigen::ComputeThinV);
  const Eigen::VectorXd& s = svd.singularValues();
  if (n > 0 && s(n - 1) < options.singular_tolerance * s(0)) {
    out.message = fmt::format(
        "the normal matrix is singular (relative singular value {:.2g}): remove redundant "
        "parameters before computing a covariance",
        s(n - 1) / s(0));
    return out;
  }
  const Eigen::MatrixXd& V = svd.matrixV();
  Eigen::MatrixXd cov_scaled = V * s.cwiseAbs2().cwiseInverse().asDiagonal() * V.transpose();
  out.covariance =
      norms.cwiseInverse().asDiagonal() * cov_scaled * norms.cwiseInverse().asDiagonal();

  if (options.scale_by_residual_variance) {
    if (whitened_residuals.size() != m)
      throw std::invalid_argument("parameter_uncertainty: residuals needed for variance scaling");
    if (m > n) out.variance_factor = whitened_residuals.squaredNorm() / static_cast<double>(m - n);
    out.covariance *= out.variance_factor;
  }
  out.sigma = out.covariance.diagonal().cwiseSqrt();
  out.correlation = out.sigma.cwiseInverse().asDiagonal() * out.covariance *
                    out.sigma.cwiseInverse().asDiagonal();
  out.quantile = normal_quantile(0.5 + 0.5 * options.confidence);
  out.ci_half_width = out.quantile * out.sigma;
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = i + 1; j < n; ++j)
      if (std::abs(out.correlation(i, j)) >= options.correlation_threshold)
        out.strongly_correlated.push_back(
            {static_cast<std::size_t>(i), static_cast<std::size_t>(j), out.correlation(i, j)});
  std::sort(out.strongly_correlated.begin(), out.strongly_correlated.end(),
            [](const CorrelatedPair& a, const CorrelatedPair& b) {
              return std::abs(a.correlation) > std::abs(b.correlation);
            });
  out.ok = true;
  out.message = fmt::format("covariance of {} parameters from {} equations (condition {:.3g})", n,
                            m, n > 0 ? s(0) / s(n - 1) : 0.0);
  return out;
}

Eigen::MatrixXd propagate_covariance(const Eigen::MatrixXd& output_jacobian,
                                     const Eigen::MatrixXd& parameter_covariance) {
  if (output_jacobian.cols() != parameter_covariance.rows())
    throw std::invalid_argument("propagate_covariance: Jacobian columns != covariance size");
  return output_jacobian * parameter_covariance * output_jacobian.transpose();
}

PredictedAccuracy predict_accuracy(const std::vector<Eigen::MatrixXd>& pose_jacobians,
                                   const Eigen::MatrixXd& parameter_covariance) {
  PredictedAccuracy out;
  double sum_p = 0.0;
  double sum_o = 0.0;
  double sum_z = 0.0;
  for (const auto& J : pose_jacobians) {
    if (J.rows() != 3 && J.rows() != 6)
      throw std::invalid_argument("predict_accuracy: pose Jacobians must have 3 or 6 rows");
    const Eigen::MatrixXd C = propagate_covariance(J, parameter_covariance);
    const double tp = C.topLeftCorner<3, 3>().trace();
    const double to = J.rows() == 6 ? C.bottomRightCorner<3, 3>().trace() : 0.0;
    out.position_rms.push_back(std::sqrt(std::max(tp, 0.0)));
    out.orientation_rms.push_back(std::sqrt(std::max(to, 0.0)));
    out.position_worst = std::max(out.position_worst, out.position_rms.back());
    sum_p += tp;
    sum_o += to;
    sum_z += C(2, 2);
  }
  if (!pose_jacobians.empty()) {
    const auto k = static_cast<double>(pose_jacobians.size());
    out.position_rms_overall = std::sqrt(std::max(sum_p / k, 0.0));
    out.orientation_rms_overall = std::sqrt(std::max(sum_o / k, 0.0));
    out.height_rms_overall = std::sqrt(std::max(sum_z / k, 0.0));
  }
  return out;
}

double normal_quantile(double probability) {
  if (!(probability > 0.0 && probability < 1.0))
    throw std::invalid_argument("normal_quantile: probability must be in (0, 1)");
  // Bisection on the CDF written with erfc: exact to double precision, no tables needed.
  double lo = -40.0;
  double hi = 40.0;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    const double cdf = 0.5 * std::erfc(-mid / std::sqrt(2.0));
    (cdf < probability ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

FactoredTest factored_residual_test(const Eigen::VectorXd& whitened, const Eigen::MatrixXd& L,
                                    double sign, double covariance_factor) {
  constexpr double kEigenvalueCut = 1e-6;  // as for a dense residual_covariance
  FactoredTest t;
  const Eigen::Index n = whitened.size();
  Eigen::VectorXd rest = whitened;  // the part outside span(L), where Q's eigenvalue is the factor
  Eigen::Index spanned = 0;
  if (L.cols() > 0) {
    // L = U Σ Vᵀ: eigenvalues of L Lᵀ are those of LᵀL, with eigenvectors u = L v / σ.
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(L.transpose() * L);
    const double largest = std::max(1.0, eig.eigenvalues().cwiseAbs().maxCoeff());
    for (Eigen::Index i = 0; i < eig.eigenvalues().size(); ++i) {
      const double s2 = eig.eigenvalues()(i);
      // A direction L barely reaches has Q's eigenvalue ~ factor, as the complement: leaving it
      // there changes rᵀ Q⁺ r by less than s2 while its u would be noise.
      if (!(s2 > 1e-12 * largest)) continue;
      const Eigen::VectorXd u = L * eig.eigenvectors().col(i) / std::sqrt(s2);
      const double p = u.dot(whitened);
      rest -= p * u;
      ++spanned;
      const double lambda = covariance_factor * (1.0 + sign * s2);
      if (lambda > kEigenvalueCut) {
        t.chi_square += p * p / lambda;
        ++t.dof;
      }
    }
  }
  if (covariance_factor > kEigenvalueCut) {
    t.chi_square += rest.squaredNorm() / covariance_factor;
    t.dof += static_cast<int>(n - spanned);
  }
  return t;
}

ResidualDiagnostics diagnose_residuals(const std::vector<PoseResidual>& residuals,
                                       const OutlierOptions& options) {
  ResidualDiagnostics out;
  std::vector<double> magnitudes;
  for (const auto& r : residuals)
    for (Eigen::Index i = 0; i < r.whitened.size(); ++i)
      magnitudes.push_back(std::abs(r.whitened(i)));
  const bool normalised = !residuals.empty() && (residuals.front().residual_covariance.size() > 0 ||
                                                 residuals.front().leverage_factor.rows() > 0);
  if (options.robust_scale && !normalised && !magnitudes.empty()) {
    auto mid = magnitudes.begin() + static_cast<std::ptrdiff_t>(magnitudes.size() / 2);
    std::nth_element(magnitudes.begin(), mid, magnitudes.end());
    const double robust = 1.4826 * *mid;
    if (robust > 0.0) out.scale = robust;
  }
  double sum_p = 0.0;
  double sum_o = 0.0;
  for (const auto& r : residuals) {
    PoseResidualSummary s;
    s.id = r.id;
    s.dof = static_cast<int>(r.whitened.size());
    s.chi_square = r.whitened.squaredNorm() / (out.scale * out.scale);
    if (r.leverage_factor.rows() > 0) {
      const FactoredTest t = factored_residual_test(r.whitened, r.leverage_factor, r.leverage_sign,
                                                    r.covariance_factor);
      s.dof = t.dof;
      s.chi_square = t.chi_square;
    } else if (r.residual_covariance.size() > 0) {
      // Normalised: directions of the block the fit absorbed (eigenvalue ~0) carry no test.
      const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(r.residual_covariance);
      const Eigen::VectorXd proj = eig.eigenvectors().transpose() * r.whitened;
      s.dof = 0;
      s.chi_square = 0.0;
      for (Eigen::Index i = 0; i < proj.size(); ++i)
        if (eig.eigenvalues()(i) > 1e-6) {
          s.chi_square += proj(i) * proj(i) / eig.eigenvalues()(i);
          ++s.dof;
        }
    }
    s.threshold = s.dof > 0 ? chi_square_quantile(1.0 - options.probability, s.dof) : 0.0;
    s.outlier = s.dof > 0 && (!std::isfinite(s.chi_square) || s.chi_square > s.threshold);
    s.position_error = r.position_error;
    s.orientation_error = r.orientation_error;
    out.outliers += s.outlier ? 1 : 0;
    sum_p += r.position_error * r.position_error;
    sum_o += r.orientation_error * r.orientation_error;
    out.position_max = std::max(out.position_max, r.position_error);
    out.orientation_max = std::max(out.orientation_max, r.orientation_error);
    out.poses.push_back(std::move(s));
  }
  if (!residuals.empty()) {
    const auto k = static_cast<double>(residuals.size());
    out.position_rms = std::sqrt(sum_p / k);
    out.orientation_rms = std::sqrt(sum_o / k);
  }
  return out;
}

}  // namespace robocal::calib
