// Issue 22: convention mistakes in measurement files are caught before fitting and named —
// quaternion order swapped, readings in degrees, inverted poses — on simulated data from library
// robots (truth perturbed, noise as a camera would give).
#include "robocal/calib/conventions.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"

#include <gtest/gtest.h>

namespace {

using namespace robocal::calib;

struct Case {
  Mechanism model;
  Eigen::VectorXd nominal;
  Measurements meas;
};

Case simulate(const std::string& name, unsigned seed) {
  Case c{load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + name + ".yaml"), {}, {}};
  c.nominal = c.model.nominal_parameters();
  const MechanismPredictor pred(c.model);
  std::mt19937 rng(seed);
  const Eigen::VectorXd truth =
      perturb_parameters(c.nominal, tolerance_sigmas(c.model, 0.5e-3, 0.2 * M_PI / 180.0), rng);
  const auto qs = sample_actuators(pred, {c.nominal, truth}, 40, rng);
  SimulationOptions sim;
  sim.kind = SimulatedObservation::kPose;
  sim.position_sigma = 50e-6;
  sim.rotation_sigma = 2e-4;
  c.meas = simulate_measurements(pred, truth, qs, sim, rng);
  return c;
}

// The rotation a reader makes of w-last numbers [x, y, z, w] taken as [w, x, y, z].
Eigen::Matrix3d read_w_last_as_w_first(const Eigen::Matrix3d& R) {
  const Eigen::Quaterniond q(R);
  return Eigen::Quaterniond(q.x(), q.y(), q.z(), q.w()).normalized().toRotationMatrix();
}

class Conventions : public ::testing::TestWithParam<const char*> {};

TEST_P(Conventions, DeclaredDataPassAndEachSwapIsNamed) {
  Case c = simulate(GetParam(), 7);
  const MechanismPredictor pred(c.model);
  ASSERT_GE(c.meas.poses.size(), 30u);
  EXPECT_FALSE(check_conventions(pred, c.nominal, c.meas).has_value())
      << check_conventions(pred, c.nominal, c.meas)->message;

  Measurements inverted = c.meas;
  for (auto& p : inverted.poses) {
    auto& o = std::get<PoseObservation>(p.observations[0]);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = o.measured_rotation;
    T.translation() = o.measured_position;
    const Eigen::Isometry3d inv = T.inverse();
    o.measured_rotation = inv.linear();
    o.measured_position = inv.translation();
  }
  const auto inv = check_conventions(pred, c.nominal, inverted);
  ASSERT_TRUE(inv.has_value());
  EXPECT_NE(inv->message.find("inverted poses"), std::string::npos) << inv->message;

  // The whole engine refuses (no "converged", no calibrated file).
  const auto res = identify(pred, c.nominal, inverted, solve_options_from_model(c.model, false));
  EXPECT_EQ(res.status, IdentificationStatus::kInvalidInput);
}

TEST_P(Conventions, QuaternionOrderSwapIsNamedWhereTheFrameRotates) {
  Case c = simulate(GetParam(), 8);
  const MechanismPredictor pred(c.model);
  Measurements swapped = c.meas;
  for (auto& p : swapped.poses) {
    auto& o = std::get<PoseObservation>(p.observations[0]);
    o.measured_rotation = read_w_last_as_w_first(o.measured_rotation);
  }
  const auto m = check_conventions(pred, c.nominal, swapped);
  ASSERT_TRUE(m.has_value());
  EXPECT_NE(m->message.find("w last"), std::string::npos) << m->message;
}

TEST_P(Conventions, ReadingsInDegreesAreNamed) {
  Case c = simulate(GetParam(), 9);
  const MechanismPredictor pred(c.model);
  Measurements deg = c.meas;
  for (auto& p : deg.poses) p.actuators *= 180.0 / M_PI;
  const auto m = check_conventions(pred, c.nominal, deg);
  ASSERT_TRUE(m.has_value());
  EXPECT_NE(m->message.find("degrees"), std::string::npos) << m->message;
}

// Robots whose measured frame rotates with revolute actuators (a Delta's plate only translates:
// a swapped quaternion there is a constant rotation the base frame absorbs, harmless).
INSTANTIATE_TEST_SUITE_P(LibraryRobots, Conventions,
                         ::testing::Values("ur5", "modular_arm", "wire_robot_branch"));

}  // namespace
