// Where the correlated part of the AprilTag corner error comes from, printed as JSON.
//
// The demo's camera (1600x1200, f = 1600 px, barrel distortion) sees its 6x6 board of 40 mm tags
// from ~1.25 m at random places in the image and tilts <= 25 deg. Each image is rendered under
// several conditions (same poses, same noise seeds), each switching one effect of the demo's
// render options off, and detected with the AprilTag board detector. Per condition:
//   - corner error against the renderer's truth: RMS, mean (bias);
//   - the error's structure: RMS over images of the per-image mean error vector, RMS over tags
//     of the per-tag mean error (common shift) and of the per-tag radial error (size), each
//     next to what independent corner errors of the same RMS would give;
//   - mono pose error against the truth with the true camera (detector's corner covariances),
//     its NEES (6 expected), and the pose error of the same poses measured from the true
//     projections plus independent Gaussian noise of the same per-axis RMS.
// With read noise off the corner error is the detector's deterministic bias alone.
//
//   bench_corner_bias [--poses 30] [--seed 1] [--only NAME] [--max-tilt-deg 25]
//                     [--max-spin-deg 180]
//   bench_corner_bias --session DIR [--only NAME]   (a `robocal simulate` session)
//   bench_corner_bias --edge-phase 1
//
// --session measures the same figures on the images the demo itself rendered (both cameras, the
// true rig from truth/truth.json; stereo next to iid corners of the same RMS), then on the same
// views re-rendered with one effect off, and rendered with the blur applied before the pixels
// integrate (blur_before_sampling: a camera). --edge-phase: the edge fit's offset bias against
// the sub-pixel phase of an axis-aligned edge, for several edge profiles.
//
// Finding (`robocal simulate --out S` seed 1, then --session S): the demo's correlated
// corner error is the renderer blurring after area sampling (vision/README.md), seen on a board
// square to the image: 0.033 of its 0.037 px RMS is deterministic (read noise off), whatever the
// lighting, vignetting or distortion; with the blur before sampling 0.019 px, stereo pose error
// with the true rig 5 um / 5 mdeg at the board centre, NEES 7 (demo images: 25 um / 14 mdeg,
// NEES 59; iid corners of the same RMS: 9 um / 7 mdeg, NEES 5.6).
#include "robocal/core/random_draws.hpp"
#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/edge_fit.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/pose_measurement.hpp"
#include "robocal/vision/renderer.hpp"
#include "robocal/vision/target.hpp"
#include "robocal/vision/target_detection.hpp"
#include "robocal/vision/target_io.hpp"

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <string>

namespace rv = robocal::vision;
using Eigen::Isometry3d;
using Eigen::Vector2d;
using Eigen::Vector3d;

namespace {

constexpr double kPi = 3.14159265358979323846;

struct Condition {
  std::string name;
  bool noise = true;
  bool lighting = true;  // vignetting and lighting gradient
  bool blur = true;
  bool distortion = true;
};

std::vector<Condition> conditions() {
  return {
      {"demo", true, true, true, true},
      {"demo_no_lighting", true, false, true, true},
      {"demo_no_distortion", true, true, true, false},
      {"noiseless", false, true, true, true},
      {"noiseless_no_lighting", false, false, true, true},
      {"noiseless_no_blur", false, true, false, true},
      {"noiseless_no_distortion", false, true, true, false},
      {"noiseless_none", false, false, false, false},
  };
}

rv::CameraModel demo_camera(bool distortion) {
  const std::vector<double> d = distortion ? std::vector<double>{-0.08, 0.06, 0.0, 0.0, 0.0}
                                           : std::vector<double>{0.0, 0.0, 0.0, 0.0, 0.0};
  return rv::make_camera(rv::CameraKind::kPinholeRadtan, 1600, 1200, 1600.0, 1600.0, 799.5, 599.5,
                         d);
}

rv::RenderOptions demo_options(const Condition& c, std::uint64_t seed) {
  rv::RenderOptions o;  // app/src/simulated_cell.cpp, CellOptions
  o.black_level = 20.0;
  o.white_level = 220.0;
  o.background_level = 60.0;
  o.blur_sigma = c.blur ? 0.8 : 0.0;
  o.read_noise = c.noise ? 2.0 : 0.0;
  o.vignetting = c.lighting ? 0.15 : 0.0;
  o.lighting_gradient = c.lighting ? Vector2d(0.05, -0.03) : Vector2d::Zero();
  o.seed = seed;
  return o;
}

// Board centre at ~1.25 m, anywhere in the central ~80 % of the image, tilted <= 25 deg.
Isometry3d random_pose(std::mt19937_64& rng, const Vector3d& board_centre, double max_tilt_deg,
                       double max_spin_deg) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double tilt = std::abs(u(rng)) * max_tilt_deg * kPi / 180.0;
  const double axis = u(rng) * kPi;
  Isometry3d pose = Isometry3d::Identity();
  pose.linear() = (Eigen::AngleAxisd(tilt, Vector3d(std::cos(axis), std::sin(axis), 0)) *
                   Eigen::AngleAxisd(u(rng) * max_spin_deg * kPi / 180.0, Vector3d::UnitZ()))
                      .toRotationMatrix();
  const double z = 1.25 + 0.1 * u(rng);
  // One draw a statement, y first (robocal/core/random_draws.hpp says why).
  const double y = 0.2 * z * u(rng);
  const double x = 0.28 * z * u(rng);
  const Vector3d centre(x, y, z);
  pose.translation() = centre - pose.linear() * board_centre;
  return pose;
}

