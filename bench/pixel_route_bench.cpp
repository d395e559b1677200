// The two camera routes of identification on the same simulated data, printed as JSON.
//
//   build/release/bench/robocal_pixel_route_bench [draws] [identifiable|all] [rig_error] [robot]
//
// Rotary Delta (default), truth = nominal + realistic perturbation (lengths σ 0.5 mm, angles
// σ 0.2°) of the parameters pixel data can identify ("identifiable", default) or of every free
// parameter ("all"); "identifiable" = the parameters both routes estimate. The demo's camera layout
// (two 1600x1200 cameras, f 1600 px, 1.25 m below the working volume, 0.5 m apart), a planar
// 8x8-corner board (2.5 cm pitch) on the plate, 60 design poses, corner noise σ 0.1 px. Camera 0 is
// the gauge (known); camera 1 is given as a rig calibration would leave it: rig_error × (20 µm, 30
// µrad) off (default 1; 0 = exact). Per noise draw, the SAME pixels feed
//   route "pose":  per-pose multi-camera PnP (vision::measure_target_pose, cameras held at the
//                  given rig) → 6-D pose + 6x6 covariance → identify (robot parameters);
//   route "pixel": the pixels directly (camera-in-the-loop) → identify (robot + camera 1 pose).
// Printed: held-out end-effector position error vs truth over 500 poses (RMS, mean over draws and
// spread), the covariance-predicted accuracy over the same held-out poses, identification time,
// and the nominal model's error; plus a noise-free run of the pixel route.
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/pixel_observations.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/vision/pose_measurement.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>

using namespace robocal;
using namespace robocal::calib;

namespace {

std::vector<Eigen::Vector3d> board() {
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 8; ++j) pts.emplace_back(0.025 * (i - 3.5), 0.025 * (j - 3.5), 0.0);
  return pts;
}

// vision's pose covariance [rotation; translation] → calib's [position; rotation] (as
// app/src/pose_bridge.hpp).
Matrix6d to_calib_covariance(const Matrix6d& v) {
  Matrix6d out;
  out << v.bottomRightCorner<3, 3>(), v.bottomLeftCorner<3, 3>(), v.topRightCorner<3, 3>(),
      v.topLeftCorner<3, 3>();
  return out;
}

struct Stats {
  std::vector<double> values;
  nlohmann::json json(double scale = 1.0) const {
    double ms = 0;
    double lo = INFINITY;
    double hi = 0;
    for (double v : values) {
      ms += v * v;
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
    const double n = static_cast<double>(values.size());
    return {
        {"rms_over_draws", std::sqrt(ms / n) * scale}, {"min", lo * scale}, {"max", hi * scale}};
  }
};

}  // namespace

