// The robot file's working volume (`workspace: {min_task_conditioning: X}`) bounds where
// calibration poses are sampled: task_conditioning (σ_min/σ_max of d(task position)/d(actuated
// joints)) is checked against the Delta's independent closed form, and sample_actuators keeps
// every pose inside the bound only when asked to.
#include "robocal/calib/closed_form.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"

#include <gtest/gtest.h>
#include <Eigen/SVD>

#include <algorithm>
#include <string>

namespace {

using namespace robocal::calib;

Mechanism delta() {
  return load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
}

TEST(WorkspaceSampling, TaskConditioningMatchesTheClosedForm) {
  const Mechanism model = delta();
  const MechanismPredictor pred(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  for (const Eigen::Vector3d& q : {Eigen::Vector3d(0.1, 0.2, 0.3), Eigen::Vector3d(-0.5, 0.9, 0.2),
                                   Eigen::Vector3d(1.2, 0.6, 0.9)}) {
    // Central differences of the closed-form forward kinematics (independent of the closure).
    Eigen::Matrix3d J;
    const double h = 1e-6;
    for (int i = 0; i < 3; ++i) {
      Eigen::Vector3d qp = q;
      Eigen::Vector3d qm = q;
      qp(i) += h;
      qm(i) -= h;
      const auto xp = closed_form_forward(model.closed_form, qp);
      const auto xm = closed_form_forward(model.closed_form, qm);
      ASSERT_TRUE(xp && xm);
      J.col(i) = (*xp - *xm) / (2.0 * h);
    }
    const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(J).singularValues();
    const double expected = sv(2) / sv(0);
    const double got =
        task_conditioning(pred, nominal, readings_from_joint_values(model, nominal, q));
    EXPECT_NEAR(got, expected, 1e-6 * std::max(1.0, expected)) << q.transpose();
  }
}

TEST(WorkspaceSampling, PosesStayInsideTheDeclaredWorkingVolume) {
  Mechanism model = delta();
  model.workspace.min_task_conditioning = 0.3;  // as `workspace: {min_task_conditioning: 0.3}`
  const MechanismPredictor pred(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  std::mt19937 rng(11);
  const auto inside = sample_actuators(pred, {nominal}, 40, rng);
  ASSERT_EQ(inside.size(), 40u);
  for (const auto& r : inside)
    EXPECT_GE(task_conditioning(pred, nominal, r), model.workspace.min_task_conditioning);
  // Without the bound the reachable set includes worse-conditioned poses.
  const auto all = sample_actuators(pred, {nominal}, 40, rng, 0.01, false);
  ASSERT_EQ(all.size(), 40u);
  double worst = 1.0;
  for (const auto& r : all) worst = std::min(worst, task_conditioning(pred, nominal, r));
  EXPECT_LT(worst, model.workspace.min_task_conditioning);
}

}  // namespace
