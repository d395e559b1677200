// The true-pose channel's replies as sim-controller writes them (robotio/README.md).
#include "robocal/robotio/sim_truth.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>

namespace robocal::robotio {
namespace {

TEST(TruePoseReply, ParsesPositionRotationAndMotionState) {
  // 90 degrees about z: w = cos 45, z = sin 45.
  const double h = std::sqrt(0.5);
  const std::string line = R"({"t":12.5,"moving":false,"motion":17,"frame":"tool",)"
                           R"("position":[0.01,-0.02,0.09],"quaternion_wxyz":[)" +
                           std::to_string(h) + ",0,0," + std::to_string(h) +
                           R"(],"actuators_true":[0.2,0.21,0.22]})";
  const TruePoseReading r = parse_true_pose_reply(line, "channel");
  EXPECT_EQ(r.t, 12.5);
  EXPECT_FALSE(r.moving);
  EXPECT_EQ(r.motion, 17);
  EXPECT_EQ(r.frame, "tool");
  EXPECT_LT((r.base_T_task.translation() - Eigen::Vector3d(0.01, -0.02, 0.09)).norm(), 1e-15);
  // The task frame's x axis points along the base's y axis.
  EXPECT_LT((r.base_T_task.linear() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(),
            1e-6);
  ASSERT_EQ(r.actuators_true.size(), 3U);
  EXPECT_EQ(r.actuators_true[2], 0.22);
}

std::string error_of(const std::string& line) {
  try {
    (void)parse_true_pose_reply(line, "true-pose channel tcp 127.0.0.1:4000");
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

TEST(TruePoseReply, BadRepliesAreErrorsNamingTheChannelAndQuotingTheLine) {
  const std::string garbage = error_of("ok");
  EXPECT_NE(garbage.find("tcp 127.0.0.1:4000"), std::string::npos) << garbage;
  EXPECT_NE(garbage.find("'ok'"), std::string::npos) << garbage;
  const std::string cannot_assemble =
      error_of(R"({"t":1,"moving":false,"motion":2,"error":"closure: no solution"})");
  EXPECT_NE(cannot_assemble.find("closure: no solution"), std::string::npos) << cannot_assemble;
  const std::string missing = error_of(R"({"t":1,"moving":false,"motion":2})");
  EXPECT_NE(missing.find("missing or mistyped"), std::string::npos) << missing;
  const std::string not_unit = error_of(
      R"({"t":1,"moving":false,"motion":2,"position":[0,0,0],"quaternion_wxyz":[2,0,0,0]})");
  EXPECT_NE(not_unit.find("unit length"), std::string::npos) << not_unit;
}

}  // namespace
}  // namespace robocal::robotio