int main(int argc, char** argv) {
  const int draws = argc > 1 ? std::stoi(argv[1]) : 10;
  const bool perturb_all = argc > 2 && std::string(argv[2]) == "all";
  // Scale of camera 1's given-pose error (1 = 20 µm and 30 µrad, about what a rig calibration
  // leaves); 0 = the rig is known exactly.
  const double rig_error = argc > 3 ? std::stod(argv[3]) : 1.0;
  const std::string path =
      argc > 4 ? argv[4] : std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml";
  const Mechanism model = load_robot_file(path);
  const MechanismPredictor robot(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  std::mt19937 rng(20261122);
  const double pixel_sigma = 0.1;

  // Cameras around the working volume; camera 1 as given by a rig calibration.
  std::vector<Eigen::Vector3d> reach;
  for (const auto& q : sample_actuators(robot, {nominal}, 100, rng)) {
    FramePrediction fp;
    std::string why;
    if (robot.predict(nominal, q, -1, false, fp, why)) reach.push_back(fp.pose.translation());
  }
  // As in `robocal demo`: two 1600x1200 cameras (f 1600 px) 1.25 m below the volume's centre,
  // 0.5 m apart, looking up at it.
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : reach) centre += p / static_cast<double>(reach.size());
  std::vector<ObservingCamera> true_cameras;
  for (int c = 0; c < 2; ++c) {
    ObservingCamera cam;
    cam.name = "camera" + std::to_string(c);
    cam.model = vision::make_camera(vision::CameraKind::kPinholeRadtan, 1600, 1200, 1600, 1600,
                                    799.5, 599.5, {-0.08, 0.06});
    cam.world_T_camera =
        camera_looking_at(centre + Eigen::Vector3d(c == 0 ? -0.25 : 0.25, 0, -1.25), centre,
                          Eigen::Vector3d::UnitY());
    true_cameras.push_back(cam);
  }
  auto given_cameras = true_cameras;
  given_cameras[1].world_T_camera.translation() +=
      rig_error * Eigen::Vector3d(20e-6, -15e-6, 15e-6);
  given_cameras[1].world_T_camera.linear() =
      Eigen::AngleAxisd(rig_error * 30e-6, Eigen::Vector3d(1, 1, 0).normalized())
          .toRotationMatrix() *
      given_cameras[1].world_T_camera.linear();
  const CameraRigPredictor rig(robot, given_cameras);
  auto full = [&](const Eigen::VectorXd& robot_params) {
    Eigen::VectorXd x = rig.initial_parameters(robot_params);
    rig.set_camera(x, 1, true_cameras[1].world_T_camera);
    return x;
  };
  const SolveOptions robot_opt = solve_options_from_model(model, false);
  const SolveOptions pixel_opt = rig.solve_options(robot_opt);

  const auto design = sample_actuators(robot, {nominal}, 60, rng);
  const auto points = board();
  PixelSimulationOptions sim;
  sim.pixel_sigma = pixel_sigma;
  // Truth.
  const Eigen::VectorXd all =
      perturb_parameters(nominal, tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0), rng);
  Eigen::VectorXd truth = all;
  if (!perturb_all) {
    PixelSimulationOptions clean = sim;
    clean.add_noise = false;
    const auto meas = simulate_pixel_measurements(rig, full(nominal), design, points, clean, rng);
    const auto base = identify(rig, rig.initial_parameters(nominal), meas, pixel_opt);
    // The pose route's base set (6-D poses at the same design) may differ: perturb only what both
    // routes estimate, so that either can represent the truth exactly.
    SimulationOptions poses_clean;
    poses_clean.kind = SimulatedObservation::kPose;
    poses_clean.add_noise = false;
    const auto pose_base = identify(
        robot, nominal, simulate_measurements(robot, nominal, design, poses_clean, rng), robot_opt);
    truth = nominal;
    for (std::size_t i : base.estimated)
      if (i < model.parameters.size() &&
          std::count(pose_base.estimated.begin(), pose_base.estimated.end(), i) > 0)
        truth(static_cast<Eigen::Index>(i)) = all(static_cast<Eigen::Index>(i));
  }
  const auto held = sample_actuators(robot, {nominal, truth}, 500, rng);
  std::vector<Eigen::Vector3d> held_truth;
  for (std::size_t k = 0; k < held.size(); ++k) {
    FramePrediction fp;
    std::string why;
    robot.predict(truth, held[k], static_cast<int>(10000 + k), false, fp, why);
    held_truth.push_back(fp.pose.translation());
  }
  // Covariance-predicted end-effector accuracy over the held-out poses (J_h Σ J_hᵀ).
  auto predicted_heldout = [&](const FramePredictor& predictor,
                               const IdentificationResult& r) -> double {
    if (!r.uncertainty.ok) return NAN;
    std::vector<Eigen::MatrixXd> jacobians;
    for (std::size_t k = 0; k < held.size(); ++k) {
      FramePrediction fp;
      std::string why;
      if (!predictor.predict(r.estimate, held[k], static_cast<int>(10000 + k), true, fp, why))
        continue;
      Eigen::MatrixXd J(3, static_cast<Eigen::Index>(r.estimated.size()));
      for (std::size_t c = 0; c < r.estimated.size(); ++c)
        J.col(static_cast<Eigen::Index>(c)) =
            fp.jacobian.col(static_cast<Eigen::Index>(r.estimated[c])).head<3>();
      jacobians.push_back(J);
    }
    return predict_accuracy(jacobians, r.uncertainty.covariance).position_rms_overall;
  };
  auto heldout_rms = [&](const Eigen::VectorXd& robot_params) -> double {
    double sum = 0;
    for (std::size_t k = 0; k < held.size(); ++k) {
      FramePrediction fp;
      std::string why;
      if (!robot.predict(robot_params, held[k], static_cast<int>(10000 + k), false, fp, why))
        return INFINITY;
      sum += (fp.pose.translation() - held_truth[k]).squaredNorm();
    }
    return std::sqrt(sum / static_cast<double>(held.size()));
  };

  std::vector<vision::RigCamera> vision_rig;
  for (const auto& c : given_cameras)
    vision_rig.push_back({c.name, c.model, c.world_T_camera.inverse(), Matrix6d::Zero()});
  vision::BoardPoints board_points;
  for (std::size_t j = 0; j < points.size(); ++j) board_points[static_cast<int>(j)] = points[j];

  Stats pose_err, pixel_err, pose_pred, pixel_pred, pose_time, pixel_time, pnp_err;
  int pose_failures = 0;
  int pixel_failures = 0;
  std::size_t poses_used = 0;
  std::size_t pose_params = 0;
  std::size_t pixel_params = 0;
  double noise_free_pixel = NAN;
  nlohmann::json noise_free_json;
  for (int d = -1; d < draws; ++d) {
    PixelSimulationOptions s = sim;
    s.add_noise = d >= 0;  // draw -1: noise-free check of route 2
    const auto pixels = simulate_pixel_measurements(rig, full(truth), design, points, s, rng);
    // Route 2: pixels directly.
    auto t0 = std::chrono::steady_clock::now();
    const auto r2 = identify(rig, rig.initial_parameters(nominal), pixels, pixel_opt);
    const double t2 = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (d < 0) {
      noise_free_pixel = heldout_rms(rig.robot_parameters(r2.estimate));
      noise_free_json = {
          {"status", to_string(r2.status)},
          {"final_cost", r2.final_cost},
          {"iterations", r2.iterations},
          {"reprojection_rms_px", pixel_errors(rig, r2.estimate, pixels.poses).rms_px}};
      continue;
    }
    if (r2.status != IdentificationStatus::kConverged) ++pixel_failures;
    pixel_err.values.push_back(heldout_rms(rig.robot_parameters(r2.estimate)));
    pixel_pred.values.push_back(predicted_heldout(rig, r2));
    pixel_time.values.push_back(t2);
    pixel_params = r2.estimated.size();
    // Route 1: per-pose PnP on the same pixels, then 6-D poses.
    Measurements poses;
    double pnp_sum = 0;
    for (const auto& p : pixels.poses) {
      std::vector<vision::CameraFrame> frames(given_cameras.size());
      for (const auto& obs : p.observations) {
        const auto& px = std::get<PixelObservation>(obs);
        frames[static_cast<std::size_t>(px.camera)].corners.push_back(
            {px.corner, px.measured, pixel_sigma});
      }
      const auto m = vision::measure_target_pose(vision_rig, board_points, frames);
      if (!m.usable()) continue;
      FramePrediction fp;
      std::string why;
      robot.predict(truth, p.actuators, -1, false, fp, why);
      pnp_sum += (m.world_T_target.translation() - fp.pose.translation()).squaredNorm();
      poses.poses.push_back({p.id,
                             p.actuators,
                             {PoseObservation::with_covariance(
                                 m.world_T_target, to_calib_covariance(m.covariance))}});
    }
    pnp_err.values.push_back(std::sqrt(pnp_sum / static_cast<double>(poses.poses.size())));
    poses_used = poses.poses.size();
    t0 = std::chrono::steady_clock::now();
    const auto r1 = identify(robot, nominal, poses, robot_opt);
    pose_time.values.push_back(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    if (r1.status != IdentificationStatus::kConverged) ++pose_failures;
    pose_err.values.push_back(heldout_rms(r1.estimate));
    pose_pred.values.push_back(predicted_heldout(robot, r1));
    pose_params = r1.estimated.size();
  }

  nlohmann::json out;
  out["robot"] = model.name;
  out["truth"] =
      perturb_all ? "all free parameters perturbed" : "parameters both routes identify perturbed";
  out["draws"] = draws;
  out["design_poses"] = design.size();
  out["board_corners"] = points.size();
  out["pixel_sigma_px"] = pixel_sigma;
  out["camera1_given_error"] = {{"position_um", rig_error * Eigen::Vector3d(20, -15, 15).norm()},
                                {"rotation_urad", rig_error * 30.0}};
  out["heldout_poses"] = held.size();
  out["nominal_heldout_rms_um"] = heldout_rms(nominal) * 1e6;
  out["route_pixel_noise_free_heldout_rms_um"] = noise_free_pixel * 1e6;
  out["route_pixel_noise_free"] = noise_free_json;
  out["pnp_position_error_rms_um"] = pnp_err.json(1e6);
  out["route_pose"] = {{"estimated_parameters", pose_params},
                       {"poses_used", poses_used},
                       {"not_converged", pose_failures},
                       {"heldout_rms_um", pose_err.json(1e6)},
                       {"predicted_heldout_rms_um", pose_pred.json(1e6)},
                       {"identify_seconds", pose_time.json()}};
  out["route_pixel"] = {{"estimated_parameters", pixel_params},
                        {"not_converged", pixel_failures},
                        {"heldout_rms_um", pixel_err.json(1e6)},
                        {"predicted_heldout_rms_um", pixel_pred.json(1e6)},
                        {"identify_seconds", pixel_time.json()}};
  std::cout << out.dump(2) << std::endl;
  return 0;
}
