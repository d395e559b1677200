// Identification on the robot library's models (closure solver + implicit-function Jacobian):
// identifiability findings, recovery per observation model, and bad input on a real model.
#include "robocal/calib/closed_form.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

namespace {

using namespace robocal::calib;

Mechanism robot(const std::string& name) {
  return load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + name + ".yaml");
}

const Redundancy* redundancy_of(const IdentificationResult& r, const std::string& name) {
  for (const auto& red : r.identifiability.redundancies)
    if (r.identifiability.names[red.parameter] == name) return &red;
  return nullptr;
}

bool listed(const IdentificationResult& r, const std::vector<std::size_t>& idx,
            const std::string& name) {
  return std::any_of(idx.begin(), idx.end(),
                     [&](std::size_t i) { return r.identifiability.names[i] == name; });
}

struct DeltaFixture : ::testing::Test {
  Mechanism model = robot("rotary_delta");
  MechanismPredictor pred{model};
  Eigen::VectorXd nominal = model.nominal_parameters();
  std::mt19937 rng{42};
};

// Constant platform orientation: the tool offset moves the measured point exactly like the
// base-frame translation; the report names the pair with coefficient ±1 and keeps the base.
TEST_F(DeltaFixture, ToolOffsetIsConfoundedWithBaseTranslation) {
  const auto qs = sample_actuators(pred, {nominal}, 40, rng);
  ASSERT_EQ(qs.size(), 40u);
  SimulationOptions sim;
  sim.add_noise = false;
  const auto meas = simulate_measurements(pred, nominal, qs, sim, rng);
  const auto res = identify(pred, nominal, meas, solve_options_from_model(model, false));
  ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
  for (const std::string tool : {"body30.d1", "body30.d2", "body30.d3"}) {
    const Redundancy* red = redundancy_of(res, tool);
    ASSERT_NE(red, nullptr) << tool;
    ASSERT_EQ(red->partners.size(), 1u) << red->explanation;
    const std::string partner = res.identifiability.names[red->partners[0]];
    EXPECT_EQ(partner.rfind("body1.d", 0), 0u) << red->explanation;
    EXPECT_NEAR(std::abs(red->coefficients[0]), 1.0, 1e-6) << red->explanation;
    EXPECT_NE(red->explanation.find("only their combination is identified"), std::string::npos);
  }
  // Closure frames beyond the rod lengths: the rods' end-frame orientation and lateral offsets
  // have no effect (ball joint at the plate); the rod lengths themselves are identified.
  for (const std::string rod : {"body17", "body20", "body23", "body26", "body29"}) {
    EXPECT_TRUE(listed(res, res.identifiability.identifiable, rod + ".d1")) << rod;
    for (const std::string key : {".a1", ".a2", ".a3", ".d2"})
      EXPECT_TRUE(listed(res, res.identifiability.no_effect, rod + key)) << rod + key;
  }
}

// Full-pose observations of a representable truth are recovered exactly, with 3-D points too.
// Representable by each route's own base set: points and full poses choose their gauge among
// confounded parameters each for itself, and a truth perturbed in a parameter the other route
// holds is only first-order representable (identification.hpp: redundancies are local). Which
// one each route holds can change with the last bits of the rank test (this test failed on one
// machine with the points' base set used for the poses: 3.3e-7 m, a minimum at cost 2.8e-4).
TEST_F(DeltaFixture, NoiseFreeRecoveryWithPointsAndPoses) {
  const auto qs = sample_actuators(pred, {nominal}, 40, rng);
  const auto opt = solve_options_from_model(model, false);
  SimulationOptions sim;
  sim.add_noise = false;
  const Eigen::VectorXd sig = tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0);
  const Eigen::VectorXd perturbed = perturb_parameters(nominal, sig, rng);
  for (auto kind : {SimulatedObservation::kPoint, SimulatedObservation::kPose}) {
    sim.kind = kind;
    const auto base =
        identify(pred, nominal, simulate_measurements(pred, nominal, qs, sim, rng), opt);
    Eigen::VectorXd truth = nominal;
    for (std::size_t i : base.estimated)
      truth(static_cast<Eigen::Index>(i)) = perturbed(static_cast<Eigen::Index>(i));
    const auto held = sample_actuators(pred, {nominal, truth}, 40, rng);
    const auto meas = simulate_measurements(pred, truth, qs, sim, rng);
    const auto res = identify(pred, nominal, meas, opt);
    ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
    const auto check = simulate_measurements(pred, truth, held, sim, rng);
    EXPECT_LT(prediction_errors(pred, res.estimate, check.poses).position_max, 1e-9);
    EXPECT_GT(prediction_errors(pred, nominal, check.poses).position_max, 1e-3);
  }
}

