// The closure solvers' conditioning numerics (calib/src/tree_evaluator.hpp), white-box: the ratio
// sigma_min / sigma_max decides the `ambiguous` verdict and the design-branch check, so the cheap
// estimate, the Cholesky certificate and the gate that combines them are checked against matrices
// built with known singular values (J = U diag(s) V^T, U and V random orthogonal), where the ratio
// is s_min / s_max by construction.
#include "tree_evaluator.hpp"

#include <gtest/gtest.h>
#include <Eigen/LU>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <random>

namespace robocal::calib::detail {
namespace {

Eigen::MatrixXd random_orthogonal(Eigen::Index n, std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::MatrixXd a(n, n);
  for (Eigen::Index i = 0; i < a.size(); ++i) a.data()[i] = g(rng);
  return Eigen::HouseholderQR<Eigen::MatrixXd>(a).householderQ();
}

struct Case {
  Eigen::MatrixXd J;
  double ratio;  // sigma_min / sigma_max by construction
};

// n = 15 (the Delta's closure): singular values spread log-uniformly over [ratio, 1] times a
// scale, the smallest exactly `ratio` times the largest; sometimes a near-double smallest value
// (the inverse iteration's slow case).
Case make_case(double ratio, std::mt19937& rng) {
  const Eigen::Index n = 15;
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double scale = std::pow(10.0, 4.0 * u(rng) - 2.0);
  Eigen::VectorXd s(n);
  s[0] = 1.0;
  s[n - 1] = ratio;
  for (Eigen::Index i = 1; i < n - 1; ++i) s[i] = std::pow(ratio, u(rng));
  if (u(rng) < 0.3) s[n - 2] = ratio * (1.0 + 0.05 * u(rng));
  // One draw a statement, the right factor first (robocal/core/random_draws.hpp says why).
  const Eigen::MatrixXd right = random_orthogonal(n, rng);
  const Eigen::MatrixXd left = random_orthogonal(n, rng);
  return {left * (scale * s).asDiagonal() * right.transpose(), ratio};
}

double log_uniform(double lo, double hi, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(std::log(lo), std::log(hi));
  return std::exp(u(rng));
}

TEST(ConditioningNumerics, ExactRatioIsTheConstructedOne) {
  std::mt19937 rng(1);
  for (int k = 0; k < 50; ++k) {
    const Case c = make_case(log_uniform(1e-4, 0.5, rng), rng);
    EXPECT_NEAR(sigma_ratio(c.J), c.ratio, 1e-9 * c.ratio);
  }
}

TEST(ConditioningNumerics, SmallLuSolvesAsADenseInverse) {
  // The LU the Newton steps and the estimate use: A^-1 b and (A^T A)^-1 b against Eigen's
  // inverse, on random matrices whose row order forces pivoting; a zero column is refused.
  std::mt19937 rng(5);
  std::normal_distribution<double> g(0.0, 1.0);
  for (int n : {1, 3, 15, 18}) {
    Eigen::MatrixXd a(n, n);
    for (Eigen::Index i = 0; i < a.size(); ++i) a.data()[i] = g(rng);
    Eigen::VectorXd b(n);
    for (Eigen::Index i = 0; i < n; ++i) b[i] = g(rng);
    SmallLu lu;
    ASSERT_TRUE(lu.factor(a));
    const Eigen::MatrixXd inv = a.inverse();
    Eigen::VectorXd x = b;
    lu.solve(x);
    EXPECT_LT((x - inv * b).norm(), 1e-10 * (inv * b).norm()) << "n " << n;
    Eigen::VectorXd y = b;
    lu.gram_inverse_apply(y);
    const Eigen::VectorXd want = inv * inv.transpose() * b;
    EXPECT_LT((y - want).norm(), 1e-9 * want.norm()) << "n " << n;
    a.col(0).setZero();
    EXPECT_FALSE(lu.factor(a));
    EXPECT_FALSE(lu.ok());
  }
}

TEST(ConditioningNumerics, EstimateNeverUnderstatesTheRatio) {
  // Its power iteration gives a lower bound of sigma_max and its inverse iteration (through the
  // LU factors' triangular solves) an upper bound of sigma_min: the estimate can only overstate,
  // which the gate relies on.
  std::mt19937 rng(2);
  Eigen::VectorXd v(15), w(15);
  for (int k = 0; k < 500; ++k) {
    const Case c = make_case(log_uniform(1e-4, 0.5, rng), rng);
    SmallLu lu;
    ASSERT_TRUE(lu.factor(c.J));
    const double estimate = sigma_ratio_estimate(lu, c.J, v, w);
    EXPECT_GE(estimate, c.ratio * (1.0 - 1e-9)) << "case " << k;
    // The same from J^T J (callers without LU factors): a Rayleigh quotient for sigma_max^2 and
    // inverse iteration through the Cholesky factor for sigma_min^2. Below ~1e-3 the squared
    // No looser than the LU route: the same inverse iteration, and sigma_max from more power
    // iterations.
    Eigen::MatrixXd B;
    double rho = 0.0;
    ASSERT_TRUE(gram_and_rho(c.J, B, rho));
    const double from_gram = gram_ratio_estimate(B, rho, v);
    EXPECT_GE(from_gram, c.ratio * (1.0 - 1e-6)) << "case " << k;
    EXPECT_LE(from_gram, estimate * (1.0 + 1e-6)) << "case " << k;
  }
}

TEST(ConditioningNumerics, CertificateNeverClaimsARatioItDoesNotHave) {
  // Sound: true only where the ratio is above t. Useful: true for most ratios clearly above t.
  std::mt19937 rng(3);
  const double t = 0.01;
  int clear = 0, proved = 0;
  for (int k = 0; k < 600; ++k) {
    const Case c = make_case(log_uniform(0.3 * t, 10.0 * t, rng), rng);
    const bool certified = sigma_ratio_certainly_above(c.J, t);
    if (certified) {
      EXPECT_GT(c.ratio, t) << "case " << k;
    }
    if (c.ratio > 1.5 * t) {
      ++clear;
      proved += certified ? 1 : 0;
    }
  }
  ASSERT_GT(clear, 100);
  EXPECT_GT(proved, clear * 9 / 10) << proved << " of " << clear;
}

TEST(ConditioningNumerics, GatedRatioLiesBetweenTheSameThresholdsAsTheTrueOne) {
  // With the estimate never trusted on its own, the gated value must fall on the same side of
  // both thresholds as the true ratio, and be the true ratio below the lower one (the ambiguous
  // verdict reports the real distance to the singularity).
  std::mt19937 rng(4);
  Eigen::VectorXd v(15), w(15);
  const double gate = 0.01, upper = 0.03;
  int below = 0, between = 0, above = 0;
  for (int k = 0; k < 900; ++k) {
    const Case c = make_case(log_uniform(0.3 * gate, 3.0 * upper, rng), rng);
    SmallLu lu;
    ASSERT_TRUE(lu.factor(c.J));
    const double r = gated_sigma_ratio(&lu, c.J, v, w, 1e9, gate, upper).ratio;
    EXPECT_EQ(r < gate, c.ratio < gate) << "case " << k << ": " << r << " vs " << c.ratio;
    EXPECT_EQ(r < upper, c.ratio < upper) << "case " << k << ": " << r << " vs " << c.ratio;
    // Without LU factors (the estimate from J^T J): the same sides of both thresholds.
    const double g = gated_sigma_ratio(nullptr, c.J, v, w, 1e9, gate, upper).ratio;
    EXPECT_EQ(g < gate, c.ratio < gate) << "case " << k << ": " << g << " vs " << c.ratio;
    EXPECT_EQ(g < upper, c.ratio < upper) << "case " << k << ": " << g << " vs " << c.ratio;
    if (c.ratio < gate) {
      EXPECT_NEAR(r, c.ratio, 1e-9 * c.ratio);
      EXPECT_NEAR(g, c.ratio, 1e-9 * c.ratio);
      ++below;
    } else {
      (c.ratio < upper ? between : above)++;
    }
  }
  EXPECT_GT(below, 50);
  EXPECT_GT(between, 50);
  EXPECT_GT(above, 50);
}

}  // namespace
}  // namespace robocal::calib::detail
