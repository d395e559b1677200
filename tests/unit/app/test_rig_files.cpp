#include "session/results_files.hpp"

#include "robocal/vision/pose.hpp"

#include <gtest/gtest.h>

namespace {

using robocal::app::pose_measurement_to_json;
using robocal::vision::PoseMeasurement;
using robocal::vision::PoseStatus;

PoseMeasurement sample_measurement() {
  PoseMeasurement m;
  m.status = PoseStatus::kOk;
  m.world_T_target = robocal::vision::pose_from_rvec_tvec(Eigen::Vector3d(0.1, -0.2, 3.0),
                                                          Eigen::Vector3d(0.3, -0.1, 1.7));
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) m.covariance(r, c) = (r == c ? 1e-9 : 1e-12 * (r + 2 * c));
  m.chi2 = 12.5;
  m.dof = 10;
  m.rms_px = 0.03;
  m.corners = 8;
  m.ambiguous = true;
  m.motion_chi2 = 2.5;
  return m;
}

// What identify reads back (rig_T_target_matrix, covariance) must be the measurement bit for bit.
TEST(PoseMeasurementJson, FullPrecisionPoseAndCovariance) {
  const PoseMeasurement m = sample_measurement();
  const nlohmann::json j = nlohmann::json::parse(pose_measurement_to_json(m).dump());
  const auto rows = j.at("rig_T_target_matrix").get<std::vector<std::vector<double>>>();
  ASSERT_EQ(rows.size(), 3u);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) EXPECT_EQ(rows[r][c], m.world_T_target.matrix()(r, c));
  const auto cov = j.at("covariance").get<std::vector<std::vector<double>>>();
  ASSERT_EQ(cov.size(), 6u);
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) EXPECT_EQ(cov[r][c], m.covariance(r, c));
  const auto tvec = j.at("rig_T_target").at("tvec").get<std::vector<double>>();
  EXPECT_DOUBLE_EQ(tvec[2], 1.7);
  EXPECT_TRUE(j.at("flags").at("ambiguous").get<bool>());
  EXPECT_FALSE(j.at("flags").at("moving").get<bool>());
  EXPECT_EQ(j.at("dof").get<int>(), 10);
  EXPECT_EQ(j.at("corners").get<int>(), 8);
  EXPECT_DOUBLE_EQ(j.at("chi2").get<double>(), 12.5);
  EXPECT_DOUBLE_EQ(j.at("motion_chi2").get<double>(), 2.5);
}

// A pose that was not measured has no pose to write (the caller writes status and message).
TEST(PoseMeasurementJson, NothingWithoutAPose) {
  PoseMeasurement m = sample_measurement();
  m.status = PoseStatus::kNotSeen;
  EXPECT_TRUE(pose_measurement_to_json(m).empty());
  m.status = PoseStatus::kMoving;  // a pose exists, flagged moving
  EXPECT_TRUE(pose_measurement_to_json(m).contains("rig_T_target"));
}

}  // namespace
