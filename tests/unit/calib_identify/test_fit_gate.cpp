// The fit gate with the robot's unmodelled error: a real robot's sag, which no kinematic
// parameter follows, must not get its calibration refused; wrong actuator units must be, however
// much unmodelled error the robot file states.
#include "robocal/calib/fit_gate.hpp"
#include "robocal/calib/identification.hpp"

#include "planar_fixture.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <variant>

namespace {

using namespace robocal::calib;
using namespace robocal::calib::testing;

constexpr double kNoise = 2e-6;  // m, the measurements' true and stated noise

// The planar arm measured at 60 poses with kNoise, the tool sagging by `sag_per_m2` times the
// square of its horizontal distance from the base axis (the model's tool height is constant, so
// no parameter can follow it), the second joint's readings scaled by `q2_unit`.
Measurements measured_arm(double sag_per_m2, double q2_unit) {
  PlanarPredictor model;
  SimulationOptions sim;
  sim.position_sigma = kNoise;
  std::mt19937 rng(5);
  const auto actuators = planar_actuators(60, 5);
  Measurements m = simulate_measurements(model, planar_truth(), actuators, sim, rng);
  const Eigen::VectorXd truth = planar_truth();
  for (auto& pose : m.poses) {
    auto& point = std::get<PointObservation>(pose.observations[0]);
    const Eigen::Vector2d reach =
        point.measured.head<2>() - Eigen::Vector2d(truth(kBx), truth(kBy));
    point.measured.z() -= sag_per_m2 * reach.squaredNorm();
    pose.actuators(1) /= q2_unit;  // the controller reports in another unit than the model's
  }
  return m;
}

NoiseGroup point_group(const IdentificationResult& r) {
  for (const NoiseGroup& g : r.noise.groups)
    if (g.type == "point") return g;
  ADD_FAILURE() << "no point group";
  return {};
}

UnmodelledErrorSpec unmodelled(double position) {
  UnmodelledErrorSpec spec;
  spec.position = position;
  return spec;
}

TEST(FitGate, ARobotsSagWithinItsStatedUnmodelledErrorIsNotRefused) {
  PlanarPredictor model;
  // 100 µm/m²: up to 90 µm at full reach, about 20 µm RMS about its mean over the poses.
  const auto result =
      identify(model, planar_nominal(), measured_arm(100e-6, 1.0), planar_geometry_first());
  ASSERT_EQ(result.status, IdentificationStatus::kConverged) << result.message;
  const NoiseGroup g = point_group(result);
  ASSERT_TRUE(g.estimable);
  // The sag is well beyond 5x the noise...
  ASSERT_GT(g.scale_low, 5.0);
  // ...so without an allowance for unmodelled error the gate refuses, naming the group,
  const FitVerdict strict = judge_identification(result, fit_gate_options(unmodelled(0.0), 0.0));
  EXPECT_FALSE(strict.plausible);
  EXPECT_NE(strict.reason.find("point measurements"), std::string::npos) << strict.reason;
  EXPECT_NE(strict.reason.find("unmodelled_error"), std::string::npos) << strict.reason;
  // ...and with the robot file's default (20 µm RMS per axis) it passes: the residuals' sigma is
  // below hypot(5 x 2 µm, 20 µm) = 22.4 µm.
  ASSERT_LT(g.estimated_sigma(), std::hypot(5.0 * kNoise, 20e-6));
  EXPECT_TRUE(judge_identification(result, fit_gate_options(UnmodelledErrorSpec{}, 0.0)).plausible);
}

TEST(FitGate, WrongActuatorUnitsAreRefusedWhateverTheUnmodelledError) {
  PlanarPredictor model;
  // Joint 2 reported 2 % off its scale (a gear ratio or steps/mm entered wrong): up to 18 mm.
  const auto result =
      identify(model, planar_nominal(), measured_arm(0.0, 1.02), planar_geometry_first());
  ASSERT_EQ(result.status, IdentificationStatus::kConverged) << result.message;
  const FitVerdict verdict =
      judge_identification(result, fit_gate_options(UnmodelledErrorSpec{}, 0.0));
  EXPECT_FALSE(verdict.plausible);
  EXPECT_NE(verdict.reason.find("actuator readings' units"), std::string::npos) << verdict.reason;
}

TEST(FitGate, ThePositionAllowanceIsSeenInPixelsAtTheBoardsScale) {
  UnmodelledErrorSpec spec;
  spec.position = 20e-6;
  spec.rotation = 3e-4;
  const FitGateOptions o = fit_gate_options(spec, 930.0);  // 1600 px focal length at 1.72 m
  EXPECT_DOUBLE_EQ(o.model_error_m, 20e-6);
  EXPECT_DOUBLE_EQ(o.model_error_rad, 3e-4);
  EXPECT_NEAR(o.model_error_px, 0.0186, 1e-12);
  EXPECT_EQ(fit_gate_options(spec, 0.0).model_error_px, 0.0);
}

}  // namespace
