#include "robocal/core/chi_square.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace robocal::core {

namespace {

struct GammaTails {
  double lower = 0.0;  // P(a, x)
  double upper = 1.0;  // Q(a, x) = 1 - P(a, x)
};

// Regularised incomplete gamma functions: the series for P below a + 1, Lentz's continued
// fraction for Q above (the classical pair; both converge to double precision in < 200 terms
// for our arguments). The tail not computed directly is the complement of the other.
GammaTails regularized_gamma(double a, double x) {
  if (!(x > 0.0)) return {};
  if (!std::isfinite(x)) return {1.0, 0.0};
  const double log_prefactor = a * std::log(x) - x - std::lgamma(a);
  if (x < a + 1.0) {
    double term = 1.0 / a;
    double sum = term;
    for (int n = 1; n < 500; ++n) {
      term *= x / (a + n);
      sum += term;
      if (std::abs(term) < 1e-17 * std::abs(sum)) break;
    }
    const double p = sum * std::exp(log_prefactor);
    return {p, 1.0 - p};
  }
  const double tiny = 1e-300;
  double b = x + 1.0 - a;
  double c = 1.0 / tiny;
  double d = 1.0 / b;
  double h = d;
  for (int i = 1; i < 500; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < tiny) d = tiny;
    c = b + an / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1.0 / d;
    const double delta = d * c;
    h *= delta;
    if (std::abs(delta - 1.0) < 1e-16) break;
  }
  const double q = std::exp(log_prefactor) * h;
  return {1.0 - q, q};
}

}  // namespace

double chi_square_cdf(double x, int dof) {
  return regularized_gamma(0.5 * dof, 0.5 * x).lower;
}

double chi_square_survival(double x, int dof) {
  return std::clamp(regularized_gamma(0.5 * dof, 0.5 * x).upper, 0.0, 1.0);
}

double chi_square_quantile(double probability, int dof) {
  if (dof < 1) throw std::invalid_argument("chi_square_quantile: dof must be >= 1");
  if (!(probability > 0.0 && probability < 1.0))
    throw std::invalid_argument("chi_square_quantile: probability must be in (0, 1)");
  const double a = 0.5 * dof;
  double lo = 0.0;
  double hi = dof + 20.0 * std::sqrt(2.0 * dof) + 100.0;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (regularized_gamma(a, 0.5 * mid).lower < probability ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

double chi_square_quantile_upper(double p, int dof) {
  double lo = 0.0;
  double hi = std::max(10.0, 10.0 * dof);
  while (chi_square_survival(hi, dof) > p) hi *= 2.0;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (chi_square_survival(mid, dof) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace robocal::core
