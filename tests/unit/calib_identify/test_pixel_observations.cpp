// Camera-in-the-loop identification on the planar arm seen by two cameras: exact pixel Jacobian
// (against central differences), recovery of the robot and the camera poses from noise-free
// pixels, covariance consistent with the spread of noisy estimates, and the refusals.
#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/pixel_observations.hpp"
#include "robocal/calib/robot_file.hpp"

#include "pixel_fixture.hpp"

#include <gtest/gtest.h>
#include <Eigen/Cholesky>

#include <random>
#include <string>

namespace {

using namespace robocal::calib;
using namespace robocal::calib::testing;

// Full truth vector of `rig`: the planar truth and the true camera poses (and intrinsics).
Eigen::VectorXd rig_truth(const CameraRigPredictor& rig) {
  Eigen::VectorXd x = rig.initial_parameters(planar_truth());
  const auto cams = planar_true_cameras();
  for (int c = 0; c < rig.camera_count(); ++c)
    rig.set_camera(x, c, cams[static_cast<std::size_t>(c)].world_T_camera,
                   &cams[static_cast<std::size_t>(c)].model);
  return x;
}

// Noise-free pixels that `rig` with parameters `truth` sees at 20 actuator draws (`seed` seeds
// both the draws and the simulation).
Measurements noise_free_pixels(const CameraRigPredictor& rig, const Eigen::VectorXd& truth,
                               unsigned seed) {
  std::mt19937 rng(seed);
  PixelSimulationOptions sim;
  sim.add_noise = false;
  return simulate_pixel_measurements(rig, truth, planar_actuators(20, seed), planar_target(), sim,
                                     rng);
}

double pose_error(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.translation() - b.translation()).norm() +
         Eigen::AngleAxisd(a.linear() * b.linear().transpose()).angle();
}

TEST(PixelObservation, JacobianMatchesCentralDifferences) {
  PlanarPredictor planar;
  CameraRigOptions ro;
  ro.estimate_intrinsics = true;  // every column kind: robot, camera pose, intrinsics
  const CameraRigPredictor rig(planar, planar_start_cameras(), ro);
  Eigen::VectorXd x = rig_truth(rig);
  // Rotation parameters away from 0, where exp's derivative is not the identity.
  x.segment<3>(static_cast<Eigen::Index>(rig.pose_offset(1)) + 3) << 0.03, -0.02, 0.05;
  const Eigen::Vector2d q(0.4, -0.7);
  int checked = 0;
  for (int cam = 0; cam < 2; ++cam) {
    for (const Eigen::Vector3d& X :
         {Eigen::Vector3d(0.05, -0.05, 0.0), Eigen::Vector3d(0, 0.1, 0.02)}) {
      const auto obs = PixelObservation::with_covariance(
          cam, 3, X, Eigen::Vector2d(600, 500),
          (Eigen::Matrix2d() << 0.04, 0.01, 0.01, 0.09).finished());
      auto residual_at = [&](const Eigen::VectorXd& p, Eigen::Vector2d& r,
                             Eigen::Matrix<double, 2, Eigen::Dynamic>* J) {
        FramePrediction pred;
        std::string why;
        EXPECT_TRUE(rig.predict(p, q, 0, J != nullptr, pred, why)) << why;
        EXPECT_TRUE(rig.pixel_residual(obs, p, pred, r, J, why)) << why;
      };
      Eigen::Vector2d r0;
      Eigen::Matrix<double, 2, Eigen::Dynamic> J;
      residual_at(x, r0, &J);
      ASSERT_EQ(J.cols(), x.size());
      Eigen::Matrix<double, 2, Eigen::Dynamic> Jn(2, x.size());
      for (Eigen::Index i = 0; i < x.size(); ++i) {
        const double h = 1e-6 * std::max(1.0, std::abs(x(i)));
        Eigen::VectorXd xp = x, xm = x;
        xp(i) += h;
        xm(i) -= h;
        Eigen::Vector2d rp, rm;
        residual_at(xp, rp, nullptr);
        residual_at(xm, rm, nullptr);
        Jn.col(i) = (rp - rm) / (2 * h);
      }
      for (Eigen::Index i = 0; i < x.size(); ++i) {
        const double scale = std::max(1.0, Jn.col(i).norm());
        EXPECT_LT((J.col(i) - Jn.col(i)).norm(), 1e-6 * scale)
            << rig.parameter_names()[static_cast<std::size_t>(i)] << " camera " << cam;
        ++checked;
      }
      // The camera the corner is not seen by has no influence.
      const auto other = static_cast<Eigen::Index>(rig.pose_offset(1 - cam));
      EXPECT_EQ(J.middleCols(other, 6).norm(), 0.0);
    }
  }
  EXPECT_EQ(checked, 4 * static_cast<int>(x.size()));
}

