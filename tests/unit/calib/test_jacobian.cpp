// Parameter and actuator Jacobians through the closures vs central differences of re-solved
// forward kinematics, on every library robot.
#include "calib_test_support.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"

#include <gtest/gtest.h>

namespace robocal::calib {
namespace {

using testing::library;
using testing::load;

struct Fk {
  Eigen::Vector3d p;
  Eigen::Matrix3d R;
};

Fk solve_pose(const Mechanism& m, const Eigen::VectorXd& params, const Eigen::VectorXd& readings,
              const Eigen::VectorXd& seed, int frame) {
  ClosureOptions o;
  o.tolerance = 1e-15;
  o.max_iterations = 30;
  const ClosureResult r = solve_closure(m, params, readings, seed, o);
  EXPECT_LE(r.residual, 1e-13);
  const JointState s = make_joint_state(m, params, readings, r.passive);
  const Eigen::Isometry3d T = frame_pose(m, params, s, frame);
  return {T.translation(), T.linear()};
}

// Central difference of the pose in the documented convention (position; world rotation vector).
Eigen::Matrix<double, 6, 1> central(const Fk& plus, const Fk& minus, double h) {
  Eigen::Matrix<double, 6, 1> d;
  d.head<3>() = (plus.p - minus.p) / (2 * h);
  d.tail<3>() = rotation_log(plus.R * minus.R.transpose()) / (2 * h);
  return d;
}

void expect_close(const Eigen::Matrix<double, 6, 1>& analytic,
                  const Eigen::Matrix<double, 6, 1>& numeric, const std::string& what) {
  const double scale = std::max(numeric.norm(), 1e-3);
  EXPECT_LE((analytic - numeric).norm() / scale, 1e-6)
      << what << "\nanalytic " << analytic.transpose() << "\nnumeric  " << numeric.transpose();
}

TEST(Jacobian, ParameterJacobianMatchesCentralDifferencesOnEveryLibraryRobot) {
  for (const auto& robot : library()) {
    const Mechanism m = load(robot.file);
    const Eigen::VectorXd p = m.nominal_parameters();
    std::mt19937 rng(5);
    for (int pose = 0; pose < 2; ++pose) {
      const Eigen::VectorXd q = testing::random_readings(robot, rng);
      const ClosureResult r = solve_closure(m, p, q);
      ASSERT_TRUE(r.ok()) << robot.file;
      const JointState s = make_joint_state(m, p, q, r.passive);
      for (int frame : {m.tool, static_cast<int>(m.bodies.size()) / 2}) {
        const FrameJacobians J = frame_jacobians(m, p, s, q, frame);
        ASSERT_EQ(J.parameters.cols(), static_cast<Eigen::Index>(m.parameters.size()));
        ASSERT_EQ(J.actuators.cols(), static_cast<Eigen::Index>(m.actuated.size()));
        int nonzero = 0;
        for (Eigen::Index k = 0; k < p.size(); ++k) {
          const Parameter& prm = m.parameters[static_cast<std::size_t>(k)];
          double h = 1e-5;
          if (prm.group == ParamGroup::kEncoderScale)
            h /= std::max(1.0, std::abs(q[m.bodies[static_cast<std::size_t>(prm.body)].actuator]));
          Eigen::VectorXd pp = p, pm = p;
          pp[k] += h;
          pm[k] -= h;
          const auto num = central(solve_pose(m, pp, q, r.passive, frame),
                                   solve_pose(m, pm, q, r.passive, frame), h);
          expect_close(J.parameters.col(k), num, robot.file + " " + prm.name);
          if (num.norm() > 1e-6) ++nonzero;
        }
        EXPECT_GT(nonzero, 0) << robot.file;
        for (Eigen::Index i = 0; i < q.size(); ++i) {
          const double h = 1e-5 * std::max(1.0, std::abs(q[i]));
          Eigen::VectorXd qp = q, qm = q;
          qp[i] += h;
          qm[i] -= h;
          const auto num = central(solve_pose(m, p, qp, r.passive, frame),
                                   solve_pose(m, p, qm, r.passive, frame), h);
          expect_close(J.actuators.col(i), num, robot.file + " actuator " + std::to_string(i));
        }
      }
    }
  }
}

TEST(Jacobian, DeltaToolPositionIgnoresNothingItShouldNot) {
  // Rod lengths must move the tool through the closure (they appear in no open chain to it
  // except rod 7), and shoulder radii too: the implicit-function term is really exercised.
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  const Eigen::Vector3d q(0.2, 0.4, 0.1);
  const ClosureResult r = solve_closure(m, p, q);
  ASSERT_TRUE(r.ok());
  const auto J = parameter_jacobian(m, p, make_joint_state(m, p, q, r.passive), q, m.tool);
  for (const char* name : {"body20.d1", "body26.d1", "body3.d1", "body24.d1"})
    EXPECT_GT(J.col(m.parameter_index(name)).head<3>().norm(), 0.1) << name;
}

}  // namespace
}  // namespace robocal::calib
