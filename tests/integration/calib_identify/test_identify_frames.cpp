// Issue 22: frames as users have them. A quaternion tool frame gives the same kinematics as its
// roll/pitch/yaw twin; `kin check` warns at gimbal lock; identification of a tool frame at the
// lock (given as a quaternion: local increments) converges to the truth as it does away from it.
#include "cli/command_registry.hpp"
#include "robocal/calib/frame_checks.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "run_robocal.hpp"

#include <fmt/core.h>
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

namespace {

using namespace robocal::calib;

std::string ur5_with_tool(const std::string& tool_line) {
  std::ifstream in(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/ur5.yaml");
  std::stringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  const std::string old = "  - {name: tool, parent: wrist3, convention: xyz_rpy, joint: fixed}";
  const auto pos = text.find(old);
  EXPECT_NE(pos, std::string::npos);
  text.replace(pos, old.size(), tool_line);
  return text;
}

// Tool rotation Rx(0.3) Ry(pi/2) Rz(-0.2): exactly at gimbal lock in the xyz order.
const Eigen::Matrix3d kLocked = (Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()) *
                                 Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()) *
                                 Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitZ()))
                                    .toRotationMatrix();

std::string quaternion_tool(const Eigen::Matrix3d& R, bool w_last = false) {
  const Eigen::Quaterniond q(R);
  const std::string nums =
      w_last ? fmt::format("{:.17g}, {:.17g}, {:.17g}, {:.17g}", q.x(), q.y(), q.z(), q.w())
             : fmt::format("{:.17g}, {:.17g}, {:.17g}, {:.17g}", q.w(), q.x(), q.y(), q.z());
  return fmt::format(
      "  - {{name: tool, parent: wrist3, convention: xyz_rpy, joint: fixed, params: {{x: 0.01, z: "
      "0.05}}, orientation: {{{}: [{}]}}}}",
      w_last ? "quaternion_xyzw" : "quaternion", nums);
}

TEST(RobotFileFrames, QuaternionToolFrameGivesTheSameKinematicsAsItsRpyTwin) {
  const Mechanism rpy =
      parse_robot_yaml(ur5_with_tool("  - {name: tool, parent: wrist3, convention: xyz_rpy, "
                                     "rotation_order: xyz, joint: fixed, params: "
                                     "{x: 0.01, z: 0.05, roll: 0.3, pitch: pi/2, yaw: -0.2}}"),
                       "ur5_rpy.yaml");
  for (bool w_last : {false, true}) {
    const Mechanism quat =
        parse_robot_yaml(ur5_with_tool(quaternion_tool(kLocked, w_last)), "ur5_q.yaml");
    const MechanismPredictor a(rpy);
    const MechanismPredictor b(quat);
    std::mt19937 rng(1);
    for (const auto& q : sample_actuators(a, {rpy.nominal_parameters()}, 20, rng)) {
      FramePrediction pa;
      FramePrediction pb;
      std::string why;
      ASSERT_TRUE(a.predict(rpy.nominal_parameters(), q, -1, false, pa, why));
      ASSERT_TRUE(b.predict(quat.nominal_parameters(), q, -1, false, pb, why));
      EXPECT_LT((pa.pose.matrix() - pb.pose.matrix()).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
}

TEST(RobotFileFrames, BadOrientationIsRefusedWithLine) {
  try {
    parse_robot_yaml(ur5_with_tool("  - {name: tool, parent: wrist3, convention: xyz_rpy, joint: "
                                   "fixed, orientation: {quaternion: [1, 0, 0.5, 0]}}"),
                     "bad.yaml");
    FAIL() << "accepted a non-unit quaternion";
  } catch (const RobotFileError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.yaml:"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("unit norm"), std::string::npos) << e.what();
  }
}

TEST(RobotFileFrames, GimbalLockedRpyFrameIsWarnedByKinCheck) {
  const auto dir =
      std::filesystem::temp_directory_path() / ("robocal_frames_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "locked.yaml").string();
  std::ofstream(path) << ur5_with_tool(
      "  - {name: tool, parent: wrist3, convention: xyz_rpy, joint: fixed, params: {pitch: pi/2}}");
  EXPECT_EQ(gimbal_lock_warnings(load_robot_file(path)).size(), 1u);
  testing::internal::CaptureStderr();
  EXPECT_EQ(
      robocal::test::run_robocal({"kin", "check", path, "--output", (dir / "c.json").string()}), 0);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("gimbal lock"), std::string::npos) << err;
  EXPECT_NE(err.find("'tool'"), std::string::npos) << err;
  // Away from the lock, and the library robots: no warning.
  EXPECT_TRUE(
      gimbal_lock_warnings(load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/ur5.yaml"))
          .empty());
  std::filesystem::remove_all(dir);
}

// Noise-free 6-D poses, tool frame perturbed: the quaternion form at the lock recovers the truth
// to the same precision as a tool frame away from the lock.
double heldout_after_identification(const Mechanism& model) {
  const MechanismPredictor pred(model);
  std::mt19937 rng(3);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  Eigen::VectorXd truth = nominal;
  for (const char* n : {"tool.roll", "tool.pitch", "tool.yaw"})
    truth(model.parameter_index(n)) += 0.01;
  truth(model.parameter_index("tool.x")) += 1e-3;
  const auto qs = sample_actuators(pred, {nominal, truth}, 30, rng);
  SimulationOptions sim;
  sim.kind = SimulatedObservation::kPose;
  sim.add_noise = false;
  const auto meas = simulate_measurements(pred, truth, qs, sim, rng);
  auto opt = solve_options_from_model(model, false);
  const auto res = identify(pred, nominal, meas, opt);
  EXPECT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
  const auto held =
      simulate_measurements(pred, truth, sample_actuators(pred, {truth}, 30, rng), sim, rng);
  const auto e = prediction_errors(pred, res.estimate, held.poses);
  return std::max(e.position_max, e.orientation_max);
}

TEST(RobotFileFrames, IdentificationAtTheLockConvergesLikeAwayFromIt) {
  const double at_lock = heldout_after_identification(
      parse_robot_yaml(ur5_with_tool(quaternion_tool(kLocked)), "ur5_lock.yaml"));
  const double away = heldout_after_identification(
      parse_robot_yaml(ur5_with_tool("  - {name: tool, parent: wrist3, convention: xyz_rpy, "
                                     "rotation_order: xyz, joint: fixed, params: "
                                     "{x: 0.01, z: 0.05, roll: 0.3, pitch: 0.4, yaw: -0.2}}"),
                       "ur5_away.yaml"));
  EXPECT_LT(at_lock, 1e-9);
  EXPECT_LT(away, 1e-9);
}

}  // namespace
