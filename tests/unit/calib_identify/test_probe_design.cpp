// I-optimal exact designs (probe_design.hpp) against closed forms and brute force.
#include "robocal/calib/probe_design.hpp"

#include <gtest/gtest.h>
#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <algorithm>
#include <functional>
#include <limits>
#include <random>

namespace {

using robocal::calib::average_prediction_variance;
using robocal::calib::DesignOptions;
using robocal::calib::i_optimal_design;

// Polynomial regression rows (1, x, ..., x^degree) at the grid points of [-1, 1].
std::vector<Eigen::MatrixXd> polynomial_candidates(int degree, const std::vector<double>& xs) {
  std::vector<Eigen::MatrixXd> rows;
  for (double x : xs) {
    Eigen::MatrixXd r(1, degree + 1);
    for (int k = 0; k <= degree; ++k) r(0, k) = std::pow(x, k);
    rows.push_back(r);
  }
  return rows;
}

std::vector<double> grid21() {
  std::vector<double> xs;
  for (int i = -10; i <= 10; ++i) xs.push_back(i / 10.0);
  return xs;
}

// Target rows whose mean Gram matrix is the uniform measure's moment matrix on [-1, 1]:
// A_jk = ∫ x^(j+k) dx / 2 (1/(j+k+1) for j+k even, else 0). Rows: sqrt(m) × the Cholesky factor.
Eigen::MatrixXd uniform_moment_targets(int degree) {
  const int p = degree + 1;
  Eigen::MatrixXd A(p, p);
  for (int j = 0; j < p; ++j)
    for (int k = 0; k < p; ++k) A(j, k) = (j + k) % 2 == 0 ? 1.0 / (j + k + 1) : 0.0;
  const Eigen::MatrixXd U = A.llt().matrixU();
  return std::sqrt(static_cast<double>(p)) * U;
}

TEST(ProbeDesign, StraightLinePutsThePointsAtTheEnds) {
  // y = a + b x, prediction averaged over [-1, 1]: any two distinct points x1 < x2 give
  // average variance ((1 + x̄²) ... ) minimised at x = ±1 with value 1/2 + 1/6 = 2/3.
  const auto xs = grid21();
  const auto d = i_optimal_design(polynomial_candidates(1, xs), uniform_moment_targets(1), {}, 2);
  ASSERT_EQ(d.chosen.size(), 2U);
  std::vector<double> at = {xs[d.chosen[0]], xs[d.chosen[1]]};
  std::sort(at.begin(), at.end());
  EXPECT_DOUBLE_EQ(at[0], -1.0);
  EXPECT_DOUBLE_EQ(at[1], 1.0);
  EXPECT_NEAR(d.average_variance, 2.0 / 3.0, 1e-6);
}

TEST(ProbeDesign, QuadraticReachesTheKnownIOptimalWeights) {
  // Quadratic regression on [-1, 1], uniform working area: the I-optimal design puts weights
  // 1/4, 1/2, 1/4 on -1, 0, 1 (not D-optimal's 1/3 each). With four points that is exact:
  // {-1, 0, 0, 1}, M = [[4,0,2],[0,2,0],[2,0,2]], trace(M⁻¹A) = 1/2 − 2/3·1/2 + 1/5 + 1/6 = 8/15.
  // An exact design that attains the continuous optimum is optimal among all exact designs.
  const auto xs = grid21();
  DesignOptions o;
  o.allow_repeats = true;
  const auto cand = polynomial_candidates(2, xs);
  const auto targets = uniform_moment_targets(2);
  const auto d = i_optimal_design(cand, targets, {}, 4, o);
  ASSERT_EQ(d.chosen.size(), 4U);
  std::vector<double> at;
  for (auto c : d.chosen) at.push_back(xs[c]);
  std::sort(at.begin(), at.end());
  EXPECT_DOUBLE_EQ(at[0], -1.0);
  EXPECT_DOUBLE_EQ(at[1], 0.0);
  EXPECT_DOUBLE_EQ(at[2], 0.0);
  EXPECT_DOUBLE_EQ(at[3], 1.0);
  EXPECT_NEAR(d.average_variance, 8.0 / 15.0, 1e-6);
  // Brute force over every multiset of four grid points: none is better.
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t a = 0; a < xs.size(); ++a)
    for (std::size_t b = a; b < xs.size(); ++b)
      for (std::size_t c = b; c < xs.size(); ++c)
        for (std::size_t e = c; e < xs.size(); ++e) {
          Eigen::MatrixXd M = Eigen::MatrixXd::Zero(3, 3);
          for (std::size_t k : {a, b, c, e}) M += cand[k].transpose() * cand[k];
          best = std::min(best, average_prediction_variance(M, targets));
        }
  EXPECT_NEAR(best, 8.0 / 15.0, 1e-9);
}

