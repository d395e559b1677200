// End-effector pose measurement accuracy on the stereo rig, printed as JSON.
//
// Two 2448x2048 cameras (f = 2400 px, 0.5 m baseline, 30 deg convergence) ~1.15 m from a 200 mm
// AprilTag board of 6 x 6 tags, tilt <= 35 deg. For each of N random poses: error of the
// measured pose against the truth, stereo and mono, with the true rig and with the rig as
// calibrated from calibration views; the normalised error squared (NEES, expectation 6); the
// rig calibration's baseline error next to cv::stereoCalibrate's on the same detections.
//
//   bench_pose_measurement [--mode synthetic|rendered] [--poses 100] [--calib-views 40]
//                          [--sigma 0.05] [--seed 1] [--corner-noise detector|iid]
//
// synthetic: exact projections + Gaussian pixel noise (--sigma): the estimator alone.
// rendered:  images rendered with exact ground truth (blur 0.8 px, read noise 2 DN) and
//            detected with the AprilTag board detector: the whole chain. The corner sigma used
//            by the estimators is the detector's joint covariance of each tag's four corners
//            (propagated from its edge fits; --corner-noise iid: independent corners with the
//            RMS residual of the rig calibration as sigma, never the truth).
#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/pose_measurement.hpp"
#include "robocal/vision/renderer.hpp"
#include "robocal/vision/rig_calibration.hpp"
#include "robocal/vision/synthetic_observations.hpp"
#include "robocal/vision/target.hpp"
#include "robocal/vision/target_detection.hpp"

#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <random>
#include <string>

namespace rv = robocal::vision;
using Eigen::Isometry3d;
using Eigen::Vector3d;

namespace {

rv::CameraModel bench_camera() {
  return rv::make_camera(rv::CameraKind::kPinholeRadtan, 2448, 2048, 2400.0, 2400.0, 1223.5, 1023.5,
                         {-0.08, 0.05, 0.0002, -0.0001, 0.0});
}

std::vector<rv::RigCamera> true_rig() {
  const double half = 0.25;
  const double converge_z = half / std::tan(15.0 * M_PI / 180.0);
  std::vector<rv::RigCamera> rig(2);
  for (int i = 0; i < 2; ++i) {
    rig[static_cast<size_t>(i)].name = i == 0 ? "left" : "right";
    rig[static_cast<size_t>(i)].model = bench_camera();
    rig[static_cast<size_t>(i)].camera_T_world = rv::camera_T_board_look_at(
        Vector3d(i == 0 ? -half : half, 0, 0), Vector3d(0, 0, converge_z), Vector3d(0, -1, 0));
  }
  return rig;
}

// Board centre near (0, 0, distance), facing the cameras, tilted <= max_tilt, spun freely.
Isometry3d random_pose(std::mt19937_64& rng, const Vector3d& board_centre, double distance,
                       double depth_range, double lateral, double max_tilt_deg) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double tilt = std::abs(u(rng)) * max_tilt_deg * M_PI / 180.0;
  const double axis_angle = u(rng) * M_PI;
  const double spin = u(rng) * M_PI;
  Isometry3d pose = Isometry3d::Identity();
  pose.linear() =
      (Eigen::AngleAxisd(tilt, Vector3d(std::cos(axis_angle), std::sin(axis_angle), 0)) *
       Eigen::AngleAxisd(spin, Vector3d::UnitZ()))
          .toRotationMatrix();
  // One draw a statement, z first (robocal/core/random_draws.hpp says why).
  const double z = distance + depth_range * u(rng);
  const double y = lateral * u(rng);
  const double x = lateral * u(rng);
  const Vector3d centre(x, y, z);
  pose.translation() = centre - pose.linear() * board_centre;
  return pose;
}

struct Observer {
  virtual ~Observer() = default;
  // What each camera sees of the board at world_T_board.
  virtual std::vector<rv::CameraFrame> observe(const std::vector<rv::RigCamera>& rig,
                                               const Isometry3d& world_T_board) = 0;
};

