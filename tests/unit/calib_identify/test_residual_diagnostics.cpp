// The report's statistics (calib/residual_diagnostics.hpp) against closed forms computed here and
// against residuals with a known position dependence (an unmodelled effect) or none (noise).
#include "../calib/calib_test_support.hpp"
#include "robocal/calib/closed_form.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/residual_diagnostics.hpp"
#include "robocal/core/random_draws.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace {

using robocal::calib::error_grid;
using robocal::calib::histogram;
using robocal::calib::pearson_correlation;
using robocal::calib::residual_load_trends;
using robocal::calib::residual_position_trends;

TEST(ReportHistogram, CountsEveryValueOnceEdgesIntoTheOuterBins) {
  const auto h = histogram({-1.0, 0.0, 0.24, 0.25, 0.5, 0.99, 1.0, 7.0}, 4, 0.0, 1.0);
  ASSERT_EQ(h.counts.size(), 4U);
  EXPECT_DOUBLE_EQ(h.width, 0.25);
  // [0, .25): -1 (clamped), 0, 0.24; [.25, .5): 0.25; [.5, .75): 0.5; [.75, 1]: 0.99, 1, 7.
  EXPECT_EQ(h.counts[0], 3U);
  EXPECT_EQ(h.counts[1], 1U);
  EXPECT_EQ(h.counts[2], 1U);
  EXPECT_EQ(h.counts[3], 3U);
  EXPECT_THROW(histogram({1.0}, 0, 0.0, 1.0), std::invalid_argument);
}

TEST(ReportCorrelation, MatchesTheClosedFormAndFishersPValue) {
  // a = 1..5, b = 2 1 4 3 5: sum(da db) = 8, sum(da^2) = sum(db^2) = 10 -> r = 0.8.
  const auto c = pearson_correlation({1, 2, 3, 4, 5}, {2, 1, 4, 3, 5});
  EXPECT_NEAR(c.r, 0.8, 1e-12);
  const double z = std::atanh(0.8) * std::sqrt(2.0);
  EXPECT_NEAR(c.p_value, std::erfc(z / std::sqrt(2.0)), 1e-12);
  EXPECT_NEAR(pearson_correlation({1, 2, 3, 4}, {-3, -5, -7, -9}).r, -1.0, 1e-12);
  // Constant or too short: no evidence of anything.
  EXPECT_EQ(pearson_correlation({1, 1, 1, 1, 1}, {1, 2, 3, 4, 5}).p_value, 1.0);
  EXPECT_EQ(pearson_correlation({1, 2, 3}, {1, 2, 3}).r, 0.0);
}

// Positions spread over a 400 mm cube; residuals of 5 µm noise.
struct Cloud {
  std::vector<Eigen::Vector3d> positions, residuals;
};
Cloud noise_cloud(unsigned seed, std::size_t n) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> where(-0.2, 0.2);
  std::normal_distribution<double> noise(0.0, 5e-6);
  Cloud c;
  for (std::size_t k = 0; k < n; ++k) {
    // One draw a statement, z first (robocal/core/random_draws.hpp says why).
    const double z = 0.8 + where(rng);
    const double y = where(rng);
    const double x = where(rng);
    c.positions.emplace_back(x, y, z);
    c.residuals.push_back(robocal::core::draw_vector3(noise, rng));
  }
  return c;
}

TEST(ReportResidualTrends, NoiseIsNotFlagged) {
  const Cloud c = noise_cloud(11, 300);
  const auto d = residual_position_trends(c.positions, c.residuals);
  EXPECT_EQ(d.n, 300U);
  EXPECT_FALSE(d.unmodelled_error_suspected());
  for (const auto& t : d.trends) EXPECT_LT(std::abs(t.correlation.r), 0.25);
}

TEST(ReportResidualTrends, AToolTiltLeftInTheResidualsIsFlaggedWithItsSlope) {
  // An unmodelled tilt of 0.1 mrad about y: the x residual grows with height z (1e-4 m per m,
  // 40 µm over the 400 mm range), far above the 5 µm noise.
  Cloud c = noise_cloud(12, 300);
  const double tilt = 1e-4;
  for (std::size_t k = 0; k < c.positions.size(); ++k)
    c.residuals[k].x() += tilt * (c.positions[k].z() - 0.8);
  const auto d = residual_position_trends(c.positions, c.residuals);
  ASSERT_TRUE(d.unmodelled_error_suspected());
  const auto& xz = d.trends[0 * 3 + 2];
  EXPECT_TRUE(xz.significant);
  EXPECT_EQ(xz.component, 0);
  EXPECT_EQ(xz.variable, 2);
  EXPECT_EQ(d.variables[2], "z");
  // Least-squares slope: its standard error is noise / (sd(z) sqrt(n)) = 5e-6 / (0.115 * 17.3).
  const double slope_sigma = 5e-6 / (0.4 / std::sqrt(12.0) * std::sqrt(300.0));
  EXPECT_NEAR(xz.slope, tilt, 4.0 * slope_sigma);
  EXPECT_NEAR(xz.amplitude, tilt * 0.4, 0.4 * 4.0 * slope_sigma + 1e-5);
  // Only that pair is flagged.
  for (std::size_t i = 0; i < d.trends.size(); ++i) {
    if (i != 2) {
      EXPECT_FALSE(d.trends[i].significant) << "pair " << i;
    }
  }
}

