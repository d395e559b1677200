// The safety guard on its own (pure): every refusal reason, on the linear delta.
#include "robocal/calib/closure.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robotio_sim.hpp"

#include <gtest/gtest.h>

namespace robocal::test {
namespace {

using robotio::MoveSpeed;
using robotio::SafetyGuard;

class GuardTest : public ::testing::Test {
 protected:
  calib::Mechanism model = linear_delta();
  SafetyGuard guard{model, model.nominal_parameters(), delta_limits()};
  std::vector<Eigen::VectorXd> targets = delta_targets(model, 2, 1);
  static constexpr MoveSpeed kOk{0.1, 2.0};
};

TEST_F(GuardTest, NotArmedRefusesButDryRunNeedsNoConfirmation) {
  auto v = guard.check_move(targets[0], targets[1], kOk);
  EXPECT_FALSE(v.allowed);
  EXPECT_NE(v.reason.find("not armed"), std::string::npos);
  guard.set_dry_run(true);
  EXPECT_TRUE(guard.check_move(targets[0], targets[1], kOk).allowed);
  guard.set_dry_run(false);
  guard.arm("yes");
  v = guard.check_move(targets[0], targets[1], kOk);
  EXPECT_TRUE(v.allowed) << v.reason;
  // The checked path starts and ends where asked, and every sample is solved.
  ASSERT_GE(v.path.size(), 2u);
  EXPECT_TRUE(v.path.front().readings.isApprox(targets[0]));
  EXPECT_TRUE(v.path.back().readings.isApprox(targets[1]));
}

TEST_F(GuardTest, SpeedAndAccelerationLimits) {
  guard.arm("yes");
  EXPECT_FALSE(guard.check_move(targets[0], targets[1], {0.26, 2.0}).allowed);
  EXPECT_FALSE(guard.check_move(targets[0], targets[1], {0.1, 5.1}).allowed);
  EXPECT_FALSE(guard.check_move(targets[0], targets[1], {0.0, 2.0}).allowed);
  EXPECT_TRUE(guard.check_move(targets[0], targets[1], {0.25, 5.0}).allowed);
}

TEST_F(GuardTest, ActuatorLimitsFromTheRobotFile) {
  robotio::SafetyLimits l = delta_limits();
  l.workspace_min = Eigen::Vector3d::Constant(-1.0);  // only the actuator limits can refuse
  l.workspace_max = Eigen::Vector3d::Constant(1.0);
  SafetyGuard open_box(model, model.nominal_parameters(), l);
  open_box.arm("yes");
  Eigen::VectorXd high = targets[0];
  high[1] = 0.46;  // carriage b above its 0.45 m travel
  const auto v = open_box.check_move(targets[0], high, kOk);
  EXPECT_FALSE(v.allowed);
  EXPECT_NE(v.reason.find("carriage_b"), std::string::npos) << v.reason;
}

TEST_F(GuardTest, WorkspaceIsCheckedAlongThePathNotOnlyAtTheEnds) {
  guard.arm("yes");
  // Both ends inside the box, the straight carriage path between them leaves it: narrow the
  // box's z range to the ends' z and move between two points where the effector dips.
  const Eigen::VectorXd params = model.nominal_parameters();
  auto tool_z = [&](const Eigen::VectorXd& r) -> Eigen::Vector3d {
    const calib::ForwardResult fk = calib::forward_kinematics(model, params, r, model.tool);
    return fk.pose.translation();
  };
  calib::TaskTarget a, b;
  a.pose.translation() = Eigen::Vector3d(-0.05, 0.0, 0.08);
  b.pose.translation() = Eigen::Vector3d(0.05, 0.0, 0.08);
  const Eigen::VectorXd ra = calib::solve_ik(model, params, a).actuator_readings;
  const Eigen::VectorXd rb = calib::solve_ik(model, params, b).actuator_readings;
  const Eigen::Vector3d mid = tool_z(0.5 * (ra + rb));
  ASSERT_LT(mid.z(), 0.08 - 1e-4) << "the linear-delta path is not straight in task space";
  robotio::SafetyLimits l = delta_limits();
  l.workspace_min.z() = 0.08 - 1e-5;
  SafetyGuard narrow(model, params, l);
  narrow.arm("yes");
  const auto v = narrow.check_move(ra, rb, kOk);
  EXPECT_FALSE(v.allowed);
  EXPECT_NE(v.reason.find("outside the declared workspace"), std::string::npos) << v.reason;
}

TEST_F(GuardTest, InjectedClearanceCheckSeesEverySample) {
  guard.arm("yes");
  int calls = 0;
  guard.set_clearance_check([&](const robotio::PathSample& s) -> std::optional<std::string> {
    ++calls;
    EXPECT_EQ(s.state.q.size(), static_cast<Eigen::Index>(model.bodies.size()));
    if (s.fraction > 0.4 && s.fraction < 0.6) return "obstacle at mid-path";
    return std::nullopt;
  });
  const auto v = guard.check_move(targets[0], targets[1], kOk);
  EXPECT_FALSE(v.allowed);
  EXPECT_NE(v.reason.find("obstacle at mid-path"), std::string::npos);
  EXPECT_GE(calls, 3);
}

TEST_F(GuardTest, StopRequestsHoldUntilResumedAndReconfirmed) {
  guard.arm("yes");
  guard.camera_lost("cam0");
  auto v = guard.check_move(targets[0], targets[1], kOk);
  EXPECT_FALSE(v.allowed);
  EXPECT_NE(v.reason.find("camera cam0 lost"), std::string::npos) << v.reason;
  guard.resume();
  EXPECT_FALSE(guard.check_move(targets[0], targets[1], kOk).allowed) << "resume must disarm";
  guard.arm("operator confirmed again");
  EXPECT_TRUE(guard.check_move(targets[0], targets[1], kOk).allowed);
  guard.request_stop_from_signal();
  EXPECT_NE(guard.check_move(targets[0], targets[1], kOk).reason.find("Ctrl-C"), std::string::npos);
}

// A path through a configuration where the rotary Delta's assembly modes meet (the closure calls
// it ambiguous) is refused before anything moves: the true robot could leave there on another
// mode than the model's answer. The ambiguous reading is found here by scanning the closure along
// one arm, independently of the guard; the path that stops short of it is allowed.
TEST(GuardModes, APathThroughASingularConfigurationIsRefused) {
  const calib::Mechanism m =
      calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  robotio::SafetyLimits l;
  l.max_speed = 10.0;
  l.max_acceleration = 100.0;
  SafetyGuard guard(m, p, l);
  guard.arm("yes");
  const Eigen::VectorXd start = Eigen::VectorXd::Zero(3);
  ASSERT_EQ(calib::solve_closure(m, p, start).mode.verdict, calib::ModeVerdict::kIntended);
  Eigen::VectorXd last_clear = start;
  Eigen::VectorXd singular;
  for (double a = 0.0; a <= guard.limits().actuator_upper[0]; a += 1e-3) {
    Eigen::VectorXd q = start;
    q[0] = a;
    const calib::ClosureResult r = calib::solve_closure(m, p, q);
    if (r.ok() && r.mode.verdict == calib::ModeVerdict::kAmbiguous) {
      singular = q;
      break;
    }
    if (r.ok() && r.mode.verdict == calib::ModeVerdict::kIntended) last_clear = q;
  }
  ASSERT_EQ(singular.size(), 3) << "no ambiguous configuration along the first arm";
  const MoveSpeed speed{1.0, 10.0};
  const auto through = guard.check_move(start, singular + 0.01 * (singular - start), speed);
  EXPECT_FALSE(through.allowed);
  EXPECT_NE(through.reason.find("singular configuration"), std::string::npos) << through.reason;
  Eigen::VectorXd short_of = start + 0.5 * (last_clear - start);
  const auto before = guard.check_move(start, short_of, speed);
  EXPECT_TRUE(before.allowed) << before.reason;
}

// Readings in encoder counts (the wire robot's branch: 268,000 per turn of j1) are sampled by
// joint travel, not by count: a half-radian move of j1 is 500 samples of 1 mrad, where one sample
// per count would be 21,000 closure solves and as many stored joint states.
TEST(GuardUnits, EncoderCountReadingsAreSampledByJointTravel) {
  const calib::Mechanism m =
      calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/wire_robot_branch.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  const Eigen::VectorXd home = m.home_actuated();
  Eigen::VectorXd turned = home;
  turned[0] += 0.5;  // rad
  const Eigen::VectorXd from = calib::readings_from_joint_values(m, p, home);
  const Eigen::VectorXd to = calib::readings_from_joint_values(m, p, turned);
  ASSERT_GT(std::abs(to[0] - from[0]), 2e4) << "j1 is not read in encoder counts";
  robotio::SafetyLimits l;
  l.max_speed = 1e5;
  l.max_acceleration = 1e6;
  SafetyGuard guard(m, p, l);
  guard.set_dry_run(true);
  const auto v = guard.check_move(from, to, {1e4, 1e5});
  ASSERT_TRUE(v.allowed) << v.reason;
  EXPECT_EQ(v.samples, 501);
  ASSERT_EQ(v.path.size(), 2u) << "only the ends are kept";
  EXPECT_TRUE(v.path.front().readings.isApprox(from));
  EXPECT_TRUE(v.path.back().readings.isApprox(to));
}

}  // namespace
}  // namespace robocal::test