struct SyntheticObserver : Observer {
  rv::BoardPoints board;
  double sigma = 0.05;
  std::mt19937_64 rng{7};
  std::vector<rv::CameraFrame> observe(const std::vector<rv::RigCamera>& rig,
                                       const Isometry3d& world_T_board) override {
    std::vector<rv::CameraFrame> out;
    for (const auto& cam : rig)
      out.push_back(
          rv::simulate_frame(cam.model, cam.camera_T_world * world_T_board, board, sigma, rng));
    return out;
  }
};

struct RenderedObserver : Observer {
  rv::TargetBoard board;
  std::vector<rv::CameraRays> rays;
  rv::AprilTagDetector detector;
  rv::RenderOptions options;
  double corner_sq = 0.0;  // detector error against the renderer's truth
  Eigen::Vector2d corner_bias = Eigen::Vector2d::Zero();
  int corner_n = 0;
  double render_s = 0.0, detect_s = 0.0;
  bool use_corner_groups = true;
  std::vector<rv::CameraFrame> observe(const std::vector<rv::RigCamera>& rig,
                                       const Isometry3d& world_T_board) override {
    std::vector<rv::CameraFrame> out;
    for (size_t c = 0; c < rig.size(); ++c) {
      options.seed += 1;
      const auto t0 = std::chrono::steady_clock::now();
      const rv::RenderResult img =
          rv::render(rays[c], {{board, rig[c].camera_T_world * world_T_board}}, options);
      const auto t1 = std::chrono::steady_clock::now();
      const rv::TargetDetection det = rv::detect_apriltag_board(img.image, board, detector);
      const auto t2 = std::chrono::steady_clock::now();
      render_s += std::chrono::duration<double>(t1 - t0).count();
      detect_s += std::chrono::duration<double>(t2 - t1).count();
      rv::CameraFrame frame;
      frame.blur_px = det.edge_blur_px;
      // The detector's joint corner covariances (per refined tag), unless --corner-noise iid.
      if (use_corner_groups) frame.corner_groups = det.corner_groups;
      if (det.status != rv::DetectionStatus::kRejected) {
        std::map<int, Eigen::Vector2d> truth;
        for (const auto& t : img.corners)
          if (t.visible) truth[t.id] = t.pixel;
        for (size_t i = 0; i < det.corner_ids.size(); ++i) {
          frame.corners.push_back({det.corner_ids[i], det.pixels[i], 0.0});
          const auto it = truth.find(det.corner_ids[i]);
          if (it != truth.end()) {
            const Eigen::Vector2d e = det.pixels[i] - it->second;
            corner_sq += e.squaredNorm();
            corner_bias += e;
            ++corner_n;
          }
        }
      }
      out.push_back(frame);
    }
    return out;
  }
};

struct Stats {
  int poses = 0, measured = 0, usable = 0, outliers = 0;
  double pos_sq = 0.0, centre_sq = 0.0, rot_sq = 0.0, nees = 0.0, pred_pos_sq = 0.0;
  double seconds = 0.0;
  void add(const rv::PoseMeasurement& m, const Isometry3d& truth, const Vector3d& centre) {
    ++poses;
    if (m.status != rv::PoseStatus::kOk) return;
    ++measured;
    if (m.usable()) ++usable;
    outliers += m.outliers;
    Eigen::Matrix<double, 6, 1> e;
    const Eigen::AngleAxisd aa(m.world_T_target.linear() * truth.linear().transpose());
    e.head<3>() = aa.axis() * aa.angle();
    e.tail<3>() = m.world_T_target.translation() - truth.translation();
    pos_sq += e.tail<3>().squaredNorm();
    centre_sq += (m.world_T_target * centre - truth * centre).squaredNorm();
    rot_sq += aa.angle() * aa.angle();
    nees += e.dot(m.covariance.ldlt().solve(e));
    pred_pos_sq += m.covariance.bottomRightCorner<3, 3>().trace();
  }
  nlohmann::json json() const {
    const double n = std::max(1, measured);
    return {{"poses", poses},
            {"measured", measured},
            {"usable", usable},
            {"corners_rejected", outliers},
            {"position_rms_um_board_origin", 1e6 * std::sqrt(pos_sq / n)},
            {"position_rms_um_board_centre", 1e6 * std::sqrt(centre_sq / n)},
            {"predicted_position_rms_um_board_origin", 1e6 * std::sqrt(pred_pos_sq / n)},
            {"rotation_rms_deg", std::sqrt(rot_sq / n) * 180.0 / M_PI},
            {"nees_mean", nees / n},
            {"nees_expected", 6.0},
            {"nees_ratio", nees / n / 6.0},
            {"ms_per_pose", 1e3 * seconds / std::max(1, poses)}};
  }
};

}  // namespace

