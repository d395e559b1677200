// Camera-in-the-loop identification of the rotary Delta (full closed-loop model) seen by two
// simulated cameras: noise-free pixels recover the true robot's end-effector predictions to
// < 1 µm and camera 1's pose; with pixel noise the predicted accuracy matches the actual error.
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/pixel_observations.hpp"
#include "robocal/calib/robot_file.hpp"

#include <gtest/gtest.h>

namespace {

using namespace robocal::calib;

// A 3x3 grid of 5 cm pitch on the plate plus one corner 2 cm off its plane.
std::vector<Eigen::Vector3d> target() {
  std::vector<Eigen::Vector3d> pts;
  for (int i = -1; i <= 1; ++i)
    for (int j = -1; j <= 1; ++j) pts.emplace_back(0.05 * i, 0.05 * j, 0.0);
  pts.emplace_back(0.0, 0.0, -0.02);
  return pts;
}

struct DeltaRig : ::testing::Test {
  Mechanism model =
      load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
  MechanismPredictor robot{model};
  Eigen::VectorXd nominal = model.nominal_parameters();
  std::mt19937 rng{4242};
  std::vector<ObservingCamera> true_cameras;
  std::vector<ObservingCamera> given_cameras;  // camera 1 as a rig calibration leaves it
  std::unique_ptr<CameraRigPredictor> rig;

  void SetUp() override {
    std::vector<Eigen::Vector3d> reach;
    for (const auto& q : sample_actuators(robot, {nominal}, 60, rng)) {
      FramePrediction fp;
      std::string why;
      if (robot.predict(nominal, q, -1, false, fp, why)) reach.push_back(fp.pose.translation());
    }
    true_cameras = cameras_below(reach);
    given_cameras = true_cameras;
    given_cameras[1].world_T_camera.translation() += Eigen::Vector3d(2e-3, -3e-3, 1e-3);
    given_cameras[1].world_T_camera.linear() =
        Eigen::AngleAxisd(3e-3, Eigen::Vector3d(0.3, -1, 0.5).normalized()).toRotationMatrix() *
        given_cameras[1].world_T_camera.linear();
    rig = std::make_unique<CameraRigPredictor>(robot, given_cameras);
  }

  Eigen::VectorXd full(const Eigen::VectorXd& robot_params) const {
    Eigen::VectorXd x = rig->initial_parameters(robot_params);
    rig->set_camera(x, 1, true_cameras[1].world_T_camera);
    return x;
  }

  // Truth differing from nominal in the parameters pixels can identify (as in the identification
  // bench's default scenario: redundant deviations are absorbed by the base set anyway).
  Eigen::VectorXd identifiable_truth(const std::vector<Eigen::VectorXd>& design,
                                     const SolveOptions& opt) {
    PixelSimulationOptions clean;
    clean.add_noise = false;
    const auto meas =
        simulate_pixel_measurements(*rig, full(nominal), design, target(), clean, rng);
    const auto base = identify(*rig, rig->initial_parameters(nominal), meas, opt);
    EXPECT_EQ(base.status, IdentificationStatus::kConverged) << base.message;
    const Eigen::VectorXd sigma = tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0);
    const Eigen::VectorXd all = perturb_parameters(nominal, sigma, rng);
    Eigen::VectorXd truth = nominal;
    for (std::size_t i : base.estimated)
      if (i < model.parameters.size())
        truth(static_cast<Eigen::Index>(i)) = all(static_cast<Eigen::Index>(i));
    return truth;
  }

  double heldout_error(const Eigen::VectorXd& robot_params, const Eigen::VectorXd& truth,
                       const std::vector<Eigen::VectorXd>& held, double* worst) const {
    double sum = 0;
    *worst = 0;
    for (std::size_t k = 0; k < held.size(); ++k) {
      FramePrediction a, b;
      std::string why;
      EXPECT_TRUE(robot.predict(robot_params, held[k], static_cast<int>(1000 + k), false, a, why));
      EXPECT_TRUE(robot.predict(truth, held[k], static_cast<int>(1000 + k), false, b, why));
      const double e = (a.pose.translation() - b.pose.translation()).norm();
      sum += e * e;
      *worst = std::max(*worst, e);
    }
    return std::sqrt(sum / static_cast<double>(held.size()));
  }
};

TEST_F(DeltaRig, NoiseFreePixelsRecoverEndEffectorAndCameraPose) {
  const SolveOptions opt = rig->solve_options(solve_options_from_model(model, false));
  const auto design = sample_actuators(robot, {nominal}, 30, rng);
  const Eigen::VectorXd truth = identifiable_truth(design, opt);
  const auto held = sample_actuators(robot, {nominal, truth}, 100, rng);
  PixelSimulationOptions clean;
  clean.add_noise = false;
  const auto meas = simulate_pixel_measurements(*rig, full(truth), design, target(), clean, rng);
  ASSERT_GE(meas.poses.size(), 25u);
  const auto res = identify(*rig, rig->initial_parameters(nominal), meas, opt);
  ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
  double worst = 0;
  const double before = heldout_error(nominal, truth, held, &worst);
  EXPECT_GT(before, 1e-4);
  heldout_error(rig->robot_parameters(res.estimate), truth, held, &worst);
  EXPECT_LT(worst, 1e-6);
  const Eigen::Isometry3d cam1 = rig->world_T_camera(res.estimate, 1);
  EXPECT_LT((cam1.translation() - true_cameras[1].world_T_camera.translation()).norm(), 1e-8);
  EXPECT_LT(Eigen::AngleAxisd(cam1.linear() * true_cameras[1].world_T_camera.linear().transpose())
                .angle(),
            1e-9);
}

TEST_F(DeltaRig, PixelNoiseGivesTheAccuracyTheCovariancePredicts) {
  const SolveOptions opt = rig->solve_options(solve_options_from_model(model, false));
  const auto design = sample_actuators(robot, {nominal}, 30, rng);
  const Eigen::VectorXd truth = identifiable_truth(design, opt);
  PixelSimulationOptions noisy;
  noisy.pixel_sigma = 0.1;
  double predicted_ms = 0;
  double actual_ms = 0;
  // 12 draws: with 3, the ratio of two RMS figures is itself too noisy for a factor-1.5 test
  // (0.43 seen on one seed; 0.92 with 12 draws on the same design).
  const int draws = 12;
  for (int d = 0; d < draws; ++d) {
    const auto meas = simulate_pixel_measurements(*rig, full(truth), design, target(), noisy, rng);
    const auto res = identify(*rig, rig->initial_parameters(nominal), meas, opt);
    ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
    ASSERT_TRUE(res.uncertainty.ok) << res.uncertainty.message;
    predicted_ms += std::pow(res.predicted.position_rms_overall, 2);
    std::vector<Eigen::VectorXd> at_design;
    for (const auto& p : meas.poses) at_design.push_back(p.actuators);
    double worst = 0;
    actual_ms +=
        std::pow(heldout_error(rig->robot_parameters(res.estimate), truth, at_design, &worst), 2);
  }
  const double ratio = std::sqrt(actual_ms / predicted_ms);
  EXPECT_GT(ratio, 1.0 / 1.5);
  EXPECT_LT(ratio, 1.5);
}

}  // namespace