TEST_F(DeltaFixture, UnsolvablePoseIsExcludedAndTooFewPosesRefused) {
  auto qs = sample_actuators(pred, {nominal}, 40, rng);
  SimulationOptions sim;
  sim.add_noise = false;
  auto meas = simulate_measurements(pred, nominal, qs, sim, rng);
  // Readings for which the closed form has no assembly (rods too short to reach).
  std::uniform_real_distribution<double> wide(-3.0, 3.0);
  Eigen::Vector3d bad;
  FramePrediction fp;
  std::string why;
  do {
    bad << wide(rng), wide(rng), wide(rng);
  } while (closed_form_forward(model.closed_form, bad).has_value() ||
           pred.predict(nominal, bad, -1, false, fp, why));
  meas.poses[4].actuators = bad;
  const auto res = identify(pred, nominal, meas, solve_options_from_model(model, false));
  ASSERT_FALSE(res.excluded.empty());
  EXPECT_EQ(res.excluded[0].id, meas.poses[4].id);
  EXPECT_NE(res.excluded[0].reason.find("cannot solve"), std::string::npos)
      << res.excluded[0].reason;

  Measurements few;
  few.poses.assign(meas.poses.begin(), meas.poses.begin() + 5);
  // Issue 21: little data is identified as far as it goes (the gauge said in words), not refused.
  const auto little = identify(pred, nominal, few, solve_options_from_model(model, false));
  ASSERT_EQ(little.status, IdentificationStatus::kConverged) << little.message;
  EXPECT_TRUE(little.limited_data);
  EXPECT_LE(little.estimated.size(), little.equations);
  EXPECT_FALSE(little.gauge.empty());
}

// MCPC at α2 = π/2: Rx(α1)·Ry(π/2) = Ry(π/2)·Rz(−α1), so α1 and the joint offset α3 act alike.
TEST(IdentifyRobots, McpcAlpha1Alpha3RedundantAtAlpha2HalfPi) {
  const Mechanism model = parse_robot_yaml(R"(
robot: mcpc_singular_test
tool: tool
task: {type: position}
bodies:
  - {name: j1, convention: mcpc, joint: revolute, role: actuated, params: {d1: 0.1}}
  - {name: j2, parent: j1, convention: mcpc, joint: revolute, role: actuated, params: {a2: pi/2}}
  - {name: tool, parent: j2, convention: mcpc, joint: fixed, params: {d1: 0.4, d2: 0.1}}
)",
                                           "mcpc_singular_test.yaml");
  const MechanismPredictor pred(model);
  std::mt19937 rng(3);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  const auto qs = sample_actuators(pred, {nominal}, 20, rng);
  SimulationOptions sim;
  sim.kind = SimulatedObservation::kPose;
  sim.add_noise = false;
  const auto res = identify(pred, nominal, simulate_measurements(pred, nominal, qs, sim, rng),
                            solve_options_from_model(model, false));
  const Redundancy* red = redundancy_of(res, "j2.a3");
  if (red == nullptr) red = redundancy_of(res, "j2.a1");
  ASSERT_NE(red, nullptr);
  const std::string a = res.identifiability.names[red->parameter];
  bool partner_found = false;
  for (std::size_t k = 0; k < red->partners.size(); ++k) {
    const std::string p = res.identifiability.names[red->partners[k]];
    if ((a == "j2.a3" && p == "j2.a1") || (a == "j2.a1" && p == "j2.a3")) {
      partner_found = true;
      EXPECT_NEAR(std::abs(red->coefficients[k]), 1.0, 1e-6);
    }
  }
  EXPECT_TRUE(partner_found) << red->explanation;
}

