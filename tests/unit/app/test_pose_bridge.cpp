#include "stages/pose_bridge.hpp"

#include <gtest/gtest.h>

namespace {

// vision reports [rotation; translation], calib expects [position; rotation]: a target measured
// with 1 µrad rotation noise and 10 µm position noise must be weighted as such by calib, and the
// rotation/position cross term must follow.
TEST(PoseBridge, SwapsRotationAndTranslationBlocks) {
  Eigen::Matrix<double, 6, 6> vision_cov = Eigen::Matrix<double, 6, 6>::Zero();
  vision_cov.block<3, 3>(0, 0) = 1e-12 * Eigen::Matrix3d::Identity();  // rotation (rad^2)
  vision_cov.block<3, 3>(3, 3) = 1e-10 * Eigen::Matrix3d::Identity();  // translation (m^2)
  vision_cov(0, 4) = vision_cov(4, 0) = 3e-12;                         // rot x with trans y
  const auto calib_cov = robocal::core::position_first(vision_cov);
  EXPECT_DOUBLE_EQ(calib_cov(0, 0), 1e-10);  // position first
  EXPECT_DOUBLE_EQ(calib_cov(5, 5), 1e-12);  // rotation last
  EXPECT_DOUBLE_EQ(calib_cov(1, 3), 3e-12);  // trans y with rot x
  EXPECT_DOUBLE_EQ(calib_cov(3, 1), 3e-12);
  EXPECT_DOUBLE_EQ(calib_cov(0, 3), 0.0);
}

TEST(PoseBridge, ObservationWeightsPositionByItsSigma) {
  robocal::vision::PoseMeasurement m;
  m.world_T_target.translation() = Eigen::Vector3d(0.1, 0.2, 1.2);
  m.covariance.setZero();
  m.covariance.block<3, 3>(0, 0) = 1e-8 * Eigen::Matrix3d::Identity();   // 100 µrad
  m.covariance.block<3, 3>(3, 3) = 1e-10 * Eigen::Matrix3d::Identity();  // 10 µm
  const auto obs = robocal::app::to_pose_observation(m);
  // A 10 µm position error is one sigma: whitened residual 1 in the position rows.
  double residual[6];
  const Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  const Eigen::Vector3d p = m.world_T_target.translation() + Eigen::Vector3d(1e-5, 0, 0);
  obs(R, p, residual);
  EXPECT_NEAR(std::abs(residual[0]), 1.0, 1e-9);
  EXPECT_NEAR(residual[3], 0.0, 1e-12);
}

}  // namespace
