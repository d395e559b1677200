// The measured region (convex hull of the measured positions): distances against closed forms
// (a cube, a flat square, a segment), the minimum-distance optimality condition on random sets,
// and the inside/outside split of held-out errors that validate reports.
#include "stages/measured_region.hpp"

#include "robocal/core/random_draws.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace {

using robocal::app::distance_to_region;
using robocal::app::kRegionInsideTolerance;
using robocal::app::NamedPoints;
using robocal::app::split_errors_by_region;
using V = Eigen::Vector3d;

std::vector<V> unit_cube() {
  std::vector<V> c;
  for (int i = 0; i < 8; ++i) c.emplace_back(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  return c;
}

// The answer is a point of the hull (its weights are convex and reproduce it) and no measured
// point lies beyond the plane through it normal to p - closest (first-order optimality of the
// nearest point of a convex set).
void expect_nearest_hull_point(const std::vector<V>& measured, const V& p,
                               const robocal::app::RegionDistance& r) {
  ASSERT_TRUE(r.converged);
  ASSERT_FALSE(r.support.empty());
  ASSERT_LE(r.support.size(), 4u);
  double sum = 0.0;
  V combination = V::Zero();
  for (const auto& [index, weight] : r.support) {
    ASSERT_LT(index, measured.size());
    EXPECT_GE(weight, 0.0);
    sum += weight;
    combination += weight * measured[index];
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  EXPECT_NEAR((combination - r.closest).norm(), 0.0, 1e-12);
  EXPECT_NEAR((p - r.closest).norm(), r.outside_m, 1e-12);
  for (const auto& m : measured)
    EXPECT_LE((p - r.closest).dot(m - r.closest), 1e-12) << "a hull point is nearer to p";
  EXPECT_LE(r.outside_m, r.nearest_measured_m + 1e-15);
  EXPECT_EQ(r.inside, r.outside_m <= kRegionInsideTolerance);
}

TEST(MeasuredRegion, CubeFaceEdgeAndCornerDistances) {
  const auto cube = unit_cube();
  struct Case {
    V p;
    double distance;
  };
  const Case cases[] = {{V(0.5, 0.5, 0.5), 0.0},
                        {V(0.2, 0.9, 0.1), 0.0},
                        {V(2.0, 0.5, 0.5), 1.0},
                        {V(0.3, -0.25, 0.7), 0.25},
                        {V(2.0, 2.0, 0.5), std::sqrt(2.0)},
                        {V(-1.0, -2.0, 3.0), std::sqrt(9.0)},
                        {V(3.0, 3.0, 3.0), std::sqrt(12.0)}};
  for (const auto& c : cases) {
    const auto r = distance_to_region(cube, c.p);
    EXPECT_NEAR(r.outside_m, c.distance, 1e-12) << c.p.transpose();
    EXPECT_EQ(r.inside, c.distance == 0.0) << c.p.transpose();
    expect_nearest_hull_point(cube, c.p, r);
  }
  // (-1,-2,3): nearest hull point is the corner (0,0,1); distance sqrt(1+4+4) = 3.
  EXPECT_NEAR((distance_to_region(cube, V(-1, -2, 3)).closest - V(0, 0, 1)).norm(), 0.0, 1e-12);
}

TEST(MeasuredRegion, AConfigurationAtAMeasuredPoseIsInside) {
  const auto cube = unit_cube();
  for (const auto& m : cube) {
    const auto r = distance_to_region(cube, m);
    EXPECT_TRUE(r.inside);
    EXPECT_NEAR(r.nearest_measured_m, 0.0, 1e-15);
  }
  // Just outside a face by more than the tolerance is outside.
  EXPECT_FALSE(distance_to_region(cube, V(0.5, 0.5, 1.0 + 10 * kRegionInsideTolerance)).inside);
  // Inside but far from every measured pose: interpolation, with the distance to report.
  const auto centre = distance_to_region(cube, V(0.5, 0.5, 0.5));
  EXPECT_TRUE(centre.inside);
  EXPECT_NEAR(centre.nearest_measured_m, std::sqrt(0.75), 1e-12);
}

TEST(MeasuredRegion, FlatAndCollinearDesigns) {
  // Poses all in one plane (z = 0): the region has no volume; a point above is outside by its
  // height, a point on the square inside.
  const std::vector<V> square = {V(0, 0, 0), V(1, 0, 0), V(0, 1, 0), V(1, 1, 0), V(0.5, 0.5, 0)};
  EXPECT_NEAR(distance_to_region(square, V(0.4, 0.7, 0.3)).outside_m, 0.3, 1e-12);
  EXPECT_TRUE(distance_to_region(square, V(0.4, 0.7, 0.0)).inside);
  EXPECT_NEAR(distance_to_region(square, V(2, 0.5, -1)).outside_m, std::sqrt(2.0), 1e-12);
  // A segment from (0,0,0) to (2,0,0).
  const std::vector<V> segment = {V(0, 0, 0), V(1, 0, 0), V(2, 0, 0)};
  EXPECT_NEAR(distance_to_region(segment, V(1.5, 3, 4)).outside_m, 5.0, 1e-12);
  EXPECT_NEAR(distance_to_region(segment, V(3, 0, 0)).outside_m, 1.0, 1e-12);
  EXPECT_TRUE(distance_to_region(segment, V(0.25, 0, 0)).inside);
  // One measured pose; none at all.
  EXPECT_NEAR(distance_to_region({V(1, 2, 3)}, V(1, 2, 5)).outside_m, 2.0, 1e-12);
  EXPECT_FALSE(distance_to_region({}, V(0, 0, 0)).inside);
  EXPECT_TRUE(std::isinf(distance_to_region({}, V(0, 0, 0)).outside_m));
}

TEST(MeasuredRegion, RandomDesignsSatisfyTheOptimalityCondition) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int inside = 0, outside = 0;
  for (int design = 0; design < 5; ++design) {
    // 60 poses in an anisotropic box, like a cell's measured volume (metres).
    std::vector<V> measured;
    // One draw a statement, z first (robocal/core/random_draws.hpp says why).
    for (int i = 0; i < 60; ++i) {
      const double z = 0.1 * u(rng);
      const double y = 0.2 * u(rng);
      const double x = 0.3 * u(rng);
      measured.emplace_back(x, y, z);
    }
    for (int q = 0; q < 60; ++q) {
      const double z = 0.25 * u(rng);
      const double y = 0.4 * u(rng);
      const double x = 0.5 * u(rng);
      const V p(x, y, z);
      const auto r = distance_to_region(measured, p);
      expect_nearest_hull_point(measured, p, r);
      (r.inside ? inside : outside)++;
    }
  }
  // The queries' box is larger than the measured one: both kinds occur.
  EXPECT_GT(inside, 10);
  EXPECT_GT(outside, 10);
}

// validate's split: counts add up, membership follows the hull, and the parts' RMS combine to
// the all-configurations RMS (n·rms² adds up) with the larger max being the overall max.
TEST(MeasuredRegion, SplitErrorsCombineToTheOverallFigures) {
  std::vector<V> measured = unit_cube();
  for (auto& m : measured) m = 0.2 * m;  // a 0.2 m cube of measured positions
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.2, 0.4);
  std::normal_distribution<double> noise(0.0, 30e-6);
  std::vector<V> truth = {measured[3], V(2.0, 0.1, 0.1)};  // at a measured pose; 1.8 m away
  for (int k = 0; k < 98; ++k) truth.push_back(robocal::core::draw_vector3(u, rng));
  std::vector<V> calibrated, nominal;
  for (const auto& t : truth) {
    calibrated.push_back(t + robocal::core::draw_vector3(noise, rng));
    nominal.push_back(t + V(1e-3, 0, 0) + 50 * robocal::core::draw_vector3(noise, rng));
  }
  calibrated[1] += V(0, 0, 5e-3);  // the far configuration is the worst
  std::vector<bool> inside;
  std::vector<double> outside_m;
  for (const auto& t : truth) {
    const auto r = distance_to_region(measured, t);
    inside.push_back(r.inside);
    outside_m.push_back(r.outside_m);
  }
  EXPECT_TRUE(inside[0]) << "a configuration at a measured pose";
  EXPECT_FALSE(inside[1]) << "a configuration 1.8 m away";
  EXPECT_NEAR(outside_m[1], 1.8, 1e-12);

  const auto split = split_errors_by_region(inside, outside_m, truth,
                                            {{"nominal", &nominal}, {"calibrated", &calibrated}});
  const auto& in = split.at("inside");
  const auto& out = split.at("outside");
  const auto n_in = in.at("held_out_poses").get<std::size_t>();
  const auto n_out = out.at("held_out_poses").get<std::size_t>();
  EXPECT_EQ(n_in + n_out, truth.size());
  EXPECT_GT(n_in, 5u);
  EXPECT_GT(n_out, 5u);
  EXPECT_EQ(in.at("calibrated").at("poses").get<std::size_t>(), n_in);
  EXPECT_NEAR(out.at("distance_max_m").get<double>(), 1.8, 1e-12);
  EXPECT_GT(out.at("distance_median_m").get<double>(), 0.0);
  EXPECT_LT(out.at("distance_median_m").get<double>(), 1.8);
  EXPECT_FALSE(in.contains("distance_max_m"));
  for (const char* name : {"nominal", "calibrated"}) {
    const auto& prediction = std::string(name) == "nominal" ? nominal : calibrated;
    double sum_sq = 0.0, max = 0.0;
    for (std::size_t k = 0; k < truth.size(); ++k) {
      const double e = (prediction[k] - truth[k]).norm();
      sum_sq += e * e;
      max = std::max(max, e);
    }
    const double rms_in = in.at(name).at("rms_m");
    const double rms_out = out.at(name).at("rms_m");
    EXPECT_NEAR(static_cast<double>(n_in) * rms_in * rms_in +
                    static_cast<double>(n_out) * rms_out * rms_out,
                sum_sq, 1e-12 * sum_sq)
        << name;
    EXPECT_DOUBLE_EQ(
        std::max(in.at(name).at("max_m").get<double>(), out.at(name).at("max_m").get<double>()),
        max)
        << name;
  }
  // The 5 mm error sits outside, and the inside figure is the 30 µm-per-axis noise (~52 µm).
  EXPECT_GT(out.at("calibrated").at("max_m").get<double>(), 5e-3);
  EXPECT_LT(in.at("calibrated").at("max_m").get<double>(), 0.5e-3);
  EXPECT_NEAR(in.at("calibrated").at("rms_m").get<double>(), std::sqrt(3.0) * 30e-6, 20e-6);
}

TEST(MeasuredRegion, EmptyPartsReportZeroPoses) {
  const std::vector<V> truth = {V(0, 0, 0), V(1, 0, 0)};
  const std::vector<V> predicted = {V(0, 0, 1e-4), V(1, 0, 2e-4)};
  const auto split =
      split_errors_by_region({true, true}, {0.0, 0.0}, truth, {{"calibrated", &predicted}});
  EXPECT_EQ(split.at("outside").at("held_out_poses").get<int>(), 0);
  EXPECT_EQ(split.at("outside").at("calibrated").at("rms_m").get<double>(), 0.0);
  EXPECT_EQ(split.at("outside").at("distance_max_m").get<double>(), 0.0);
  EXPECT_NEAR(split.at("inside").at("calibrated").at("rms_m").get<double>(),
              std::sqrt((1e-8 + 4e-8) / 2.0), 1e-15);
}

}  // namespace