TEST(ProbeDesign, MatchesBruteForceOnRandomLinearModels) {
  // Random linear models with candidates of one or two rows, prior information and working-area
  // rows: greedy plus exchange against every subset of the same size.
  for (unsigned seed = 1; seed <= 5; ++seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> n01(0.0, 1.0);
    const int p = 4;
    std::vector<Eigen::MatrixXd> cand;
    for (int c = 0; c < 12; ++c) {
      Eigen::MatrixXd F(1 + c % 2, p);
      for (Eigen::Index i = 0; i < F.size(); ++i) F.data()[i] = n01(rng);
      cand.push_back(F);
    }
    Eigen::MatrixXd G(6, p);
    for (Eigen::Index i = 0; i < G.size(); ++i) G.data()[i] = n01(rng);
    const Eigen::MatrixXd M0 = 0.1 * Eigen::MatrixXd::Identity(p, p);
    const std::size_t count = 5;
    DesignOptions o;
    o.ridge = 0.0;
    const auto d = i_optimal_design(cand, G, M0, count, o);
    ASSERT_EQ(d.chosen.size(), count);
    double best = std::numeric_limits<double>::infinity();
    std::vector<int> pick;
    for (std::size_t c = 0; c < cand.size(); ++c) pick.push_back(c + count >= cand.size() ? 1 : 0);
    do {
      Eigen::MatrixXd M = M0;
      for (std::size_t c = 0; c < cand.size(); ++c)
        if (pick[c] != 0) M += cand[c].transpose() * cand[c];
      best = std::min(best, average_prediction_variance(M, G));
    } while (std::next_permutation(pick.begin(), pick.end()));
    EXPECT_NEAR(d.average_variance, best, 1e-9 * best) << "seed " << seed;
    EXPECT_LE(d.average_variance, d.greedy_average_variance);
  }
}

TEST(ProbeDesign, LeavesUndeterminedWhatTheWorkingAreaSeesLeast) {
  // Three parameters, two measurements: one direction stays undetermined. Candidates measure
  // e1, e2 or e3; the working area sees e3 only weakly. The design must measure e1 and e2
  // (leaving e3, which the targets see least), whatever order the candidates come in.
  std::vector<Eigen::MatrixXd> cand;
  for (int k : {2, 0, 1}) {
    Eigen::MatrixXd F = Eigen::MatrixXd::Zero(1, 3);
    F(0, k) = 1.0;
    cand.push_back(F);
  }
  Eigen::MatrixXd G(2, 3);
  G << 1.0, 0.5, 0.01, 0.2, 1.0, 0.0;
  const auto d = i_optimal_design(cand, G, {}, 2);
  ASSERT_EQ(d.chosen.size(), 2U);
  std::vector<std::size_t> chosen = d.chosen;
  std::sort(chosen.begin(), chosen.end());
  EXPECT_EQ(chosen, (std::vector<std::size_t>{1, 2}));
}

}  // namespace

namespace {

TEST(ProbeDesign, HeldParameterErrorMatchesSimulation) {
  // A linear model y = F δ + ε (unit noise), the estimator fits the parameters S by least squares
  // with those in H held at 0 while their truth is N(0, σ_H²). The formula for the average
  // squared prediction error over the targets against a simulation of that estimator.
  std::mt19937 rng(7);
  std::normal_distribution<double> n01(0.0, 1.0);
  const int p = 5;
  Eigen::MatrixXd F(8, p);
  for (Eigen::Index i = 0; i < F.size(); ++i) F.data()[i] = n01(rng);
  Eigen::MatrixXd G(4, p);
  for (Eigen::Index i = 0; i < G.size(); ++i) G.data()[i] = n01(rng);
  const std::vector<std::size_t> held = {1, 4};
  Eigen::VectorXd sigma(p);
  sigma << 0.0, 0.7, 0.0, 0.0, 1.3;
  const double formula =
      robocal::calib::average_prediction_error_with_held(F.transpose() * F, G, held, sigma);
  Eigen::MatrixXd FS(F.rows(), 3);
  FS << F.col(0), F.col(2), F.col(3);
  Eigen::MatrixXd GS(G.rows(), 3);
  GS << G.col(0), G.col(2), G.col(3);
  const Eigen::MatrixXd solve = (FS.transpose() * FS).inverse() * FS.transpose();
  double sum = 0.0;
  const int draws = 40000;
  for (int k = 0; k < draws; ++k) {
    Eigen::VectorXd truth(p);
    for (int i = 0; i < p; ++i) truth(i) = sigma(i) > 0.0 ? sigma(i) * n01(rng) : n01(rng);
    Eigen::VectorXd y = F * truth;
    for (Eigen::Index i = 0; i < y.size(); ++i) y(i) += n01(rng);
    const Eigen::VectorXd est = solve * y;
    sum += (GS * est - G * truth).squaredNorm() / static_cast<double>(G.rows());
  }
  const double simulated = sum / draws;
  // The mean of 40 000 draws of a sum of squares: a few per mille of statistical error.
  EXPECT_NEAR(simulated / formula, 1.0, 0.02)
      << "formula " << formula << " simulated " << simulated;
  // Nothing held: the plain average prediction variance.
  EXPECT_NEAR(robocal::calib::average_prediction_error_with_held(F.transpose() * F, G, {}, sigma),
              average_prediction_variance(F.transpose() * F, G), 1e-12);
}

}  // namespace
