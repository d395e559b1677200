// Gauge choice with little data (gauge_choice.hpp) against brute force on small linear models:
// every subset's expected prediction error computed by actually solving the held-at-nominal
// least-squares problem for each unit noise vector and each unit held deviation.
#include "robocal/calib/gauge_choice.hpp"

#include <gtest/gtest.h>
#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace {

using robocal::calib::choose_gauge;
using robocal::calib::GaugeOptions;

Eigen::MatrixXd columns(const Eigen::MatrixXd& X, const std::vector<std::size_t>& cols) {
  Eigen::MatrixXd out(X.rows(), static_cast<Eigen::Index>(cols.size()));
  for (std::size_t k = 0; k < cols.size(); ++k)
    out.col(static_cast<Eigen::Index>(k)) = X.col(static_cast<Eigen::Index>(cols[k]));
  return out;
}

// Mean over the target rows of the squared prediction error of the estimator that fits the
// columns `est` to data y = J d + e and holds the others at 0: noise part summed over unit noise
// vectors (white, unit σ), bias part over each held parameter's deviation sigma_j e_j.
struct Brute {
  double total = 0.0;
  double bias = 0.0;
};
Brute brute_force(const Eigen::MatrixXd& J, const Eigen::MatrixXd& G, const Eigen::VectorXd& sigma,
                  const std::vector<std::size_t>& est) {
  const Eigen::MatrixXd Js = columns(J, est);
  const Eigen::MatrixXd Gs = columns(G, est);
  const auto m = static_cast<double>(G.rows());
  auto fit = [&](const Eigen::VectorXd& y) -> Eigen::VectorXd {
    return Js.colPivHouseholderQr().solve(y);
  };
  Brute b;
  for (Eigen::Index i = 0; i < J.rows(); ++i) {
    const Eigen::VectorXd x = fit(Eigen::VectorXd::Unit(J.rows(), i));
    b.total += (Gs * x).squaredNorm() / m;
  }
  for (Eigen::Index j = 0; j < J.cols(); ++j) {
    if (std::find(est.begin(), est.end(), static_cast<std::size_t>(j)) != est.end()) continue;
    const Eigen::VectorXd d = sigma(j) * Eigen::VectorXd::Unit(J.cols(), j);
    const Eigen::VectorXd x = fit(J * d);
    b.bias += (Gs * x - G * d).squaredNorm() / m;
  }
  b.total += b.bias;
  return b;
}

// Every r-subset of p columns.
std::vector<std::vector<std::size_t>> subsets(std::size_t p, std::size_t r) {
  std::vector<std::vector<std::size_t>> out;
  std::vector<bool> mask(p, false);
  std::fill(mask.begin(), mask.begin() + static_cast<std::ptrdiff_t>(r), true);
  do {
    std::vector<std::size_t> s;
    for (std::size_t j = 0; j < p; ++j)
      if (mask[j]) s.push_back(j);
    out.push_back(s);
  } while (std::prev_permutation(mask.begin(), mask.end()));
  return out;
}

// Rank-r data (6 equations, 7 parameters, rank 4: J = A B), targets of full rank: every 4-subset
// fits the data equally; the choice must be the brute-force minimum, criterion and bias equal.
TEST(GaugeChoice, PicksTheBruteForceMinimumOnARankDeficientLinearModel) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n01;
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::MatrixXd A = Eigen::MatrixXd::NullaryExpr(6, 4, [&] { return n01(rng); });
    const Eigen::MatrixXd B = Eigen::MatrixXd::NullaryExpr(4, 7, [&] { return n01(rng); });
    const Eigen::MatrixXd J = A * B;
    const Eigen::MatrixXd G = Eigen::MatrixXd::NullaryExpr(30, 7, [&] { return n01(rng); });
    Eigen::VectorXd sigma(7);
    for (Eigen::Index j = 0; j < 7; ++j) sigma(j) = std::exp(n01(rng));
    const std::vector<std::size_t> initial = {0, 1, 2, 3};
    for (const bool bias_only : {false, true}) {
      GaugeOptions o;
      o.bias_only = bias_only;
      const auto choice = choose_gauge(J, G, sigma, initial, {}, {}, o);
      double best = std::numeric_limits<double>::infinity();
      std::vector<std::size_t> best_set;
      for (const auto& s : subsets(7, 4)) {
        const Brute b = brute_force(J, G, sigma, s);
        const double v = bias_only ? b.bias : b.total;
        if (v < best) {
          best = v;
          best_set = s;
        }
      }
      EXPECT_EQ(choice.evaluated, 35u);
      EXPECT_EQ(choice.estimated, best_set) << "trial " << trial;
      EXPECT_NEAR(choice.expected_error, best, 1e-9 * best);
      const Brute at = brute_force(J, G, sigma, choice.estimated);
      EXPECT_NEAR(choice.bias, at.bias, 1e-9 * at.total);
      const Brute first = brute_force(J, G, sigma, initial);
      EXPECT_NEAR(choice.initial_expected_error, bias_only ? first.bias : first.total,
                  1e-9 * first.total);
      EXPECT_EQ(choice.changed, best_set != initial);
      EXPECT_EQ(choice.held.size(), 3u);
    }
  }
}

