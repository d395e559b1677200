// Held-out error statistics and the realised camera frame: a measurement world turned and moved
// by a known small transform (a camera's principal point off), with noise on every measured
// position, is found again from the measured positions and their truth alone.
#include "robocal/calib/held_out_errors.hpp"
#include "robocal/core/random_draws.hpp"

#include <gtest/gtest.h>

#include <random>

namespace {

using robocal::calib::position_error_stats;
using robocal::calib::realised_frame;

TEST(RealisedFrame, FindsTheTurnAndShiftOfTheMeasuredWorld) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> spread(-0.6, 0.6);
  std::normal_distribution<double> noise(0.0, 5e-6);
  // 20 µrad about an oblique axis, 15 µm: what a principal point 0.03 px off does at f = 1600 px.
  Eigen::Isometry3d world = Eigen::Isometry3d::Identity();
  world.linear() =
      Eigen::AngleAxisd(20e-6, Eigen::Vector3d(0.2, 1.0, -0.1).normalized()).toRotationMatrix();
  world.translation() = Eigen::Vector3d(4e-6, 2e-6, -15e-6);
  std::vector<Eigen::Vector3d> truth, measured;
  for (int k = 0; k < 60; ++k) {
    // One draw a statement, z first (robocal/core/random_draws.hpp says why).
    const double z = 1.0 + 0.5 * spread(rng);
    const double y = spread(rng);
    const double x = spread(rng);
    truth.emplace_back(x, y, z);
    measured.push_back(world * truth.back() + robocal::core::draw_vector3(noise, rng));
  }
  const auto found = realised_frame(measured, truth);
  ASSERT_TRUE(found.has_value());
  // 60 positions over 1.2 m with 5 µm noise: the turn to ~2 µrad, the shift to a few µm.
  const double turn_error = Eigen::AngleAxisd(found->linear() * world.linear().transpose()).angle();
  EXPECT_LT(turn_error, 4e-6);
  EXPECT_LT((found->translation() - world.translation()).norm(), 5e-6);
  // In the realised frame the measured positions are off by the noise alone (5 µm x sqrt(3)).
  std::vector<Eigen::Vector3d> carried;
  for (const auto& t : truth) carried.push_back(*found * t);
  EXPECT_LT(position_error_stats(measured, carried).rms, 10e-6);
  EXPECT_GT(position_error_stats(measured, truth).rms, 15e-6);
  // A point 2 m from the measured ones: the realised frame carries it as the world does.
  const Eigen::Vector3d far(2.5, 0.0, 1.0);
  EXPECT_LT((*found * far - world * far).norm(), 12e-6);
  EXPECT_GT((far - world * far).norm(), 40e-6);
}

TEST(RealisedFrame, NeedsPositionsOffOneLine) {
  std::vector<Eigen::Vector3d> line, two;
  for (int k = 0; k < 10; ++k) line.emplace_back(0.1 * k, 0.2 * k, 1.0);
  EXPECT_FALSE(realised_frame(line, line).has_value());
  two = {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1, 0, 1)};
  EXPECT_FALSE(realised_frame(two, two).has_value());
  EXPECT_THROW((void)realised_frame(two, line), std::invalid_argument);
}

}  // namespace