struct PoseStats {
  int n = 0;
  double centre_sq = 0.0, rot_sq = 0.0, nees = 0.0;
  void add(const rv::PoseMeasurement& m, const Isometry3d& truth, const Vector3d& centre) {
    if (m.status != rv::PoseStatus::kOk) return;
    ++n;
    const Eigen::AngleAxisd aa(m.world_T_target.linear() * truth.linear().transpose());
    Eigen::Matrix<double, 6, 1> e;
    e.head<3>() = aa.axis() * aa.angle();
    e.tail<3>() = m.world_T_target.translation() - truth.translation();
    centre_sq += (m.world_T_target * centre - truth * centre).squaredNorm();
    rot_sq += aa.angle() * aa.angle();
    nees += e.dot(m.covariance.ldlt().solve(e));
  }
  nlohmann::json json() const {
    const double k = std::max(1, n);
    return {{"poses", n},
            {"centre_position_rms_um", 1e6 * std::sqrt(centre_sq / k)},
            {"rotation_rms_mdeg", 1e3 * std::sqrt(rot_sq / k) * 180.0 / kPi},
            {"nees_mean", nees / k}};
  }
};

// Bias of the edge fit on an axis-aligned edge against the edge's sub-pixel phase, for profiles
// of increasing realism: (a) the fit's own model (Gaussian step at pixel centres), (b) a
// continuous Gaussian blur integrated over the pixel's box (a real sensor), (c) the renderer:
// box-area sampling then cv::GaussianBlur's discrete kernel, (d) (c) quantised to 8 bit.
nlohmann::json edge_phase_bias(double blur_sigma) {
  const double dark = 20.0, bright = 220.0;
  const auto cdf = [](double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); };
  const auto pdf = [](double x) { return std::exp(-0.5 * x * x) / std::sqrt(2.0 * kPi); };
  // Integral of Phi((t - x0) / s) dt over [lo, hi].
  const auto int_cdf = [&](double lo, double hi, double x0, double s) {
    const auto F = [&](double t) {
      const double z = (t - x0) / s;
      return (t - x0) * cdf(z) + s * pdf(z);
    };
    return F(hi) - F(lo);
  };
  const int width = 24, rows = 16;
  nlohmann::json out = nlohmann::json::array();
  // (e, f): the renderer's order (area sampling, then the discrete kernel) on a grid 2x / 4x
  // finer, area-averaged down to the pixels: what supersampling the blur would buy.
  const char* names[] = {"gauss_at_centres", "gauss_box",         "renderer",
                         "renderer_8bit",    "renderer_2x_finer", "renderer_4x_finer"};
  for (int kind = 0; kind < 6; ++kind) {
    double sq = 0.0, worst = 0.0;
    int n = 0;
    for (int k = 0; k < 20; ++k) {
      const double x0 = 11.0 + k / 20.0;
      std::vector<double> row(width);
      if (kind <= 1) {
        for (int i = 0; i < width; ++i)
          row[static_cast<size_t>(i)] =
              kind == 0 ? dark + (bright - dark) * cdf((i - x0) / blur_sigma)
                        : dark + (bright - dark) * int_cdf(i - 0.5, i + 0.5, x0, blur_sigma);
      } else {
        const int f = kind == 4 ? 2 : kind == 5 ? 4 : 1;  // fine samples per pixel
        cv::Mat ideal(1, width * f, CV_32F), blurred;
        for (int i = 0; i < width * f; ++i) {
          // Fine sample i covers [i / f - 0.5, (i + 1) / f - 0.5] in pixel coordinates.
          const double lo = static_cast<double>(i) / f - 0.5;
          ideal.at<float>(0, i) = static_cast<float>(
              dark + (bright - dark) * std::clamp((lo + 1.0 / f - x0) * f, 0.0, 1.0));
        }
        cv::GaussianBlur(ideal, blurred, cv::Size(0, 0), f * blur_sigma, 0.0, cv::BORDER_REFLECT);
        for (int i = 0; i < width; ++i) {
          double v = 0.0;
          for (int j = 0; j < f; ++j) v += blurred.at<float>(0, i * f + j) / f;
          row[static_cast<size_t>(i)] = kind == 3 ? std::round(v) : v;
        }
      }
      std::vector<rv::EdgeSample> samples;
      for (int y = 0; y < rows; ++y)
        for (int i = 7; i < 17; ++i)
          samples.push_back({Vector2d(i, y), row[static_cast<size_t>(i)]});
      const auto fit = rv::fit_edge_line(samples, Vector2d(x0, 0.0), Vector2d(x0, rows - 1.0));
      if (!fit) continue;
      const double e = fit->point().x() - x0;  // the fitted line is vertical
      sq += e * e;
      worst = std::max(worst, std::abs(e));
      ++n;
    }
    out.push_back({{"profile", names[kind]},
                   {"blur_sigma_px", blur_sigma},
                   {"phases", n},
                   {"offset_error_rms_px", std::sqrt(sq / std::max(1, n))},
                   {"offset_error_max_px", worst}});
  }
  return out;
}