// Sets the data do not separate are never chosen: with columns 0 and 1 equal, no estimated set
// holds both; parameters with tiny tolerances (known) are the ones held.
TEST(GaugeChoice, OnlySeparableSetsAndTolerancesDecide) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n01;
  const Eigen::MatrixXd A = Eigen::MatrixXd::NullaryExpr(6, 4, [&] { return n01(rng); });
  Eigen::MatrixXd B = Eigen::MatrixXd::NullaryExpr(4, 7, [&] { return n01(rng); });
  B.col(1) = B.col(0);
  const Eigen::MatrixXd J = A * B;
  const Eigen::MatrixXd G = Eigen::MatrixXd::NullaryExpr(30, 7, [&] { return n01(rng); });
  Eigen::VectorXd sigma = Eigen::VectorXd::Ones(7);
  const auto choice = choose_gauge(J, G, sigma, {0, 2, 3, 4}, {}, {});
  EXPECT_EQ(choice.evaluated, 35u - 10u);  // the C(5, 2) sets with both 0 and 1 are out
  EXPECT_FALSE(
      std::find(choice.estimated.begin(), choice.estimated.end(), 0) != choice.estimated.end() &&
      std::find(choice.estimated.begin(), choice.estimated.end(), 1) != choice.estimated.end());
  // Tolerances decide: three parameters known to 1e-9 are the ones held (no bias) when the
  // rank analysis would have estimated them.
  {
    const Eigen::MatrixXd Jg = A * Eigen::MatrixXd::NullaryExpr(4, 7, [&] { return n01(rng); });
    Eigen::VectorXd s = sigma;
    s.tail(3).setConstant(1e-9);
    GaugeOptions o;
    o.bias_only = true;
    const auto tight = choose_gauge(Jg, G, s, {3, 4, 5, 6}, {}, {}, o);
    EXPECT_EQ(tight.estimated, (std::vector<std::size_t>{0, 1, 2, 3}));
    EXPECT_TRUE(tight.changed);
    EXPECT_LT(tight.bias, 1e-12 * tight.initial_bias);
  }
  // must_estimate is honoured.
  const auto forced = choose_gauge(J, G, sigma, {0, 2, 3, 4}, {6}, {});
  EXPECT_TRUE(std::find(forced.estimated.begin(), forced.estimated.end(), 6) !=
              forced.estimated.end());
}

// Too many subsets: exchanges from the given set never end above it and keep a separable set.
TEST(GaugeChoice, ExchangeSearchImprovesOnTheGivenSet) {
  std::mt19937 rng(11);
  std::normal_distribution<double> n01;
  const Eigen::MatrixXd A = Eigen::MatrixXd::NullaryExpr(6, 4, [&] { return n01(rng); });
  const Eigen::MatrixXd B = Eigen::MatrixXd::NullaryExpr(4, 7, [&] { return n01(rng); });
  const Eigen::MatrixXd J = A * B;
  const Eigen::MatrixXd G = Eigen::MatrixXd::NullaryExpr(30, 7, [&] { return n01(rng); });
  const Eigen::VectorXd sigma = Eigen::VectorXd::Ones(7);
  GaugeOptions o;
  o.max_subsets = 1;
  const auto choice = choose_gauge(J, G, sigma, {0, 1, 2, 3}, {}, {}, o);
  EXPECT_LE(choice.expected_error, choice.initial_expected_error);
  EXPECT_NEAR(choice.expected_error, brute_force(J, G, sigma, choice.estimated).total,
              1e-9 * choice.expected_error);
  EXPECT_EQ(choice.estimated.size(), 4u);
}

// Issue 48: criteria equal up to rounding are a tie, decided by the fixed rule (the
// lexicographically first set of column indices) whichever of the two is computed larger.
TEST(GaugeChoice, CriteriaEqualUpToRoundingAreDecidedByTheFixedRule) {
  using robocal::calib::gauge_criterion_less;
  const std::vector<std::size_t> first = {0, 1};
  const std::vector<std::size_t> second = {0, 2};
  for (const double noise : {1e-13, -1e-13, 1e-9, -1e-9}) {
    EXPECT_TRUE(gauge_criterion_less(1.0 + noise, first, 1.0, second)) << noise;
    EXPECT_FALSE(gauge_criterion_less(1.0, second, 1.0 + noise, first)) << noise;
  }
  // A real difference still decides by value.
  EXPECT_TRUE(gauge_criterion_less(1.0, second, 1.01, first));
  EXPECT_FALSE(gauge_criterion_less(1.01, first, 1.0, second));
  // Non-finite criteria are never less.
  EXPECT_FALSE(gauge_criterion_less(std::numeric_limits<double>::infinity(), first, 1.0, second));

  // A mirror-symmetric model (columns 1 and 2 the same up to a last-bits factor, as a Delta's
  // arms): the sets {0, 1} and {0, 2} fit equally; whichever is computed larger and whichever
  // the analysis gives, the choice is {0, 1}, by full enumeration and by exchanges.
  for (const double eps : {1e-14, -1e-14, 3e-12, -3e-12}) {
    Eigen::MatrixXd J(3, 3);
    J << 1.0, 0.3, 0.3 * (1.0 + eps), 0.2, 1.0, 1.0 + eps, 0.0, 0.5, 0.5 * (1.0 + eps);
    Eigen::MatrixXd G(4, 3);
    G << 1.0, 0.5, 0.5 * (1.0 + eps), 0.0, 1.0, 1.0 + eps, 0.3, 0.2, 0.2 * (1.0 + eps), 1.0, 1.0,
        1.0 + eps;
    const Eigen::VectorXd sigma = Eigen::VectorXd::Ones(3);
    for (const std::size_t max_subsets : {std::size_t{20000}, std::size_t{1}}) {
      GaugeOptions o;
      o.max_subsets = max_subsets;
      for (const auto& initial : {first, second}) {
        const auto choice = choose_gauge(J, G, sigma, initial, {}, {}, o);
        EXPECT_EQ(choice.estimated, first) << "eps " << eps << ", max_subsets " << max_subsets;
      }
    }
  }
}

}  // namespace
