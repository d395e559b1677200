#pragma once
// Uncertainty and residual diagnostics of an identification, as pure functions over the whitened
// identification Jacobian and residuals (rows already multiplied by the inverse square root of
// each measurement's covariance, so unit-variance noise is assumed).
#include <Eigen/Core>
#include "robocal/core/chi_square.hpp"

#include <cstddef>
#include <string>
#include <vector>

namespace robocal::calib {

struct CovarianceOptions {
  double confidence = 0.95;            // two-sided confidence level of the reported intervals
  double correlation_threshold = 0.9;  // |ρ| at or above this is reported as strongly correlated
  // Scale the covariance by the a-posteriori variance factor rᵀr/(m−n) (use when the stated
  // measurement noise is not trusted). Needs the residuals.
  bool scale_by_residual_variance = false;
  // Relative singular value (column-scaled) below which JᵀJ is called singular: redundant
  // parameters must be removed (see identifiability.hpp) before a covariance exists.
  double singular_tolerance = 1e-10;
};

struct CorrelatedPair {
  std::size_t first = 0;
  std::size_t second = 0;
  double correlation = 0.0;
};

struct ParameterUncertainty {
  bool ok = false;      // false when JᵀJ is singular (message says why)
  std::string message;  // plain words
  std::vector<std::string> names;
  Eigen::MatrixXd covariance;   // (JᵀJ)⁻¹ [× variance factor]
  Eigen::VectorXd sigma;        // sqrt of the diagonal
  Eigen::MatrixXd correlation;  // covariance normalised by σ_i σ_j
  double confidence = 0.95;
  double quantile = 0.0;          // standard normal quantile used for the intervals
  Eigen::VectorXd ci_half_width;  // quantile · σ
  double variance_factor = 1.0;   // applied factor (1 unless scale_by_residual_variance)
  std::vector<CorrelatedPair> strongly_correlated;  // sorted by |ρ| descending
};

// Covariance of the least-squares estimate from the whitened Jacobian at the solution.
// `whitened_residuals` is only needed for scale_by_residual_variance.
ParameterUncertainty parameter_uncertainty(const Eigen::MatrixXd& whitened_jacobian,
                                           const std::vector<std::string>& names,
                                           const CovarianceOptions& options = {},
                                           const Eigen::VectorXd& whitened_residuals = {});

// Covariance of a derived quantity y = f(params) with Jacobian J_y: J_y Σ J_yᵀ.
Eigen::MatrixXd propagate_covariance(const Eigen::MatrixXd& output_jacobian,
                                     const Eigen::MatrixXd& parameter_covariance);

// Predicted end-effector accuracy over a set of poses. Each Jacobian has the frame position in its
// first three rows (and, when 6 rows, the world-frame rotation vector in the last three) with one
// column per estimated parameter.
struct PredictedAccuracy {
  std::vector<double> position_rms;     // per pose: sqrt(trace Σ_pp) = expected 3-D error RMS
  std::vector<double> orientation_rms;  // per pose, rad (0 when only 3 rows)
  double position_rms_overall = 0.0;    // sqrt(mean over poses of trace Σ_pp)
  // sqrt(mean over poses of Σ_zz): the vertical (world z) part alone; on a printer whose bed is
  // the world's xy plane, the bed height (first layer).
  double height_rms_overall = 0.0;
  double position_worst = 0.0;
  double orientation_rms_overall = 0.0;
};
PredictedAccuracy predict_accuracy(const std::vector<Eigen::MatrixXd>& pose_jacobians,
                                   const Eigen::MatrixXd& parameter_covariance);

// Standard normal quantile (inverse CDF), by bisection on the exact CDF (erfc). The chi-square
// quantile is core's (core/chi_square.hpp).
double normal_quantile(double probability);
using core::chi_square_quantile;

// Residual of one pose (or one observation) after the fit.
struct PoseResidual {
  std::string id;
  Eigen::VectorXd whitened;        // r / σ (unit variance when the noise model is right)
  double position_error = 0.0;     // metres (Euclidean), for reporting
  double orientation_error = 0.0;  // radians (angle), for reporting (0 if not observed)
  // Covariance of `whitened` under the noise model (noise_estimate.hpp: I − J_b C J_bᵀ for rows
  // in the fit): when given, the test statistic is rᵀ Q⁺ r with the rank of Q as dof (correct for
  // any leverage and any mix of σ) and `whitened` is taken as already scaled (no robust rescaling).
  Eigen::MatrixXd residual_covariance;
  // The same covariance in factored form, given instead of residual_covariance when the block is
  // large (a pose seen by several cameras has hundreds of pixel rows, and the eigen decomposition
  // of an n x n matrix cost a six-camera Gantry-Tau a minute): Q = covariance_factor ·
  // (I + leverage_sign · L Lᵀ) with L = J_b C^½ (n x parameters). Its eigenvalues come from the
  // small Gram matrix LᵀL; the test is the same rᵀ Q⁺ r with the same eigenvalue cut.
  Eigen::MatrixXd leverage_factor;
  double leverage_sign = -1.0;     // −1: rows in the fit, +1: rows that were not
  double covariance_factor = 1.0;  // the squared ratio of the fit's to the test's noise scale
};

// rᵀ Q⁺ r and the number of eigenvalues of Q above 1e-6, with Q = covariance_factor ·
// (I + sign · L Lᵀ): exact, at the cost of a parameters x parameters eigen decomposition.
struct FactoredTest {
  double chi_square = 0.0;
  int dof = 0;
};
FactoredTest factored_residual_test(const Eigen::VectorXd& whitened, const Eigen::MatrixXd& L,
                                    double sign, double covariance_factor);

struct OutlierOptions {
  // A pose is an outlier when its normalised squared residual exceeds the chi-square quantile with
  // its dimension at 1 − probability.
  double probability = 1e-3;
  // Normalise by a robust scale (1.4826 · median |whitened component|) instead of trusting the
  // stated noise: keeps the test meaningful when the stated σ is off (units, optimism).
  bool robust_scale = true;
};

struct PoseResidualSummary {
  std::string id;
  double chi_square = 0.0;  // ‖r‖² / scale²
  int dof = 0;
  double threshold = 0.0;
  double position_error = 0.0;
  double orientation_error = 0.0;
  bool outlier = false;
};

// Fit residuals of one observation type in its own unit, |measured − predicted| per observation
// (a point's or pose's position: the Euclidean distance; a rotation: the angle).
struct TypeResiduals {
  std::string type;  // "point", "pose position", "pose rotation", "probe height", "distance"
  std::string unit;  // "m" or "rad"
  std::size_t count = 0;
  double rms = 0.0;
  double max = 0.0;
};

struct ResidualDiagnostics {
  std::vector<PoseResidualSummary> poses;
  // Per observation type present in the fit (identify fills it; the position figures below
  // count probe heights as positions and leave distances out).
  std::vector<TypeResiduals> by_type;
  double scale = 1.0;  // the scale used (1 or robust)
  double position_rms = 0.0;
  double position_max = 0.0;
  double orientation_rms = 0.0;
  double orientation_max = 0.0;
  std::size_t outliers = 0;
  // Probe heights among the fitted observations: the data of a printer's bed.
  [[nodiscard]] bool has_probe_heights() const {
    for (const auto& t : by_type)
      if (t.type == "probe height" && t.count > 0) return true;
    return false;
  }
};
ResidualDiagnostics diagnose_residuals(const std::vector<PoseResidual>& residuals,
                                       const OutlierOptions& options = {});

}  // namespace robocal::calib