TEST(PixelObservation, LayoutNamesAndGauge) {
  PlanarPredictor planar;
  const CameraRigPredictor rig(planar, planar_start_cameras());
  ASSERT_EQ(rig.parameter_count(), 10u + 12u);
  const auto names = rig.parameter_names();
  EXPECT_EQ(names[10], "camera0.x");
  EXPECT_EQ(names[21], "camera1.rz");
  const SolveOptions opt = rig.solve_options(planar_geometry_first());
  // Camera 0 is the gauge: its pose is never a candidate; camera 1's is, kept first.
  for (std::size_t i = 10; i < 16; ++i)
    EXPECT_EQ(std::count(opt.candidates.begin(), opt.candidates.end(), i), 0) << names[i];
  for (std::size_t i = 16; i < 22; ++i) {
    EXPECT_EQ(std::count(opt.candidates.begin(), opt.candidates.end(), i), 1) << names[i];
    EXPECT_LT(opt.preference[i], 0);
  }
  // Start values reproduce the given camera poses.
  const Eigen::VectorXd x = rig.initial_parameters(planar_nominal());
  EXPECT_LT(pose_error(rig.world_T_camera(x, 1), planar_start_cameras()[1].world_T_camera), 1e-15);
  CameraRigOptions ro;
  ro.estimate_intrinsics = true;
  const CameraRigPredictor with_k(planar, planar_start_cameras(), ro);
  EXPECT_EQ(with_k.parameter_count(), 10u + 6u + 9u + 6u + 8u);
  EXPECT_EQ(with_k.parameter_names()[16], "camera0.fx");
  EXPECT_EQ(with_k.parameter_names()[31], "camera1.fx");
}

TEST(PixelObservation, NoiseFreePixelsRecoverRobotAndCameraPoses) {
  PlanarPredictor planar;
  const CameraRigPredictor rig(planar, planar_start_cameras());
  const Eigen::VectorXd truth = rig_truth(rig);
  const auto meas = noise_free_pixels(rig, truth, 5);
  ASSERT_GE(meas.poses.size(), 15u);
  const auto res = identify(rig, rig.initial_parameters(planar_nominal()), meas,
                            rig.solve_options(planar_geometry_first()));
  ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
  // 7 robot parameters (as with points: 3 redundancies) + camera 1's 6.
  EXPECT_EQ(res.estimated.size(), 13u);
  EXPECT_EQ(res.identifiability.redundancies.size(), 3u);
  EXPECT_LT(planar_heldout_rms(rig.robot_parameters(res.estimate), planar_truth()), 1e-9);
  EXPECT_GT(planar_heldout_rms(planar_nominal(), planar_truth()), 1e-3);
  EXPECT_LT(
      pose_error(rig.world_T_camera(res.estimate, 1), planar_true_cameras()[1].world_T_camera),
      1e-9);
  EXPECT_GT(pose_error(rig.world_T_camera(rig.initial_parameters(planar_nominal()), 1),
                       planar_true_cameras()[1].world_T_camera),
            5e-3);
  EXPECT_LT(pixel_errors(rig, res.estimate, meas.poses).rms_px, 1e-6);
}