// The same image with the lens blur applied BEFORE the pixels integrate light, as in a camera:
// the board's neighbourhood is rendered at 4x resolution (a 4x camera on the crop), blurred
// there (sigma 4 x blur: the sampled kernel is then practically continuous), area-averaged down
// to the real pixels, pasted into the background, then lighting, noise and 8-bit quantisation
// as the renderer applies them. Returns an empty image when the board leaves the image.
cv::Mat render_blur_before_sampling(const rv::CameraModel& camera, const rv::TargetBoard& board,
                                    const Isometry3d& camera_T_board, const rv::RenderOptions& o) {
  constexpr int kScale = 4;
  double u0 = 1e9, v0 = 1e9, u1 = -1e9, v1 = -1e9;
  for (double x : {board.extent_min.x(), board.extent_max.x()})
    for (double y : {board.extent_min.y(), board.extent_max.y()})
      for (double t = 0.0; t <= 1.0; t += 0.05) {
        // Along the paper's border (distortion bends it).
        const Vector3d a(
            x, board.extent_min.y() + t * (board.extent_max.y() - board.extent_min.y()), 0.0);
        const Vector3d b(board.extent_min.x() + t * (board.extent_max.x() - board.extent_min.x()),
                         y, 0.0);
        for (const Vector3d& q : {a, b}) {
          const auto px = rv::project(camera, camera_T_board * q);
          if (!px) return {};
          u0 = std::min(u0, px->x()), v0 = std::min(v0, px->y());
          u1 = std::max(u1, px->x()), v1 = std::max(v1, px->y());
        }
      }
  const int cu = std::max(0, static_cast<int>(std::floor(u0)) - 12);
  const int cv0 = std::max(0, static_cast<int>(std::floor(v0)) - 12);
  const int cw = std::min(camera.width, static_cast<int>(std::ceil(u1)) + 12) - cu;
  const int ch = std::min(camera.height, static_cast<int>(std::ceil(v1)) + 12) - cv0;
  if (cw <= 0 || ch <= 0) return {};
  // Fine pixel centre x_f maps to coarse x = (x_f + 0.5) / kScale - 0.5 + crop origin.
  rv::CameraModel fine = camera;
  fine.width = cw * kScale;
  fine.height = ch * kScale;
  fine.params[0] *= kScale;
  fine.params[1] *= kScale;
  fine.params[2] = kScale * (camera.params[2] - cu + 0.5) - 0.5;
  fine.params[3] = kScale * (camera.params[3] - cv0 + 0.5) - 0.5;
  rv::RenderOptions flat = o;
  flat.lighting_gradient = Vector2d::Zero();
  flat.vignetting = 0.0;
  const cv::Mat ideal =
      rv::render_ideal(rv::precompute_rays(fine), {{board, camera_T_board}}, flat);
  cv::Mat blurred, crop;
  if (o.blur_sigma > 0.0)
    cv::GaussianBlur(ideal, blurred, cv::Size(0, 0), kScale * o.blur_sigma, kScale * o.blur_sigma,
                     cv::BORDER_REFLECT);
  else
    blurred = ideal;
  cv::resize(blurred, crop, cv::Size(cw, ch), 0.0, 0.0, cv::INTER_AREA);
  cv::Mat image(camera.height, camera.width, CV_32F, cv::Scalar(o.background_level));
  crop.copyTo(image(cv::Rect(cu, cv0, cw, ch)));
  // Lighting and vignetting as renderer.hpp defines them.
  const double W = camera.width, H = camera.height;
  const double cx = 0.5 * (W - 1.0), cy = 0.5 * (H - 1.0);
  const double r_corner2 = cx * cx + cy * cy;
  for (int v = 0; v < camera.height; ++v)
    for (int u = 0; u < camera.width; ++u) {
      const double r2 = (u - cx) * (u - cx) + (v - cy) * (v - cy);
      const double f = (1.0 + o.lighting_gradient.x() * (u / W - 0.5) +
                        o.lighting_gradient.y() * (v / H - 0.5)) *
                       (1.0 - o.vignetting * r2 / r_corner2);
      image.at<float>(v, u) = static_cast<float>(image.at<float>(v, u) * f);
    }
  rv::RenderOptions sensor = o;
  sensor.blur_sigma = 0.0;
  return rv::apply_sensor(image, sensor);
}