// One pose of the modular arm cannot calibrate its 18+ parameters: only a subset is estimated, and
// the identifiability analysis of that pose says "underdetermined".
TEST(IdentifyRobots, OnePoseModularArmIsUnderdetermined) {
  const Mechanism model = robot("modular_arm");
  const MechanismPredictor pred(model);
  std::mt19937 rng(5);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  const auto qs = sample_actuators(pred, {nominal}, 1, rng);
  ASSERT_EQ(qs.size(), 1u);
  SimulationOptions sim;
  sim.kind = SimulatedObservation::kPose;
  const auto meas = simulate_measurements(pred, nominal, qs, sim, rng);
  // Issue 21: one pose identifies what one pose can (at most 6 combinations), the gauge said.
  const auto res = identify(pred, nominal, meas, solve_options_from_model(model, false));
  EXPECT_TRUE(res.limited_data) << res.message;
  EXPECT_LE(res.estimated.size(), 6u);
  EXPECT_FALSE(res.gauge.empty());

  FramePrediction fp;
  std::string why;
  ASSERT_TRUE(pred.predict(nominal, qs[0], -1, true, fp, why));
  const auto report = analyze_identifiability(fp.jacobian, pred.parameter_names());
  EXPECT_TRUE(report.underdetermined);
  EXPECT_LE(report.rank, 6u);
}

// Heights-only probing of a printer delta on its bed (one plane): the common rod length is
// barely separated from the common endstop height (a steep rod lengthened moves the nozzle like a
// lower endstop). Reported as ill-conditioned, with the rod lengths as culprits and the endstops
// in the weak direction. (With this model's per-tower x/y positions and the endstops known, rod
// length vs radius is well conditioned; the confusion firmware users see shows up here as rod
// length vs endstop.)
TEST(IdentifyRobots, LinearDeltaHeightsOnlyRodLengthIllConditioned) {
  const Mechanism model = robot("linear_delta");
  const MechanismPredictor pred(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Eigen::VectorXd> readings;
  while (readings.size() < 40) {
    // One draw a statement, y first (robocal/core/random_draws.hpp says why).
    const double y = 0.09 * u(rng);
    const double x = 0.09 * u(rng);
    const Eigen::Vector3d T(x, y, 0.02);
    if (T.head<2>().norm() > 0.09) continue;
    const auto q = closed_form_inverse(model.closed_form, T);
    ASSERT_TRUE(q.has_value());
    readings.push_back(readings_from_joint_values(model, nominal, *q));
  }
  SimulationOptions sim;
  sim.kind = SimulatedObservation::kProbeHeight;
  sim.add_noise = false;
  const auto meas = simulate_measurements(pred, nominal, readings, sim, rng);
  SolveOptions opt = solve_options_from_model(model, false);
  opt.candidates.clear();
  for (const std::string n :
       {"rod_a.length", "rod_b.length", "rod_c.length", "tower_a.x", "tower_a.y", "tower_b.x",
        "tower_b.y", "tower_c.y", "carriage_a.encoder_offset", "carriage_b.encoder_offset",
        "carriage_c.encoder_offset"})
    opt.candidates.push_back(static_cast<std::size_t>(model.parameter_index(n)));
  const auto res = identify(pred, nominal, meas, opt);
  std::string all;
  for (const auto& m : res.identifiability.messages) all += m + "\n";
  ASSERT_FALSE(res.identifiability.ill_conditioned.empty()) << all;
  const auto& weak = res.identifiability.ill_conditioned.front();
  EXPECT_NE(res.identifiability.names[weak.first].find(".length"), std::string::npos) << all;
  EXPECT_NE(res.identifiability.names[weak.second].find(".length"), std::string::npos) << all;
  double rods = 0.0;
  double endstops = 0.0;
  for (std::size_t k = 0; k < weak.direction.size(); ++k) {
    const std::string& n = res.identifiability.names[k];
    if (n.find(".length") != std::string::npos) rods += weak.direction[k] * weak.direction[k];
    if (n.find("encoder_offset") != std::string::npos)
      endstops += weak.direction[k] * weak.direction[k];
  }
  EXPECT_GT(rods, 0.3) << all;
  EXPECT_GT(endstops, 0.3) << all;
  EXPECT_GT(res.identifiability.condition_number, 1e2) << all;
  EXPECT_NE(weak.explanation.find("encoder_offset"), std::string::npos) << weak.explanation;
}

}  // namespace
