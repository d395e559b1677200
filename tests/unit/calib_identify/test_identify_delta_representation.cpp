// A truth that differs from nominal in parameters the nominal base set holds fixed must still be
// represented by the base set. On the rotary Delta the elbow offsets of the chain that carries the
// plate (body6.d1, body6.d2) move the measurements, at the nominal model, exactly like offsets
// inside the plate ball joint (body8.d1, ...), which is modelled as three revolutes. Only to
// first order, though: an offset inside that 3R gimbal makes the ball joint non-spherical, and
// near the gimbal's lock (inside the working volume) such a stand-in is millimetres off. The base
// set must keep the upstream parameter (solve_options_from_model), so this truth is recovered.
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"

#include <gtest/gtest.h>

#include <string>

namespace {

using namespace robocal::calib;

Eigen::Index parameter_index(const Mechanism& model, const std::string& name) {
  for (std::size_t i = 0; i < model.parameters.size(); ++i)
    if (model.parameters[i].name == name) return static_cast<Eigen::Index>(i);
  ADD_FAILURE() << "no parameter " << name;
  return 0;
}

TEST(DeltaRepresentation, PlateChainElbowOffsetsAreRecoveredNoiseFree) {
  const Mechanism model =
      load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
  const MechanismPredictor pred(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  Eigen::VectorXd truth = nominal;
  truth(parameter_index(model, "body6.d1")) += 0.4e-3;
  truth(parameter_index(model, "body6.d2")) -= 0.6e-3;

  std::mt19937 rng(7);
  const auto design = sample_actuators(pred, {nominal, truth}, 40, rng);
  const auto held = sample_actuators(pred, {nominal, truth}, 150, rng);
  ASSERT_EQ(design.size(), 40u);
  ASSERT_EQ(held.size(), 150u);
  SimulationOptions sim;
  sim.add_noise = false;
  const auto meas = simulate_measurements(pred, truth, design, sim, rng);
  const auto res = identify(pred, nominal, meas, solve_options_from_model(model, false));
  ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;

  const auto check = simulate_measurements(pred, truth, held, sim, rng);
  ASSERT_EQ(check.poses.size(), held.size());
  const ErrorStatistics after = prediction_errors(pred, res.estimate, check.poses);
  EXPECT_EQ(after.poses, held.size());  // every held-out pose assembles with the estimate
  EXPECT_LT(after.position_max, 1e-6);
  EXPECT_GT(prediction_errors(pred, nominal, check.poses).position_max, 1e-4);  // really off
}

}  // namespace
