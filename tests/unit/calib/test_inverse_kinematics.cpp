// Inverse kinematics: FK o IK round trips on every library robot, closed-form seeds, perturbed
// (non-closed-form) models, unreachable targets.
#include "calib_test_support.hpp"
#include "robocal/calib/closed_form.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/kinematics.hpp"

#include <gtest/gtest.h>

namespace robocal::calib {
namespace {

using testing::library;
using testing::load;

TaskTarget target_of(const Mechanism& m, const Eigen::VectorXd& p, const JointState& s) {
  TaskTarget t;
  t.pose = frame_pose(m, p, s, m.task.frame);
  if (m.task.type == TaskType::kJoint) t.joint_value = s.q[m.task.joint];
  return t;
}

double task_error(const Mechanism& m, const TaskTarget& a, const TaskTarget& b) {
  switch (m.task.type) {
    case TaskType::kPosition:
      return (a.pose.translation() - b.pose.translation()).norm();
    case TaskType::kPose:
      return std::max((a.pose.translation() - b.pose.translation()).norm(),
                      rotation_error(a.pose.linear(), b.pose.linear()).norm());
    case TaskType::kJoint:
      return std::abs(a.joint_value - b.joint_value);
  }
  return 1e9;
}

TEST(InverseKinematics, ForwardOfInverseRoundTripsOnEveryLibraryRobot) {
  for (const auto& robot : library()) {
    const Mechanism m = load(robot.file);
    const Eigen::VectorXd p = m.nominal_parameters();
    std::mt19937 rng(21);
    std::normal_distribution<double> noise(0.0, 1.0);
    for (int k = 0; k < 8; ++k) {
      const Eigen::VectorXd q = testing::random_readings(robot, rng);
      const ForwardResult fk = forward_kinematics(m, p, q, m.task.frame);
      ASSERT_TRUE(fk.closure.ok()) << robot.file;
      const TaskTarget target = target_of(m, p, fk.state);
      IkSeed seed;
      // Robots without a closed form start from a nearby configuration (an arm's previous pose);
      // the parallel robots with closed forms start cold.
      if (m.closed_form.kind == ClosedFormKind::kNone && m.task.type != TaskType::kJoint) {
        seed.actuator_q = Eigen::VectorXd(q.size());
        for (Eigen::Index i = 0; i < q.size(); ++i)
          seed.actuator_q[i] =
              fk.state.q[m.actuated[static_cast<std::size_t>(i)]] + 0.1 * noise(rng);
      }
      const IkResult ik = solve_ik(m, p, target, seed);
      // Issue 15: IK answers on the robot file's declared assembly/working mode. A target that
      // only a configuration on another mode reaches (possible when the random readings are on
      // another mode themselves) is refused as such, never answered silently.
      if (ik.status == SolveStatus::kOtherMode) {
        EXPECT_NE(fk.closure.mode.verdict, ModeVerdict::kIntended) << robot.file;
        continue;
      }
      ASSERT_TRUE(ik.ok()) << robot.file << " " << to_string(ik.status) << " " << ik.residual;
      EXPECT_NE(ik.mode.verdict, ModeVerdict::kOther) << robot.file;
      const ForwardResult back =
          forward_kinematics(m, p, ik.actuator_readings, m.task.frame, ik.passive);
      ASSERT_TRUE(back.closure.ok());
      EXPECT_LE(task_error(m, target_of(m, p, back.state), target), 1e-9) << robot.file;
      // Parallel robots with closed forms: the same actuators (intended branch), not another.
      if (m.closed_form.kind != ClosedFormKind::kNone) {
        EXPECT_LE((ik.actuator_readings - q).cwiseAbs().maxCoeff(), 1e-8) << robot.file;
      }
    }
  }
}

TEST(InverseKinematics, DeltaClosedFormInverseMatchesGenericSolver) {
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  for (const Eigen::Vector3d& T : {Eigen::Vector3d(0, 0, -0.9), Eigen::Vector3d(0.2, -0.1, -1.0),
                                   Eigen::Vector3d(-0.15, 0.2, -1.1)}) {
    const auto cf = delta_inverse(m.closed_form, T);
    ASSERT_TRUE(cf);
    TaskTarget target;
    target.pose.translation() = T;
    const IkResult ik = solve_ik(m, p, target);
    ASSERT_TRUE(ik.ok());
    EXPECT_LE((ik.actuator_q - *cf).cwiseAbs().maxCoeff(), 1e-9);
    const auto back = delta_forward(m.closed_form, *cf);
    ASSERT_TRUE(back);
    EXPECT_LE((*back - T).norm(), 1e-12);
  }
}

TEST(InverseKinematics, PerturbedDeltaWarmStartedAlongPath) {
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd p = testing::perturbed_parameters(m, 5e-4, 2);
  TaskTarget target;
  target.pose.translation() = Eigen::Vector3d(0.0, 0.0, -0.9);
  IkResult prev = solve_ik(m, p, target);
  ASSERT_TRUE(prev.ok());
  for (int k = 0; k < 50; ++k) {
    target.pose.translation() += Eigen::Vector3d(0.001, 0.0005, -0.0008);
    const IkResult ik = solve_ik(m, p, target, {prev.actuator_q, prev.passive});
    ASSERT_TRUE(ik.ok());
    const ForwardResult fk = forward_kinematics(m, p, ik.actuator_readings, m.tool, ik.passive);
    EXPECT_LE((fk.pose.translation() - target.pose.translation()).norm(), 1e-9);
    prev = ik;
  }
}

TEST(InverseKinematics, UnreachableTargetReportsNoSolutionWithResidual) {
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  TaskTarget target;
  target.pose.translation() = Eigen::Vector3d(0, 0, -3.0);  // far beyond arm + rod
  const IkResult ik = solve_ik(m, p, target);
  EXPECT_FALSE(ik.ok());
  EXPECT_GT(ik.residual, 0.1);

  const Mechanism arm = load("modular_arm.yaml");
  TaskTarget far;
  far.pose.translation() = Eigen::Vector3d(3.0, 0, 0.5);
  const IkResult r2 = solve_ik(arm, arm.nominal_parameters(), far);
  EXPECT_FALSE(r2.ok());
  EXPECT_GT(r2.residual, 1.0);
}

}  // namespace
}  // namespace robocal::calib