// Structure of the corner error of one image: accumulates over images.
struct ErrorStats {
  double sq = 0.0, image_mean_sq = 0.0, tag_mean_sq = 0.0, tag_radial_sq = 0.0;
  double corners_per_image = 0.0;
  Vector2d bias = Vector2d::Zero();
  int n = 0, images = 0, tags = 0;
  // Errors of the detected corners against the truth; returns them by id.
  std::map<int, Vector2d> add(const rv::TargetDetection& det,
                              const std::map<int, Vector2d>& truth) {
    std::map<int, Vector2d> error;
    Vector2d image_sum = Vector2d::Zero();
    for (size_t i = 0; i < det.corner_ids.size(); ++i) {
      const auto it = truth.find(det.corner_ids[i]);
      if (it == truth.end()) continue;
      const Vector2d e = det.pixels[i] - it->second;
      error[det.corner_ids[i]] = e;
      sq += e.squaredNorm();
      bias += e;
      image_sum += e;
      ++n;
    }
    if (!error.empty()) {
      image_mean_sq += (image_sum / static_cast<double>(error.size())).squaredNorm();
      corners_per_image += static_cast<double>(error.size());
      ++images;
    }
    // Per tag: common shift and size change (mean outward error along centre -> corner).
    for (const auto& g : det.corner_groups) {
      Vector2d c = Vector2d::Zero(), mean = Vector2d::Zero();
      bool complete = !g.corner_ids.empty();
      for (int id : g.corner_ids) {
        if (!error.count(id)) {
          complete = false;
        } else {
          c += truth.at(id);
          mean += error[id];
        }
      }
      if (!complete) continue;
      const double k = static_cast<double>(g.corner_ids.size());
      c /= k;
      mean /= k;
      double radial = 0.0;
      for (int id : g.corner_ids) radial += error[id].dot((truth.at(id) - c).normalized()) / k;
      tag_mean_sq += mean.squaredNorm();
      tag_radial_sq += radial * radial;
      ++tags;
    }
    return error;
  }
  [[nodiscard]] double rms() const { return std::sqrt(sq / std::max(1, n)); }
  nlohmann::json json() const {
    const double r = rms();
    const double cpi = corners_per_image / std::max(1, images);
    return {{"corners", n},
            {"corner_error_rms_px", r},
            {"corner_bias_px", {bias.x() / std::max(1, n), bias.y() / std::max(1, n)}},
            {"image_mean_error_rms_px", std::sqrt(image_mean_sq / std::max(1, images))},
            {"image_mean_error_rms_px_if_iid", r / std::sqrt(std::max(1.0, cpi))},
            {"tag_mean_error_rms_px", std::sqrt(tag_mean_sq / std::max(1, tags))},
            {"tag_mean_error_rms_px_if_iid", r / 2.0},
            {"tag_radial_error_rms_px", std::sqrt(tag_radial_sq / std::max(1, tags))},
            {"tag_radial_error_rms_px_if_iid", r / std::sqrt(2.0) / 2.0}};
  }
};