TEST(PixelObservation, CovarianceMatchesTheSpreadOfNoisyEstimates) {
  PlanarPredictor planar;
  const CameraRigPredictor rig(planar, planar_start_cameras());
  const Eigen::VectorXd truth = rig_truth(rig);
  const Eigen::VectorXd start = rig.initial_parameters(planar_nominal());
  const SolveOptions opt = rig.solve_options(planar_geometry_first());
  const auto qs = planar_actuators(14, 6);
  std::mt19937 rng(6);
  PixelSimulationOptions sim;
  sim.pixel_sigma = 0.3;
  // The noise-free estimate is the truth in the identified (base-set) coordinates.
  sim.add_noise = false;
  const auto clean = identify(
      rig, start, simulate_pixel_measurements(rig, truth, qs, planar_target(), sim, rng), opt);
  ASSERT_EQ(clean.status, IdentificationStatus::kConverged);
  sim.add_noise = true;
  const int draws = 8;
  double nees = 0.0;
  double predicted_ms = 0.0;
  double actual_ms = 0.0;
  for (int d = 0; d < draws; ++d) {
    const auto meas = simulate_pixel_measurements(rig, truth, qs, planar_target(), sim, rng);
    const auto res = identify(rig, start, meas, opt);
    ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
    ASSERT_TRUE(res.uncertainty.ok);
    ASSERT_EQ(res.estimated, clean.estimated);
    Eigen::VectorXd e(static_cast<Eigen::Index>(res.estimated.size()));
    for (std::size_t k = 0; k < res.estimated.size(); ++k)
      e(static_cast<Eigen::Index>(k)) = res.estimate(static_cast<Eigen::Index>(res.estimated[k])) -
                                        clean.estimate(static_cast<Eigen::Index>(res.estimated[k]));
    nees += e.dot(res.uncertainty.covariance.ldlt().solve(e)) / static_cast<double>(e.size());
    // Reduced chi-square of the fit near 1: the whitening is right.
    double rows = 0;
    for (const auto& pr : res.residuals.poses) rows += pr.dof;
    const double dof = rows - static_cast<double>(res.estimated.size());
    EXPECT_NEAR(2.0 * res.final_cost / dof, 1.0, 0.35);
    // Predicted vs actual end-effector error at the measured poses.
    predicted_ms += std::pow(res.predicted.position_rms_overall, 2);
    PlanarPredictor model;
    double sum = 0;
    for (const auto& pose : meas.poses) {
      FramePrediction a, b;
      std::string why;
      model.predict(rig.robot_parameters(res.estimate), pose.actuators, 0, false, a, why);
      model.predict(planar_truth(), pose.actuators, 0, false, b, why);
      sum += (a.pose.translation() - b.pose.translation()).squaredNorm();
    }
    actual_ms += sum / static_cast<double>(meas.poses.size());
  }
  nees /= draws;
  // Mean of chi2_n / n over 8 draws with n = 13: 1 ± 0.14 (1σ).
  EXPECT_GT(nees, 0.65);
  EXPECT_LT(nees, 1.4);
  const double ratio = std::sqrt(actual_ms / predicted_ms);
  EXPECT_GT(ratio, 1.0 / 1.5);
  EXPECT_LT(ratio, 1.5);
}