int main(int argc, char** argv) {
  std::string mode = "synthetic";
  int poses = 100, calib_views = 40;
  double sigma = 0.05;
  unsigned seed = 1;
  std::string corner_noise = "detector";  // rendered: detector (joint per-tag) | iid
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--mode")
      mode = v;
    else if (k == "--poses")
      poses = std::stoi(v);
    else if (k == "--calib-views")
      calib_views = std::stoi(v);
    else if (k == "--sigma")
      sigma = std::stod(v);
    else if (k == "--seed")
      seed = static_cast<unsigned>(std::stoul(v));
    else if (k == "--corner-noise")
      corner_noise = v;
    else {
      std::cerr << "unknown option " << k << "\n";
      return 2;
    }
  }
  if (mode != "synthetic" && mode != "rendered") {
    std::cerr << "--mode must be synthetic or rendered\n";
    return 2;
  }
  const auto rig = true_rig();
  rv::TargetSpec spec;
  spec.kind = rv::TargetKind::kAprilTagGrid;
  spec.name = "ee-6x6-200mm";
  spec.cols = 6;
  spec.rows = 6;
  spec.tag_size = 0.2 / 7.5;
  spec.tag_spacing = 0.3 * spec.tag_size;
  const rv::TargetBoard target = rv::build_target(spec);
  rv::BoardPoints board;
  for (const auto& c : target.corners) board[c.id] = c.point;
  const Vector3d centre(0.1, 0.1, 0.0);

  std::unique_ptr<Observer> observer;
  RenderedObserver* rendered = nullptr;
  if (mode == "synthetic") {
    auto s = std::make_unique<SyntheticObserver>();
    s->board = board;
    s->sigma = sigma;
    s->rng.seed(seed + 1000);
    observer = std::move(s);
  } else {
    auto r = std::make_unique<RenderedObserver>();
    r->board = target;
    for (const auto& cam : rig) r->rays.push_back(rv::precompute_rays(cam.model));
    r->options.blur_sigma = 0.8;
    r->options.read_noise = 2.0;
    r->options.seed = seed;
    r->use_corner_groups = corner_noise != "iid";
    rendered = r.get();
    observer = std::move(r);
  }
  std::mt19937_64 rng(seed);

  // 1. Rig calibration from calibration views (the same board, spread over the shared volume).
  std::vector<std::vector<rv::CameraFrame>> views;
  for (int v = 0; v < calib_views; ++v)
    views.push_back(observer->observe(rig, random_pose(rng, centre, 1.1, 0.2, 0.12, 45.0)));
  auto start = rig;  // extrinsics are not used as a start
  rv::RigCalibrationOptions copt;
  copt.default_sigma_px = mode == "synthetic" ? sigma : 0.05;
  auto t0 = std::chrono::steady_clock::now();
  const auto calib = rv::calibrate_rig(start, board, views, copt);
  const double calib_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!calib.ok) {
    std::cerr << "rig calibration failed: " << calib.message << "\n";
    return 1;
  }
  const auto cv = rv::opencv_stereo_calibrate(start, board, views, 0, 1);
  const double true_baseline = (rig[1].camera_T_world.inverse().translation() -
                                rig[0].camera_T_world.inverse().translation())
                                   .norm();
  // The corner sigma the measurement uses: synthetic: the known one; rendered: the calibration's
  // RMS residual (what a user has), never the truth.
  const double corner_sigma = mode == "synthetic" ? sigma : calib.rms_px;

  // 2. Measurements.
  rv::PoseMeasurementOptions mopt;
  mopt.default_sigma_px = corner_sigma;
  // Rig in the calibrated frame: the reference camera's frame. The true rig expressed there too.
  std::vector<rv::RigCamera> truth_in_ref = rig;
  for (auto& c : truth_in_ref)
    c.camera_T_world = c.camera_T_world * rig[0].camera_T_world.inverse();
  const auto calibrated = calib.rig();
  Stats stereo_true, mono_true, stereo_calibrated;
  for (int p = 0; p < poses; ++p) {
    const Isometry3d world_T_board = random_pose(rng, centre, 1.15, 0.05, 0.05, 35.0);
    const Isometry3d truth = rig[0].camera_T_world * world_T_board;  // in the reference frame
    const auto frame = observer->observe(rig, world_T_board);
    auto ts = std::chrono::steady_clock::now();
    const auto m = rv::measure_target_pose(truth_in_ref, board, frame, mopt);
    stereo_true.seconds +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
    stereo_true.add(m, truth, centre);
    ts = std::chrono::steady_clock::now();
    const auto mono = rv::measure_target_pose({truth_in_ref[0]}, board, {frame[0]}, mopt);
    mono_true.seconds +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
    mono_true.add(mono, truth, centre);
    ts = std::chrono::steady_clock::now();
    const auto mc = rv::measure_target_pose(calibrated, board, frame, mopt);
    stereo_calibrated.seconds +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
    stereo_calibrated.add(mc, truth, centre);
  }

  nlohmann::json out;
  out["bench"] = "pose_measurement";
  out["mode"] = mode;
  out["setup"] = {{"cameras", 2},
                  {"resolution", "2448x2048"},
                  {"focal_px", 2400},
                  {"baseline_m", true_baseline},
                  {"convergence_deg", 30},
                  {"distance_m", 1.15},
                  {"board", "AprilTag 6x6 tags, 200 mm"},
                  {"max_tilt_deg", 35},
                  {"poses", poses},
                  {"calibration_views", calib_views},
                  {"seed", seed}};
  if (mode == "synthetic") {
    out["setup"]["pixel_noise_sigma_px"] = sigma;
  } else {
    out["setup"]["blur_sigma_px"] = 0.8;
    out["setup"]["read_noise_dn"] = 2.0;
    const double n = std::max(1, rendered->corner_n);
    out["detector"] = {{"corners", rendered->corner_n},
                       {"error_rms_px", std::sqrt(rendered->corner_sq / n)},
                       {"bias_px", {rendered->corner_bias.x() / n, rendered->corner_bias.y() / n}},
                       {"render_s", rendered->render_s},
                       {"detect_s", rendered->detect_s}};
  }
  out["corner_sigma_used_px"] = corner_sigma;
  out["corner_noise"] = mode == "synthetic" ? "iid" : corner_noise;
  out["rig_calibration_outliers"] = calib.rejected.size();
  out["stereo_true_rig"] = stereo_true.json();
  out["mono_true_rig"] = mono_true.json();
  out["stereo_calibrated_rig"] = stereo_calibrated.json();
  const auto& right = calib.cameras[1];
  out["rig_calibration"] = {
      {"views", calib_views},
      {"rms_px", calib.rms_px},
      {"seconds", calib_s},
      {"baseline_true_m", true_baseline},
      {"baseline_m", right.baseline_m},
      {"baseline_sigma_m", right.baseline_sigma_m},
      {"baseline_error_percent", 100.0 * (right.baseline_m - true_baseline) / true_baseline},
      {"baseline_error_sigmas", (right.baseline_m - true_baseline) / right.baseline_sigma_m},
      {"rotation_error_deg",
       rv::rotation_angle_between(right.camera_T_rig, truth_in_ref[1].camera_T_world) * 180.0 /
           M_PI},
      {"opencv_stereoCalibrate",
       {{"ok", cv.ok},
        {"message", cv.message},
        {"rms_px", cv.rms_px},
        {"baseline_m", cv.baseline_m},
        {"baseline_error_percent", 100.0 * (cv.baseline_m - true_baseline) / true_baseline},
        {"rotation_error_deg",
         rv::rotation_angle_between(cv.b_T_a, truth_in_ref[1].camera_T_world) * 180.0 / M_PI}}}};
  out["targets"] = {{"position_rms_um", 20},
                    {"rotation_rms_deg", 0.005},
                    {"nees_ratio", "1/1.5..1.5"},
                    {"baseline_error_percent", 0.01}};
  std::cout << out.dump(2) << std::endl;
  return 0;
}