Isometry3d pose_json(const nlohmann::json& j) {
  return rv::pose_from_rvec_tvec(Vector3d(j["rvec"][0], j["rvec"][1], j["rvec"][2]),
                                 Vector3d(j["tvec"][0], j["tvec"][1], j["tvec"][2]));
}

void stereo_iid_add(PoseStats& stats, const std::vector<rv::RigCamera>& rig0,
                    const rv::BoardPoints& points, const std::vector<rv::CameraFrame>& frames,
                    const nlohmann::json& pose, const rv::RigCamera& cam0, const Vector3d& centre) {
  rv::PoseMeasurementOptions mopt;
  mopt.default_sigma_px = 0.05;
  stats.add(rv::measure_target_pose(rig0, points, frames, mopt),
            cam0.camera_T_world * pose_json(pose["world_T_board"]), centre);
}

// The demo's own images: the true rig and board poses from truth/truth.json.
int run_session(const std::filesystem::path& dir, const std::string& only) {
  std::ifstream in(dir / "truth" / "truth.json");
  if (!in) {
    std::cerr << dir.string() << "/truth/truth.json: cannot read\n";
    return 2;
  }
  const nlohmann::json truth = nlohmann::json::parse(in);
  const rv::TargetBoard board = rv::load_target_file(dir / "targets" / "end_effector.yaml");
  rv::BoardPoints points;
  for (const auto& c : board.corners) points[c.id] = c.point;
  const Vector3d centre(0.5 * (board.extent_min.x() + board.extent_max.x()),
                        0.5 * (board.extent_min.y() + board.extent_max.y()), 0.0);
  std::vector<rv::RigCamera> rig;
  std::vector<std::string> names;
  for (const auto& c : truth["cameras"]) {
    rv::RigCamera cam;
    cam.name = c["name"];
    cam.model.kind = *rv::kind_from_name(c["model"].get<std::string>());
    cam.model.width = c["width"];
    cam.model.height = c["height"];
    cam.model.params = c["params"].get<std::vector<double>>();
    cam.camera_T_world = pose_json(c["camera_T_world"]);
    rig.push_back(cam);
    names.push_back(cam.name);
  }
  // Sources: the session's own images, then re-renders of the same views with one effect off.
  std::vector<Condition> sources = {{"session_images", true, true, true, true}};
  for (const auto& c : conditions()) sources.push_back(c);
  sources.push_back({"blur_before_sampling", true, true, true, true});
  sources.push_back({"blur_before_sampling_noiseless", false, true, true, true});
  nlohmann::json out;
  out["bench"] = "corner_bias";
  out["session"] = dir.string();
  rv::AprilTagDetector detector;
  for (const auto& source : sources) {
    if (!only.empty() && source.name != only) continue;
    const bool from_files = source.name == "session_images";
    std::vector<rv::RigCamera> cams = rig;
    if (!source.distortion)
      for (auto& c : cams) std::fill(c.model.params.begin() + 4, c.model.params.end(), 0.0);
    std::vector<rv::CameraRays> rays;
    if (!from_files && source.name.rfind("blur_before_sampling", 0) != 0)
      for (const auto& c : cams) rays.push_back(rv::precompute_rays(c.model));
    // Rig frame = camera 0 (as the measured rig); truth expressed there.
    std::vector<rv::RigCamera> rig0 = cams;
    for (auto& c : rig0) c.camera_T_world = c.camera_T_world * cams[0].camera_T_world.inverse();
    std::vector<ErrorStats> errors(cams.size());
    std::vector<PoseStats> mono(cams.size());
    PoseStats stereo;
    rv::PoseMeasurementOptions mopt;
    mopt.default_sigma_px = 0.05;
    std::uint64_t seed = 1;
    // Per pose and camera: the true pixels of the detected corners (for the iid comparison).
    std::vector<std::vector<std::map<int, Vector2d>>> detected_truth;
    for (const auto& p : truth["poses"]) {
      const Isometry3d world_T_board = pose_json(p["world_T_board"]);
      std::vector<rv::CameraFrame> frames;
      detected_truth.emplace_back(cams.size());
      for (size_t c = 0; c < cams.size(); ++c) {
        const Isometry3d camera_T_board = cams[c].camera_T_world * world_T_board;
        cv::Mat image;
        if (from_files) {
          const auto path = dir / "poses" / p["pose"].get<std::string>() / (names[c] + ".png");
          const rv::LoadedImage img = rv::load_gray_image(path);
          if (!img.error.empty()) {
            std::cerr << img.error << "\n";
            return 1;
          }
          image = img.gray;
        } else if (source.name.rfind("blur_before_sampling", 0) == 0) {
          image = render_blur_before_sampling(cams[c].model, board, camera_T_board,
                                              demo_options(source, ++seed));
        } else {
          image =
              rv::render(rays[c], {{board, camera_T_board}}, demo_options(source, ++seed)).image;
        }
        std::map<int, Vector2d> truth_px;
        for (const auto& t : rv::corner_truth(cams[c].model, {{board, camera_T_board}}, {}))
          if (t.visible) truth_px[t.id] = t.pixel;
        const rv::TargetDetection det = image.empty()
                                            ? rv::TargetDetection{}
                                            : rv::detect_apriltag_board(image, board, detector);
        rv::CameraFrame frame;
        if (det.status != rv::DetectionStatus::kRejected) {
          for (const auto& [id, e] : errors[c].add(det, truth_px))
            detected_truth.back()[c][id] = truth_px.at(id);
          frame.blur_px = det.edge_blur_px;
          frame.corner_groups = det.corner_groups;
          for (size_t i = 0; i < det.corner_ids.size(); ++i)
            frame.corners.push_back({det.corner_ids[i], det.pixels[i], 0.0});
        }
        mono[c].add(rv::measure_target_pose({cams[c]}, points, {frame}, mopt), world_T_board,
                    centre);
        frames.push_back(frame);
      }
      stereo.add(rv::measure_target_pose(rig0, points, frames, mopt),
                 cams[0].camera_T_world * world_T_board, centre);
    }
    // The same poses measured from the true pixels of the same corners plus independent Gaussian
    // noise of the detections' per-axis RMS (each camera its own), sigma known exactly.
    PoseStats iid;
    std::mt19937_64 noise_rng(99);
    for (size_t p = 0; p < detected_truth.size(); ++p) {
      std::vector<rv::CameraFrame> frames(cams.size());
      for (size_t c = 0; c < cams.size(); ++c) {
        const double sigma = errors[c].rms() / std::sqrt(2.0);
        std::normal_distribution<double> gauss(0.0, sigma);
        for (const auto& [id, px] : detected_truth[p][c])
          frames[c].corners.push_back(
              {id, px + robocal::core::draw_vector2(gauss, noise_rng), std::max(sigma, 1e-6)});
      }
      stereo_iid_add(iid, rig0, points, frames, truth["poses"][p], cams[0], centre);
    }
    nlohmann::json j = {{"noise", source.noise},
                        {"lighting", source.lighting},
                        {"blur", source.blur},
                        {"distortion", source.distortion}};
    for (size_t c = 0; c < cams.size(); ++c)
      j["cameras"][names[c]] = {{"corners", errors[c].json()}, {"mono_pose", mono[c].json()}};
    j["stereo_pose_true_rig"] = stereo.json();
    j["stereo_pose_true_rig_iid_corners_same_rms"] = iid.json();
    out["sources"][source.name] = j;
    std::cerr << source.name << " done\n";
  }
  std::cout << out.dump(2) << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  int poses = 30;
  unsigned seed = 1;
  double max_tilt_deg = 25.0, max_spin_deg = 180.0;
  std::string only, session;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--poses")
      poses = std::stoi(v);
    else if (k == "--seed")
      seed = static_cast<unsigned>(std::stoul(v));
    else if (k == "--only")
      only = v;
    else if (k == "--max-tilt-deg")
      max_tilt_deg = std::stod(v);
    else if (k == "--max-spin-deg")
      max_spin_deg = std::stod(v);
    else if (k == "--session")
      session = v;
    else if (k == "--edge-phase") {
      nlohmann::json j = nlohmann::json::array();
      for (double b : {0.5, 0.8, 1.2}) j.push_back(edge_phase_bias(b));
      std::cout << j.dump(2) << std::endl;
      return 0;
    } else {
      std::cerr << "unknown option " << k << "\n";
      return 2;
    }
  }
  if (!session.empty()) return run_session(session, only);
  rv::TargetSpec spec;  // the demo's end-effector board
  spec.kind = rv::TargetKind::kAprilTagGrid;
  spec.name = "end_effector";
  spec.cols = 6;
  spec.rows = 6;
  spec.tag_size = 0.04;
  spec.tag_spacing = 0.01;
  const rv::TargetBoard board = rv::build_target(spec);
  rv::BoardPoints points;
  for (const auto& c : board.corners) points[c.id] = c.point;
  const Vector3d centre(0.5 * (board.extent_min.x() + board.extent_max.x()),
                        0.5 * (board.extent_min.y() + board.extent_max.y()), 0.0);

  const std::vector<Condition> all = conditions();
  std::mt19937_64 pose_rng(seed);
  std::vector<Isometry3d> truth;
  for (int p = 0; p < poses; ++p)
    truth.push_back(random_pose(pose_rng, centre, max_tilt_deg, max_spin_deg));

  nlohmann::json out;
  out["bench"] = "corner_bias";
  out["setup"] = {{"camera", "1600x1200, f 1600 px"},
                  {"board", "6x6 AprilTags 40 mm, 10 mm gap"},
                  {"distance_m", "1.15..1.35"},
                  {"max_tilt_deg", max_tilt_deg},
                  {"max_spin_deg", max_spin_deg},
                  {"poses", poses},
                  {"seed", seed}};
  rv::AprilTagDetector detector;
  for (const auto& cond : all) {
    if (!only.empty() && cond.name != only) continue;
    const rv::CameraModel camera = demo_camera(cond.distortion);
    const rv::CameraRays rays = rv::precompute_rays(camera);
    rv::RigCamera rig_camera;
    rig_camera.model = camera;
    ErrorStats errors;
    PoseStats detected;
    std::vector<std::vector<std::pair<int, Vector2d>>> true_pixels;  // per pose, for the iid run
    for (int p = 0; p < poses; ++p) {
      const rv::RenderResult img =
          rv::render(rays, {{board, truth[static_cast<size_t>(p)]}}, demo_options(cond, seed + p));
      const rv::TargetDetection det = rv::detect_apriltag_board(img.image, board, detector);
      std::map<int, Vector2d> truth_px;
      for (const auto& t : img.corners)
        if (t.visible) truth_px[t.id] = t.pixel;
      true_pixels.emplace_back(truth_px.begin(), truth_px.end());
      if (det.status == rv::DetectionStatus::kRejected) continue;
      errors.add(det, truth_px);
      rv::CameraFrame frame;
      frame.blur_px = det.edge_blur_px;
      frame.corner_groups = det.corner_groups;
      for (size_t i = 0; i < det.corner_ids.size(); ++i)
        frame.corners.push_back({det.corner_ids[i], det.pixels[i], 0.0});
      rv::PoseMeasurementOptions mopt;
      mopt.default_sigma_px = 0.05;
      detected.add(rv::measure_target_pose({rig_camera}, points, {frame}, mopt),
                   truth[static_cast<size_t>(p)], centre);
    }
    const double per_axis = errors.rms() / std::sqrt(2.0);
    // Same poses, true projections + independent Gaussian noise of the measured per-axis RMS.
    PoseStats iid;
    std::mt19937_64 noise_rng(seed + 99);
    std::normal_distribution<double> gauss(0.0, per_axis);
    for (int p = 0; p < poses && per_axis > 0.0; ++p) {
      rv::CameraFrame frame;
      for (const auto& [id, px] : true_pixels[static_cast<size_t>(p)])
        frame.corners.push_back({id, px + robocal::core::draw_vector2(gauss, noise_rng), per_axis});
      rv::PoseMeasurementOptions mopt;
      mopt.default_sigma_px = per_axis;
      iid.add(rv::measure_target_pose({rig_camera}, points, {frame}, mopt),
              truth[static_cast<size_t>(p)], centre);
    }
    nlohmann::json j = errors.json();
    j.update({{"noise", cond.noise},
              {"lighting", cond.lighting},
              {"blur", cond.blur},
              {"distortion", cond.distortion},
              {"pose_detected_corners", detected.json()},
              {"pose_iid_corners_same_rms", iid.json()}});
    out["conditions"][cond.name] = j;
    std::cerr << cond.name << " done\n";
  }
  std::cout << out.dump(2) << std::endl;
  return 0;
}