TEST(ReportErrorGrid, RmsPerCellOverTheBoundingBox) {
  // Four points in the corners of a 2 x 1 box, two in the lower-left cell.
  const std::vector<Eigen::Vector2d> p = {{0, 0}, {0.1, 0.1}, {2, 0}, {0, 1}, {2, 1}};
  const std::vector<double> v = {3, 4, 1, 2, 5};
  const auto g = error_grid(p, v, 2, 2);
  EXPECT_DOUBLE_EQ(g.cell.x(), 1.0);
  EXPECT_DOUBLE_EQ(g.cell.y(), 0.5);
  EXPECT_EQ(g.count[0], 2U);
  EXPECT_NEAR(g.rms[0], std::sqrt((9.0 + 16.0) / 2.0), 1e-12);
  EXPECT_EQ(g.count[1], 1U);  // (2, 0): the upper edge belongs to the last cell
  EXPECT_DOUBLE_EQ(g.rms[1], 1.0);
  EXPECT_DOUBLE_EQ(g.rms[2], 2.0);
  EXPECT_DOUBLE_EQ(g.rms[3], 5.0);
  EXPECT_DOUBLE_EQ(g.max_rms(), 5.0);
}

// The loads of a unit weight at the tool are the slopes of the tool's height in each actuator
// (virtual work): checked against the rotary Delta's closed-form forward kinematics,
// differentiated here with its own step.
TEST(ToolWeightLoads, AreTheSlopesOfTheClosedFormToolHeight) {
  using namespace robocal::calib;
  const Mechanism m = robocal::calib::testing::load("rotary_delta.yaml");
  const MechanismPredictor predictor(m);
  const Eigen::VectorXd p = m.nominal_parameters();
  for (const Eigen::Vector3d& q : {Eigen::Vector3d(0.2, 0.4, 0.1), Eigen::Vector3d(0.5, 0.1, 0.3),
                                   Eigen::Vector3d(-0.2, 0.3, 0.6)}) {
    Eigen::VectorXd loads;
    ASSERT_TRUE(tool_weight_loads(predictor, p, q, loads));
    ASSERT_EQ(loads.size(), 3);
    for (int i = 0; i < 3; ++i) {
      const double h = 1e-5;
      const auto up = delta_forward(m.closed_form, q + h * Eigen::Vector3d::Unit(i));
      const auto down = delta_forward(m.closed_form, q - h * Eigen::Vector3d::Unit(i));
      ASSERT_TRUE(up && down);
      const double slope = (up->z() - down->z()) / (2 * h);
      EXPECT_NEAR(loads[i], slope, 1e-6) << "actuator " << i + 1 << " at " << q.transpose();
    }
  }
}

// A compliant second actuator: the residual along x is its load times a compliance (5 mm per
// unit load, about 0.1 mm over the poses), with 5 um noise. The load test flags that pair and
// estimates the compliance; with noise alone nothing is flagged.
TEST(ReportResidualTrends, AnErrorThatFollowsAnActuatorsLoadIsFlagged) {
  using namespace robocal::calib;
  const Mechanism m = robocal::calib::testing::load("rotary_delta.yaml");
  const MechanismPredictor predictor(m);
  const Eigen::VectorXd p = m.nominal_parameters();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> angle(-0.2, 0.6);
  std::normal_distribution<double> noise(0.0, 5e-6);
  std::vector<Eigen::VectorXd> loads;
  std::vector<Eigen::Vector3d> clean, compliant;
  while (loads.size() < 120) {
    const Eigen::Vector3d q = robocal::core::draw_vector3(angle, rng);
    Eigen::VectorXd load;
    if (!tool_weight_loads(predictor, p, q, load)) continue;
    loads.push_back(load);
    const Eigen::Vector3d n = robocal::core::draw_vector3(noise, rng);
    clean.push_back(n);
    compliant.emplace_back(n + Eigen::Vector3d(5e-3 * load[1], 0, 0));
  }
  EXPECT_FALSE(residual_load_trends(loads, clean).unmodelled_error_suspected());
  const ResidualTrends d = residual_load_trends(loads, compliant);
  ASSERT_EQ(d.trends.size(), 9U);
  EXPECT_EQ(d.variables[1], "load on actuator 2");
  const ResidualTrend& x2 = d.trends[0 * 3 + 1];
  EXPECT_TRUE(x2.significant);
  EXPECT_NEAR(x2.slope, 5e-3, 5e-4);
  // The x residual follows the second actuator's load more closely than any other's; y and z
  // carry noise only.
  for (std::size_t i = 0; i < 9; ++i) {
    if (i < 3 && i != 1) {
      EXPECT_LT(std::abs(d.trends[i].correlation.r), std::abs(x2.correlation.r));
    }
    if (i >= 3) {
      EXPECT_FALSE(d.trends[i].significant) << d.variables[i % 3] << " component " << i / 3;
    }
  }
}

}  // namespace