TEST(PixelObservation, PosesWithUnusablePixelsAreExcludedWithAReason) {
  PlanarPredictor planar;
  const CameraRigPredictor rig(planar, planar_start_cameras());
  const Eigen::VectorXd truth = rig_truth(rig);
  auto meas = noise_free_pixels(rig, truth, 7);
  std::get<PixelObservation>(meas.poses[0].observations[0]).camera = 5;       // no such camera
  std::get<PixelObservation>(meas.poses[1].observations[0]).point.z() = 5.0;  // behind camera
  std::get<PixelObservation>(meas.poses[2].observations[0]).measured.x() = std::nan("");
  const auto res = identify(rig, rig.initial_parameters(planar_nominal()), meas,
                            rig.solve_options(planar_geometry_first()));
  ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
  ASSERT_EQ(res.excluded.size(), 3u);
  EXPECT_NE(res.excluded[0].reason.find("camera 5 does not exist"), std::string::npos)
      << res.excluded[0].reason;
  EXPECT_NE(res.excluded[1].reason.find("behind the camera"), std::string::npos)
      << res.excluded[1].reason;
  EXPECT_NE(res.excluded[2].reason.find("not finite"), std::string::npos);
  // A model without cameras cannot explain pixels: every such pose says so.
  const auto plain = identify(planar, planar_nominal(), meas, planar_geometry_first());
  EXPECT_EQ(plain.status, IdentificationStatus::kInvalidInput);
  ASSERT_FALSE(plain.excluded.empty());
  EXPECT_NE(plain.excluded.back().reason.find("no cameras"), std::string::npos);
}

// Corners measured jointly (one tag's edge fit) are whitened by their joint covariance: with
// known pixel offsets δ at the truth, the starting cost is ½ δᵀ C⁻¹ δ, computed here directly.
TEST(PixelObservation, GroupedCornersAreWhitenedByTheirJointCovariance) {
  PlanarPredictor planar;
  const CameraRigPredictor rig(planar, planar_start_cameras());
  const Eigen::VectorXd truth = rig_truth(rig);
  auto meas = noise_free_pixels(rig, truth, 11);
  ASSERT_FALSE(meas.poses.empty());
  PoseMeasurement& pose = meas.poses[0];
  ASSERT_GE(pose.observations.size(), 4u);
  // A correlated 6x6 covariance for observations 1..3 (px²).
  Eigen::MatrixXd A(6, 6);
  A << 0.9, 0.1, 0.3, 0.0, -0.2, 0.1,  //
      0.0, 0.7, 0.2, 0.4, 0.0, -0.1,   //
      0.1, 0.0, 0.8, 0.1, 0.3, 0.0,    //
      0.2, -0.3, 0.0, 0.6, 0.1, 0.2,   //
      0.0, 0.1, -0.1, 0.0, 0.9, 0.3,   //
      -0.1, 0.0, 0.2, 0.1, 0.0, 0.5;
  const Eigen::MatrixXd C = 0.04 * (A * A.transpose() + 0.1 * Eigen::MatrixXd::Identity(6, 6));
  Eigen::VectorXd delta(6);
  delta << 0.11, -0.07, 0.05, 0.13, -0.09, 0.02;
  std::vector<PixelObservation> members;
  for (int k = 0; k < 3; ++k) {
    auto& o = std::get<PixelObservation>(pose.observations[static_cast<std::size_t>(1 + k)]);
    o = PixelObservation::with_covariance(o.camera, o.corner, o.point,
                                          o.measured + delta.segment<2>(2 * k),
                                          C.block<2, 2>(2 * k, 2 * k));
    members.push_back(o);
  }
  pose.pixel_groups.push_back(PixelGroup::from_covariance(1, members, C));

  const auto res = identify(rig, truth, meas, rig.solve_options(planar_geometry_first()));
  ASSERT_NE(res.status, IdentificationStatus::kInvalidInput) << res.message;
  ASSERT_TRUE(res.excluded.empty());
  const double expected = 0.5 * delta.dot(C.llt().solve(delta));
  EXPECT_NEAR(res.initial_cost, expected, 1e-9 * expected);
  // Treating the same corners as independent gives a different cost: the group matters here.
  const double independent = [&] {
    double sum = 0.0;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2d d = delta.segment<2>(2 * k);
      sum += 0.5 * d.dot(C.block<2, 2>(2 * k, 2 * k).llt().solve(d));
    }
    return sum;
  }();
  EXPECT_GT(std::abs(expected - independent), 0.05 * expected);
}

