#pragma once
// The chi-square distribution, for consistency tests of weighted residuals (outlier thresholds
// in identification, the motion test between frames of a pose in the camera pipeline).

namespace robocal::core {

// P(X <= x) for X ~ chi-square with `dof` degrees of freedom (0 for x <= 0).
double chi_square_cdf(double x, int dof);
// P(X > x): computed directly in the upper tail, so tiny p-values keep their precision.
double chi_square_survival(double x, int dof);
// The x with chi_square_cdf(x, dof) = probability; probability in (0, 1), dof >= 1, else
// std::invalid_argument.
double chi_square_quantile(double probability, int dof);
// The x with chi_square_survival(x, dof) = p (p in (0, 1)).
double chi_square_quantile_upper(double p, int dof);

}  // namespace robocal::core