TEST(PixelObservation, MalformedPixelGroupsExcludeTheirPoseWithAReason) {
  PlanarPredictor planar;
  const CameraRigPredictor rig(planar, planar_start_cameras());
  const Eigen::VectorXd truth = rig_truth(rig);
  auto meas = noise_free_pixels(rig, truth, 13);
  ASSERT_GE(meas.poses.size(), 3u);
  const auto n = static_cast<int>(meas.poses[0].observations.size());
  meas.poses[0].pixel_groups.push_back({n - 1, 2, Eigen::MatrixXd::Identity(4, 4)});  // past end
  meas.poses[1].pixel_groups.push_back({0, 2, Eigen::MatrixXd::Identity(4, 4)});
  meas.poses[1].pixel_groups.push_back({1, 2, Eigen::MatrixXd::Identity(4, 4)});  // overlaps
  meas.poses[2].pixel_groups.push_back({0, 2, Eigen::MatrixXd::Identity(3, 3)});  // wrong size
  const auto res = identify(rig, rig.initial_parameters(planar_nominal()), meas,
                            rig.solve_options(planar_geometry_first()));
  ASSERT_EQ(res.excluded.size(), 3u);
  for (const auto& e : res.excluded)
    EXPECT_NE(e.reason.find("pixel group"), std::string::npos) << e.reason;
  EXPECT_NE(res.excluded[1].reason.find("already in another group"), std::string::npos);
  EXPECT_THROW(
      PixelGroup::from_covariance(0, {PixelObservation{}}, Eigen::MatrixXd::Identity(3, 3)),
      std::invalid_argument);
}

// Pose blocks evaluated on two workers (SolveOptions::threads) give the one-worker estimate to the
// bit: the Delta's closed loops through MechanismPredictor's shared solver pool, watched by two
// cameras, its geometry and the second camera's pose estimated from noisy pixels.
TEST(PixelObservation, TwoWorkersGiveTheOneWorkerEstimateToTheBit) {
  const Mechanism model =
      load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
  std::mt19937 rng(5);
  std::normal_distribution<double> n01(0.0, 1.0);
  const Eigen::VectorXd sigmas = tolerance_sigmas(model, 2e-4, 2e-3);
  Eigen::VectorXd truth = model.nominal_parameters();
  for (Eigen::Index i = 0; i < truth.size(); ++i) truth(i) += sigmas(i) * n01(rng);
  const auto run = [&](int threads) {
    const MechanismPredictor robot(model);  // fresh caches for each run
    const auto actuators = sample_actuators(robot, {model.nominal_parameters(), truth}, 24, rng);
    std::vector<Eigen::Vector3d> tool;
    for (const auto& a : actuators) {
      FramePrediction p;
      std::string why;
      EXPECT_TRUE(robot.predict(truth, a, -1, false, p, why)) << why;
      tool.push_back(p.pose.translation());
    }
    const CameraRigPredictor rig(robot, cameras_below(tool, 2));
    std::mt19937 noise(9);
    const Measurements m = simulate_pixel_measurements(rig, rig.initial_parameters(truth),
                                                       actuators, planar_target(), {}, noise);
    SolveOptions options = rig.solve_options(solve_options_from_model(model, true));
    options.threads = threads;
    EXPECT_TRUE(rig.thread_safe());
    return identify(rig, rig.initial_parameters(model.nominal_parameters()), m, options);
  };
  std::mt19937 start = rng;
  const IdentificationResult one = run(1);
  rng = start;  // the same poses for both
  const IdentificationResult two = run(2);
  ASSERT_EQ(one.status, IdentificationStatus::kConverged) << one.message;
  EXPECT_EQ(two.status, one.status);
  EXPECT_EQ(two.iterations, one.iterations);
  EXPECT_EQ(two.final_cost, one.final_cost);
  ASSERT_EQ(two.estimate.size(), one.estimate.size());
  for (Eigen::Index i = 0; i < one.estimate.size(); ++i)
    EXPECT_EQ(two.estimate(i), one.estimate(i)) << i;
  EXPECT_EQ(two.uncertainty.covariance, one.uncertainty.covariance);
}

}  // namespace
